//! The plant as a hybrid system for `integrator`: its vector field, the guards that end a
//! contact phase, and what each event does to the state and the phase. The forces come from
//! `Plant::eval` (the parent module).

use super::*;

// Guard identities.
pub(super) const G_TOUCH: u8 = 0;
pub(super) const G_REL_VEL_ZERO: u8 = 1;
pub(super) const G_STICK_ZERO: u8 = 2;
pub(super) const G_STICK_YIELD: u8 = 3;
pub(super) const G_OPEN: u8 = 4;
pub(super) const G_YIELD: u8 = 5;
pub(super) const G_UNLOAD: u8 = 6;
pub(super) const G_ENGAGE: u8 = 7;
pub(super) const G_DISENGAGE: u8 = 8;
pub(super) const G_SENSOR_ZERO: u8 = 9;

impl Plant {
    /// Where the rigid contact goes when the billet touches or the bodies stop approaching.
    fn classify_rigid(&self, y: &mut [f64; N], mode: Mode, approaching: bool) -> Contact {
        let e = self.eval(y, Mode { contact: Contact::Free, ..mode });
        let f_l = self.yield_load(e.h_m, e.ddelta_mps);
        if approaching || e.stick_n >= f_l {
            y[P] = e.delta_m;
            if !approaching {
                // The relative velocity is zero only to the event's tolerance; a negative
                // remainder would start the flow on the wrong side of its guard, and the
                // billet would "unform" at the parting velocity.
                self.common_velocity(y);
            }
            Contact::Plastic
        } else if e.stick_n > 0.0 {
            self.common_velocity(y);
            Contact::Stuck
        } else {
            Contact::Free
        }
    }

    /// Make the contact phase agree with the state after an event. Two guards can cross at
    /// the same instant (the sensor load and the stick force reach zero together when the
    /// tools part); the first event leaves the second at exactly zero, where a strict sign
    /// change can no longer be seen. So a phase whose condition no longer holds ends here.
    fn settle(&self, y: &mut [f64; N], mode: Mode) -> Mode {
        let mut next = mode;
        match mode.contact {
            Contact::Stuck => {
                let e = self.eval(y, mode);
                let f_l = self.yield_load(e.h_m, 0.0);
                if e.stick_n <= 0.0 {
                    next.contact = Contact::Free;
                } else if e.stick_n >= f_l {
                    y[P] = e.delta_m;
                    next.contact = Contact::Plastic;
                }
            }
            Contact::Elastic => {
                let e = self.eval(y, mode);
                if e.delta_m - y[P] - self.gap_contact_m <= 0.0 && e.ddelta_mps <= 0.0 {
                    next.contact = Contact::Free;
                }
            }
            // Entering plastic flow where the billet would already be unloading (the rate from
            // the consistency condition is negative) leaves no guard to end it: it is elastic.
            Contact::Plastic if !self.rigid() => {
                if self.eval(y, mode).p_rate_mps < 0.0 {
                    next.contact = Contact::Elastic;
                }
            }
            // Parting from a rigid contact leaves the gap delta - p at roundoff, and a
            // positive roundoff would leave the touch guard unarmed: the ram would pass
            // through the billet. The bodies are touching here, so the gap is exactly zero.
            Contact::Free if self.rigid() => {
                let e = self.eval(y, mode);
                if e.delta_m > y[P] {
                    y[P] = e.delta_m;
                }
            }
            Contact::Free | Contact::Plastic => {}
        }
        next
    }

    /// Give both bodies either side of a rigid contact their common (momentum-weighted)
    /// velocity. Used where the relative velocity is zero up to the event's tolerance.
    fn common_velocity(&self, y: &mut [f64; N]) {
        if let Lower::Mass { m_kg, .. } = self.lower {
            let v = (self.m_upper_kg * y[VU] + m_kg * y[VL]) / (self.m_upper_kg + m_kg);
            y[VU] = v;
            y[VL] = v;
        }
    }
}

impl Hybrid<N> for Plant {
    type Mode = Mode;

    fn rhs(&self, y: &[f64; N], mode: Mode, dy: &mut [f64; N]) {
        let e = self.eval(y, mode);
        let (x3v, v3) = if self.foundation.is_some() { (y[X3], y[V3]) } else { (0.0, 0.0) };
        let _ = x3v;
        dy[XU] = y[VU];
        dy[VU] = e.acc_upper;
        let mut damped = 0.0;
        if let Some((m, _, c)) = self.ram {
            dy[XR] = y[VR];
            dy[VR] = -e.link_n / m;
            damped += c * (y[VR] - y[VU]).powi(2);
        } else {
            dy[XR] = 0.0;
            dy[VR] = 0.0;
        }
        let mut down_n = e.contact_n;
        match self.lower {
            Lower::Mass { c_ns_per_m, .. } => {
                dy[XL] = y[VL];
                dy[VL] = e.acc_lower;
                if mode.engaged {
                    damped += c_ns_per_m * (y[VL] - v3).powi(2);
                }
                down_n = e.support_n;
                dy[XN] = 0.0;
            }
            Lower::Chain { c_frame_ns_per_m, .. } => {
                dy[XL] = 0.0;
                dy[VL] = 0.0;
                if self.node {
                    dy[XN] = e.vn_mps;
                    damped += c_frame_ns_per_m * (e.vn_mps - v3).powi(2);
                } else {
                    dy[XN] = 0.0;
                }
            }
        }
        if let Some(f) = self.foundation {
            dy[X3] = y[V3];
            dy[V3] = self.foundation_acc(y, down_n);
            damped += f.c3_ns_per_m * y[V3] * y[V3];
        } else {
            dy[X3] = 0.0;
            dy[V3] = 0.0;
        }
        dy[P] = e.p_rate_mps;
        dy[Z] = if self.highpass_tau_s.is_finite() { (e.sensor_raw_n - y[Z]) / self.highpass_tau_s } else { 0.0 };
        let flow = Flow { contact_n: e.contact_n, frictionless_n: e.frictionless_n, p_rate_mps: e.p_rate_mps };
        (dy[WP], dy[WF]) = flow.work_rates();
        dy[WD] = damped;
    }

    fn guards(&self, y: &[f64; N], dy: &[f64; N], mode: Mode, out: &mut Guards) {
        // Every guard is a function of the kinematics (and of `dy`); the flow load enters
        // only the yield guards, computed there.
        let e = self.kinematics(y, mode);
        if self.rigid() {
            match mode.contact {
                Contact::Free | Contact::Elastic => out.push(G_TOUCH, e.delta_m - y[P], Crossing::Rising),
                Contact::Plastic => out.push(G_REL_VEL_ZERO, e.ddelta_mps, Crossing::Falling),
                Contact::Stuck => {
                    let f_l = self.yield_load(e.h_m, 0.0);
                    out.push(G_STICK_ZERO, e.stick_n, Crossing::Falling);
                    out.push(G_STICK_YIELD, e.stick_n - f_l, Crossing::Rising);
                }
            }
        } else {
            let compression = e.delta_m - y[P] - self.gap_contact_m;
            match mode.contact {
                Contact::Free | Contact::Stuck => out.push(G_TOUCH, compression, Crossing::Rising),
                Contact::Elastic => {
                    out.push(G_OPEN, compression, Crossing::Falling);
                    if self.billet.is_some() {
                        let f_l = self.yield_load(e.h_m, e.ddelta_mps);
                        out.push(G_YIELD, e.contact_n - f_l, Crossing::Rising);
                    }
                }
                Contact::Plastic => out.push(G_UNLOAD, dy[P], Crossing::Falling),
            }
        }
        if self.gap_support_m > 0.0 {
            let x3 = if self.foundation.is_some() { y[X3] } else { 0.0 };
            let closure = y[XL] - x3 - self.gap_support_m;
            if mode.engaged {
                out.push(G_DISENGAGE, closure, Crossing::Falling);
            } else {
                out.push(G_ENGAGE, closure, Crossing::Rising);
            }
        }
        if mode.contact != Contact::Plastic {
            let sensor = if self.sensor_is_kinematic() { self.sensor(y, &e) } else { self.sensor_at(y, mode) };
            out.push(G_SENSOR_ZERO, sensor, Crossing::Falling);
        }
    }

    fn on_event(&self, y: &mut [f64; N], mode: Mode, guard_id: u8) -> Mode {
        let mut next = mode;
        match guard_id {
            G_TOUCH if self.rigid() => {
                let approaching = y[VU] > if matches!(self.lower, Lower::Mass { .. }) { y[VL] } else { 0.0 };
                next.contact = self.classify_rigid(y, mode, approaching);
            }
            // A billet whose flow load is already reached when the contact closes (a fresh
            // billet's flow stress rises from near zero with strain) would start on the yield
            // guard's triggered side, where no sign change can be seen: it flows at once.
            G_TOUCH => {
                let e = self.eval(y, Mode { contact: Contact::Elastic, ..mode });
                let flows = self.billet.is_some() && e.contact_n >= self.yield_load(e.h_m, e.ddelta_mps);
                next.contact = if flows { Contact::Plastic } else { Contact::Elastic };
            }
            G_REL_VEL_ZERO => next.contact = self.classify_rigid(y, mode, false),
            G_STICK_ZERO | G_OPEN => next.contact = Contact::Free,
            G_STICK_YIELD => {
                let e = self.eval(y, mode);
                y[P] = e.delta_m;
                self.common_velocity(y);
                next.contact = Contact::Plastic;
            }
            G_YIELD => next.contact = Contact::Plastic,
            G_UNLOAD => {
                // Leave the yield surface exactly: shift the plastic compression so that the
                // elastic force equals the flow load (a correction of the stabilised drift,
                // usually sub-micrometre), which keeps the next yield guard armed.
                // The shift is plastic flow from the contact force down to the flow load: its
                // work, ½ (F + F_L) Δp, is booked like the flow's, or the ledger loses the
                // elastic energy it releases. At the default tolerance the drift is not always
                // small: blow 3 of the paper's press on copper with 0.3 mm of dead travel
                // shifted by 0.12 mm (216 J, 3.3 % of the blow; 8 nm at rtol 1e-8).
                let e = self.eval(y, mode);
                let (f_l, frictionless) = self.upset(e.h_m, e.ddelta_mps);
                let dp = (e.contact_n - f_l) / self.k_contact_n_per_m;
                let work = 0.5 * (e.contact_n + f_l) * dp;
                let share = frictionless_share(f_l, frictionless);
                y[P] += dp;
                y[WP] += work * share;
                y[WF] += work * (1.0 - share);
                next.contact = Contact::Elastic;
            }
            G_ENGAGE => next.engaged = true,
            G_DISENGAGE => next.engaged = false,
            _ => {}
        }
        self.settle(y, next)
    }

    fn max_step(&self) -> f64 {
        self.max_step_s
    }
}
