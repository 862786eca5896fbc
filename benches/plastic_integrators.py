#!/usr/bin/env python3
"""What an integrator that advances the lower tool's ringing exactly would buy the fits' blow
(issue 17: one hammer blow as fitted in at most 50 us). A measurement, not a test: it prints,
it asserts nothing. It is a second code path, written from the papers' equations, not from
`src/physics`: eq. 3 of seed 000 with constant flow stress and Coulomb friction, the ram m1
on the billet, the lower tool m2 on its frame spring k and damper c.

It integrates the first plastic phase of a base-hammer blow (from contact, the lower tool at
rest, until the ram and the lower tool first move together) on the state of `BaseHammer`
(ram position and speed, lower tool position and speed, plastic compression, plastic,
friction and damped work) with:

  - the reference: scipy's DOP853 at rtol 1e-13;
  - Dormand-Prince 5(4) with `integrator`'s step control and error norm (rtol 1e-6, the
    fits' `FIT_RTOL`; the scales of `blow::scales`);
  - Lawson's integrating factor on the same tableau: the lower tool's oscillator and the
    compression's share of its speed (the linear part L) advanced by exp(hL) at the stages;
  - ETDRK4 (Cox and Matthews 2002) at fixed steps, the same L, with its continuous
    extension at the 100 kHz samples in between.

For each it prints the steps, the vector-field evaluations, and the errors at the phase's
last step against the reference: the compression (the final height; bound 1e-8 m, 1e-3 of
the encoder step, `blow::tests`), the sensor k x + c v at the samples (bound 200 N, a tenth
of the captures' load noise) and the plastic work (the ledger's 1e-5 of the kinetic energy).

The library's own Dormand-Prince takes 250 steps over this phase of the suite's hammer (its
blow starts with a 17 us stuck phase, and its law is the library's); this script's takes
192. The ratios between the methods are what carry over.

Usage: python3 benches/plastic_integrators.py   (numpy and scipy; a few seconds)
"""

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import expm

# The steel billet of seed 000 §2.1 (config/steel-16NiCrMo13.process.toml).
D_M, H0_M, SIGMA_PA, MU = 0.060, 0.112, 90e6, 0.2
R0SQ_H0 = (D_M / 2) ** 2 * H0_M
RTOL = 1e-6
SAMPLE_S = 1e-5


def blow(m1, m2, k, c, v0, rate_m=0.0):
    """The vector field, its linear part L, the rest N, and the error norm's scales."""

    def load(h, hdot):
        rsq = R0SQ_H0 / h
        a = 2 * MU * np.sqrt(rsq) / h
        # The `rate` effect (reference 10 /s, the library's 1e-2 /s floor), when asked for.
        sigma = SIGMA_PA * (max(hdot / h, 1e-2) / 10.0) ** rate_m if rate_m else SIGMA_PA
        frictionless = np.pi * rsq * sigma
        return frictionless * (2 / a) * (np.expm1(a) / a - 1), frictionless

    def f(y):
        _, vu, xl, vl, p, _, _, _ = y
        rate = vu - vl
        total, frictionless = load(H0_M - p, max(rate, 0.0))
        return np.array(
            [vu, -total / m1, vl, (total - k * xl - c * vl) / m2, rate,
             frictionless * rate, (total - frictionless) * rate, c * vl * vl]
        )

    lin = np.zeros((8, 8))
    lin[2, 3], lin[3, 2], lin[3, 3], lin[4, 3] = 1.0, -k / m2, -c / m2, -1.0
    f_max = np.sqrt(k / m2) / (2 * np.pi)
    x = v0 / (10 * f_max)
    kinetic = 0.5 * m1 * v0**2
    scale = np.array([x, v0, x, v0, x, kinetic, kinetic, kinetic])
    return f, lin, (lambda y: f(y) - lin @ y), scale, f_max, kinetic


# Dormand-Prince 5(4) (Hairer, Norsett, Wanner, Table II.5.2), the last row the solution.
A = np.zeros((7, 7))
A[1, :1] = [1 / 5]
A[2, :2] = [3 / 40, 9 / 40]
A[3, :3] = [44 / 45, -56 / 15, 32 / 9]
A[4, :4] = [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729]
A[5, :5] = [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656]
A[6, :6] = [35 / 384, 0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84]
C = np.array([0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1, 1])
E = np.array([71 / 57600, 0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40])


def dopri_step(f, y0, h):
    ks = []
    for i in range(7):
        yi = y0 + h * sum(A[i, j] * ks[j] for j in range(i)) if i else y0
        ks.append(f(yi))
    return yi, h * sum(E[j] * ks[j] for j in range(7))


def lawson_step(lin, rest, y0, h):
    ks = []
    for i in range(7):
        yi = expm(C[i] * h * lin) @ y0
        for j in range(i):
            if A[i, j]:
                yi = yi + h * A[i, j] * (expm((C[i] - C[j]) * h * lin) @ ks[j])
        ks.append(rest(yi))
    return yi, h * sum(E[j] * (expm((1 - C[j]) * h * lin) @ ks[j]) for j in range(7) if E[j])


def adaptive(step, y0, scale, h_max):
    """`integrator::integrate`'s control: RMS norm over rtol (scale + |y|), safety 0.9,
    growth within [0.2, 5], the plant's `max_step`. Ends before the relative speed's zero;
    also returns the steps tried (accepted and rejected)."""
    t, y, h, steps, tried = 0.0, y0, 1e-6, 0, 0
    while True:
        y1, err = step(y, h)
        tried += 1
        e = np.sqrt(np.mean((err / (RTOL * (scale + np.maximum(abs(y), abs(y1))))) ** 2))
        if e > 1:
            h *= max(0.9 * e**-0.2, 0.2)
            continue
        if y1[1] - y1[3] < 0:
            return t, y, steps, tried
        t, y, steps = t + h, y1, steps + 1
        h = min(h * (min(0.9 * e**-0.2, 5.0) if e > 0 else 5.0), h_max)


def phis(m):
    """exp(M) and phi_1..3(M), from the exponential of the augmented matrix."""
    n = m.shape[0]
    z = np.zeros((4 * n, 4 * n))
    z[:n, :n] = m
    for b in range(3):
        z[b * n:(b + 1) * n, (b + 1) * n:(b + 2) * n] = np.eye(n)
    x = expm(z)
    return [x[:n, b * n:(b + 1) * n] for b in range(4)]


def etdrk4(rest, lin, y0, h, sensor_err):
    """ETDRK4 at the fixed step h; the sensor's worst error at the samples inside."""
    e1, p1, p2, p3 = phis(h * lin)
    eh, ph1, _, _ = phis(h * lin / 2)
    n_sub = int(round(h / SAMPLE_S))
    inside = [phis(j / n_sub * h * lin) for j in range(1, n_sub)]
    t, y, steps, worst = 0.0, y0, 0, 0.0
    while True:
        nu = rest(y)
        a = eh @ y + (h / 2) * ph1 @ nu
        na = rest(a)
        b = eh @ y + (h / 2) * ph1 @ na
        nb = rest(b)
        cc = eh @ a + (h / 2) * ph1 @ (2 * nb - nu)
        nc = rest(cc)
        # The quadratic through the stages' N: nu + d1 s/h + d2 (s/h)^2.
        d1, d2 = -3 * nu + 2 * (na + nb) - nc, 2 * (nu - (na + nb) + nc)
        y1 = e1 @ y + h * (p1 @ nu + p2 @ d1 + 2 * p3 @ d2)
        if y1[1] - y1[3] < 0:
            return t, y, steps, worst
        for j, (ej, q1, q2, q3) in enumerate(inside, start=1):
            th = j / n_sub
            yj = ej @ y + th * h * (q1 @ nu + th * q2 @ d1 + 2 * th * th * q3 @ d2)
            worst = max(worst, sensor_err(t + th * h, yj))
        t, y, steps = t + h, y1, steps + 1
        worst = max(worst, sensor_err(t, y))


def study(label, m1, m2, k, c, v0, rate_m=0.0, lawson=False):
    f, lin, rest, scale, f_max, kinetic = blow(m1, m2, k, c, v0, rate_m)
    y0 = np.array([0, v0, 0, 0, 0, 0, 0, 0.0])

    def parted(_t, y):
        return y[1] - y[3]

    parted.terminal, parted.direction = True, -1
    ref = solve_ivp(lambda _t, y: f(y), (0, 0.05), y0, method="DOP853", rtol=1e-13,
                    atol=1e-13 * scale, events=parted, dense_output=True)
    print(f"{label}: first plastic phase {ref.t_events[0][0] * 1e3:.2f} ms, fastest mode {f_max:.0f} Hz")

    def report(name, t, y, steps, evals, sensor=None):
        err = abs(y - ref.sol(t))
        s = f", sensor at the samples {sensor:.1e} N" if sensor is not None else ""
        print(f"  {name}: {steps} steps, {evals} evaluations; compression {err[4]:.1e} m, "
              f"ram {err[0]:.1e} m{s}, plastic work {err[5] / kinetic:.1e} of the kinetic energy")

    h_max = 0.25 / f_max
    # Six evaluations per step tried (the last stage is the next step's first).
    t, y, steps, tried = adaptive(lambda y, h: dopri_step(f, y, h), y0, scale, h_max)
    report("Dormand-Prince 5(4), rtol 1e-6", t, y, steps, 6 * tried)
    if lawson:
        t, y, steps, tried = adaptive(lambda y, h: lawson_step(lin, rest, y, h), y0, scale, h_max)
        report("Lawson Dormand-Prince 5(4), rtol 1e-6", t, y, steps, 6 * tried)

    def sensor_err(t, y):
        r = ref.sol(t)
        return abs(k * (y[2] - r[2]) + c * (y[3] - r[3]))

    for h in (25e-6, 50e-6, 100e-6, 150e-6):
        t, y, steps, worst = etdrk4(rest, lin, y0, h, sensor_err)
        report(f"ETDRK4 at {h * 1e6:.0f} us", t, y, steps, 4 * steps, worst)


if __name__ == "__main__":
    study("suite's hammer (910 / 26 kg, 2.6e9 N/m, 24000 N s/m) at 4.0 m/s", 910, 26, 2.6e9, 24000, 4.0,
          lawson=True)
    study("paper hammer (732 / 19 kg, 3.15e9 N/m, 18540 N s/m) at 5.3 m/s", 732, 19, 3.15e9, 18540, 5.3)
    study("suite's hammer with the rate effect, m = 0.15", 910, 26, 2.6e9, 24000, 4.0, rate_m=0.15)
