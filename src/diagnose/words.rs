//! The verdict in a process engineer's words (issue 41): the effect, its fitted value in
//! engineering units with its interval, the holdout shrink and where it acts, then the
//! runner-up and the confidence.

use crate::physics::effects::{Effect, K_DIE_KEY};

use super::Diagnosis;
use super::confidence::ParamInterval;

/// `value` of `key` in engineering units, with `±` its interval's larger half-width.
fn value(key: &str, params: &[ParamInterval], v: f64) -> String {
    let pm =
        params.iter().find(|p| p.key == key).map(|p| p.rel_half_width()).filter(|w| *w > 0.0 && w.is_finite()).map_or(
            String::new(),
            |w| {
                // Under half a per cent the interval is stated as such, not rounded up to 1 %.
                if w < 0.005 { " (± under 1 %)".to_string() } else { format!(" ± {:.0} %", w * 100.0) }
            },
        );
    let unit = match key {
        "gap_m" => format!("{:.2} mm", v * 1e3),
        "k_contact_N_per_m" | "k3_N_per_m" | K_DIE_KEY => format!("{:.2} GN/m", v / 1e9),
        "m_lower_kg" | "m3_kg" if v >= 1000.0 => format!("{:.1} t", v / 1e3),
        "m_lower_kg" | "m3_kg" => format!("{v:.0} kg"),
        "c3_Ns_per_m" => format!("{:.0} kN s/m", v / 1e3),
        "tau_s" => format!("{:.1} ms", v * 1e3),
        "rate_ref_per_s" => format!("{v:.3} /s"),
        _ => format!("{v:.3}"),
    };
    format!("{unit}{pm}")
}

/// One effect with its fitted values, as a phrase ("a contact compliance of 1.00 GN/m ± 4 %").
pub fn describe(e: &Effect, params: &[ParamInterval]) -> String {
    let v = |key: &str, x: f64| value(key, params, x);
    match *e {
        Effect::Clearance { gap_m, m_lower_kg, k_die_n_per_m } if m_lower_kg > 0.0 => {
            let die =
                format!("a clearance of {} under a lower die of {}", v("gap_m", gap_m), v("m_lower_kg", m_lower_kg));
            if k_die_n_per_m.is_finite() {
                format!("{die}, struck through a contact of {}", v(K_DIE_KEY, k_die_n_per_m))
            } else {
                die
            }
        }
        Effect::Clearance { gap_m, .. } => format!("a clearance of {} under the lower tool", v("gap_m", gap_m)),
        Effect::ElasticRecovery { k_contact_n_per_m } => {
            format!("a contact compliance of {}", v("k_contact_N_per_m", k_contact_n_per_m))
        }
        Effect::FrictionRise { exponent } => {
            format!("friction rising as the billet flattens, μ ∝ (h0/h)^p with p = {}", v("exponent", exponent))
        }
        Effect::StrainRate { m, rate_ref_per_s } => format!(
            "a strain-rate sensitivity m = {} (reference rate {})",
            v("m", m),
            v("rate_ref_per_s", rate_ref_per_s)
        ),
        Effect::StrainHardening { n, eps_ref } => {
            format!("strain hardening n = {} (reference strain {})", v("n", n), v("eps_ref", eps_ref))
        }
        Effect::Thermal { q_dt } => {
            format!("a billet cooling blow by blow, flow stress × exp({} per blow)", v("q_dT", q_dt))
        }
        Effect::Foundation { m3_kg, k3_n_per_m, c3_ns_per_m } => format!(
            "a foundation of {} on {} (damper {})",
            v("m3_kg", m3_kg),
            v("k3_N_per_m", k3_n_per_m),
            v("c3_Ns_per_m", c3_ns_per_m)
        ),
        Effect::SensorHighpass { tau_s } => {
            format!("a load-sensor high-pass (charge amplifier) of time constant {}", v("tau_s", tau_s))
        }
    }
}

/// The report's opening: what, how much it closes, where it acts; then the runner-up and
/// how sure the verdict is.
pub fn opening(d: &Diagnosis) -> String {
    let c = &d.confidence;
    let sure = format!(
        "{:.0} % of {} bootstrap resamples of the blows reach the same verdict",
        c.agreement * 100.0,
        c.resamples
    );
    let runner = c.runner_up.as_ref().map_or(String::new(), |r| format!(" The runner-up is {}: {}.", r.name, r.why));
    let Some(v) = &d.verdict else {
        return format!(
            "No unmodelled effect is named: the base model's holdout error is {:.1} % of the peak against {:.1} % of sensor noise.{runner} {sure}.",
            d.baseline_holdout * 100.0,
            d.noise_nrmse * 100.0
        );
    };
    let what: Vec<String> = v.effects.iter().map(|e| describe(e, &c.params)).collect();
    let what = what.join(" together with ");
    let shrink = 1.0 - v.holdout / d.baseline_holdout;
    let interval = c
        .shrink_interval
        .map_or(String::new(), |(a, b)| format!(" (90 % interval {:.0}–{:.0} %)", a * 100.0, b * 100.0));
    let acts = d.acts.map_or(String::new(), |a| {
        format!(
            "; it acts in the {} phase and the {} band, where it removes {:.0} % of the base model's error",
            a.phase().replace('_', "-"),
            a.band(),
            a.removed_by_phase.iter().copied().fold(f64::MIN, f64::max) * 100.0
        )
    });
    let head = match &c.uncertain_between {
        Some((a, b)) if !c.settled.is_empty() => {
            let shares: Vec<String> = c
                .settled
                .iter()
                .map(|e| {
                    let s = c.effects.iter().find(|(k, _)| k == e).map_or(0.0, |x| x.1);
                    format!("{e} ({:.0} % of the resamples name it)", s * 100.0)
                })
                .collect();
            format!(
                "Uncertain between {a} and {b}, but settled on {}: the doubt is only about what goes with it. The rule's choice is ",
                shares.join(" and ")
            )
        }
        Some((a, b)) => format!("Uncertain between {a} and {b}. The rule's choice is "),
        None => String::new(),
    };
    let mut first = format!(
        "{head}{what} ({}) closes {:.0} % of the gap on the held-out blows{interval}{acts}.",
        v.name,
        shrink * 100.0
    );
    if let Some(f) = first.get(..1) {
        first = f.to_uppercase() + &first[1..];
    }
    format!("{first}{runner} {sure}.")
}
