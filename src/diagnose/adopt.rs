//! What `diagnose` found, as a machine file (issue 37): the input `machine.toml` with the
//! verdict's effects under `[effects.NAME]` (their fitted parameters), and a `[diagnosed]`
//! table with the provenance (the verdict, the calibration and holdout directories, the
//! date, the holdout shrink) and each parameter's relative standard error. The base
//! parameters are left as they were: the diagnosis fits the effects on the base model, it
//! does not refit the base. Every other line of the input, comments included, is kept
//! (`toml_edit`). Pure code: the caller reads and writes the files and the clock.

use nalgebra::DMatrix;

use super::attribute::library;
use super::blowset::BlowSet;
use crate::physics::effects::{Effect, EffectSet};
use crate::physics::machine::Machine;

/// The provenance of an adopted effect.
#[derive(Debug, Clone, PartialEq)]
pub struct Provenance {
    /// The verdict's name (`"a"` or `"a+b"`).
    pub verdict: String,
    pub calib: String,
    pub holdout: String,
    /// When the diagnosis ran, RFC 3339.
    pub date: String,
    pub holdout_shrink: f64,
}

/// A fitted parameter's relative standard error, by `EFFECT.PARAM`.
pub type RelSd = Vec<(String, f64)>;

/// Relative step of the finite differences, in ln of each parameter.
const LN_STEP: f64 = 1e-3;

/// The relative standard errors of the fitted parameters of `effects` on the calibration
/// blows: the Jacobian of `calib`'s residuals in the logarithms of the parameters (forward
/// differences), the residuals' variance from their own sum of squares over the degrees of
/// freedom, `cov = s² (JᵀJ)⁻¹`. It covers the measurement's noise and the residual misfit
/// of the model, not the base parameters' own errors (held fixed). A direction the blows
/// do not determine has an infinite error; `None` where the model cannot simulate the blows.
pub fn rel_sd(machine: &Machine, base: &EffectSet, effects: &[Effect], calib: &BlowSet) -> Option<RelSd> {
    let lib = library(machine.kind());
    // Each effect's fitted parameters, by the library's keys, and its builder.
    let mut params: Vec<(usize, &'static str, f64)> = Vec::new();
    let mut cands = Vec::new();
    for (i, e) in effects.iter().enumerate() {
        let c = lib.iter().find(|c| c.name == e.name())?;
        let given = e.params();
        for p in &c.params {
            let v = given.iter().find(|(k, _)| *k == p.key).map_or(0.0, |(_, v)| *v);
            params.push((i, p.key, v));
        }
        cands.push(c);
    }
    let set_of = |values: &[f64]| {
        let mut s = *base;
        let mut k = 0;
        for c in &cands {
            let n = c.params.len();
            s.apply(&c.effect(&values[k..k + n]));
            k += n;
        }
        s
    };
    let values: Vec<f64> = params.iter().map(|p| p.2).collect();
    let r0 = calib.residuals(machine, &set_of(&values))?;
    let (n, p) = (r0.len(), values.len());
    let mut jac = DMatrix::<f64>::zeros(n, p);
    for j in 0..p {
        let mut v = values.clone();
        v[j] *= LN_STEP.exp();
        let r = calib.residuals(machine, &set_of(&v))?;
        for i in 0..n {
            jac[(i, j)] = (r[i] - r0[i]) / LN_STEP;
        }
    }
    let s2 = r0.iter().map(|x| x * x).sum::<f64>() / (n.saturating_sub(p)).max(1) as f64;
    let jtj = jac.transpose() * &jac;
    let cov = jtj.try_inverse().map(|inv| inv * s2);
    Some(
        params
            .iter()
            .enumerate()
            .map(|(j, (i, key, _))| {
                let sd = cov.as_ref().map_or(f64::INFINITY, |c| c[(j, j)].max(0.0).sqrt());
                (format!("{}.{key}", effects[*i].name()), if sd.is_finite() { sd } else { f64::INFINITY })
            })
            .collect(),
    )
}

/// `input` (a `machine.toml`'s text) with `effects` under `[effects.NAME]`, replacing any
/// table of the same name, and `[diagnosed]` holding `provenance` and `sd`, replacing any
/// earlier one. An error only if `input` is not TOML.
pub fn machine_toml(
    input: &str,
    effects: &[Effect],
    provenance: &Provenance,
    sd: &RelSd,
) -> Result<String, toml_edit::TomlError> {
    use toml_edit::{DocumentMut, Item, Table, value};
    let mut doc: DocumentMut = input.parse()?;
    if !doc.contains_table("effects") {
        let mut t = Table::new();
        t.set_implicit(true);
        doc.insert("effects", Item::Table(t));
    }
    for e in effects {
        let mut t = Table::new();
        for (k, v) in e.params() {
            t.insert(k, value(v));
        }
        t.decor_mut().set_prefix(format!(
            "\n# Adopted from `forgemon diagnose` ({}): see [diagnosed] below.\n",
            provenance.date
        ));
        doc["effects"][e.name()] = Item::Table(t);
    }
    let mut d = Table::new();
    d.decor_mut().set_prefix(
        "\n# What `forgemon diagnose` found and this file adopted: the verdict, where its effect was fitted\n\
         # (calib) and scored (holdout), when, the holdout error it removed, and each fitted parameter's\n\
         # relative standard error (noise and misfit on the calibration blows; the base parameters\n\
         # above are as identified, not refitted).\n",
    );
    d.insert("verdict", value(provenance.verdict.clone()));
    d.insert("calib", value(provenance.calib.clone()));
    d.insert("holdout", value(provenance.holdout.clone()));
    d.insert("date", value(provenance.date.clone()));
    d.insert("holdout_shrink", value((provenance.holdout_shrink * 1e4).round() / 1e4));
    let mut rel = Table::new();
    for (k, v) in sd {
        // TOML has no infinity in every reader's hands: an undetermined direction is -1.
        rel.insert(k, value(if v.is_finite() { (v * 1e4).round() / 1e4 } else { -1.0 }));
    }
    d.insert("rel_sd", Item::Table(rel));
    doc.insert("diagnosed", Item::Table(d));
    Ok(doc.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::parse_machine;

    const HAMMER: &str = "# Identified on blows 1-5.\nkind = \"hammer\"\nm1_kg = 732  # ram\nm2_kg = 19\n\
                          k_N_per_m = 3.15e9\nc_Ns_per_m = 18540\n";

    fn provenance() -> Provenance {
        Provenance {
            verdict: "foundation".into(),
            calib: "calib".into(),
            holdout: "holdout".into(),
            date: "2026-11-28T08:00:00+00:00".into(),
            holdout_shrink: 0.8312,
        }
    }

    /// The written file loads as a machine file with the effect, keeps the input's lines,
    /// and a second adoption replaces the first instead of adding to it.
    #[test]
    fn the_adopted_file_loads_with_the_effect_and_keeps_the_input() {
        let found = [Effect::Foundation { m3_kg: 1500.0, k3_n_per_m: 4e9, c3_ns_per_m: 1.5e5 }];
        let sd = vec![("foundation.m3_kg".to_string(), 0.041), ("foundation.c3_Ns_per_m".to_string(), f64::INFINITY)];
        let text = machine_toml(HAMMER, &found, &provenance(), &sd).unwrap();
        assert!(text.starts_with(HAMMER), "{text}");
        let m = parse_machine("out.toml", &text).unwrap();
        assert_eq!(m.effects, found.to_vec());
        assert!(text.contains("holdout_shrink = 0.8312") && text.contains("\"foundation.m3_kg\" = 0.041"), "{text}");
        assert!(text.contains("\"foundation.c3_Ns_per_m\" = -1"), "{text}");
        let again = [Effect::Foundation { m3_kg: 1600.0, k3_n_per_m: 4e9, c3_ns_per_m: 1.5e5 }];
        let text2 = machine_toml(&text, &again, &provenance(), &sd).unwrap();
        assert_eq!(parse_machine("out.toml", &text2).unwrap().effects, again.to_vec());
        assert_eq!(text2.lines().filter(|l| *l == "[diagnosed]").count(), 1, "{text2}");
        // Another effect joins the one adopted before.
        let rise = [Effect::FrictionRise { exponent: 0.8 }];
        let text3 = machine_toml(&text2, &rise, &provenance(), &sd).unwrap();
        assert_eq!(parse_machine("out.toml", &text3).unwrap().effects.len(), 2, "{text3}");
        assert!(machine_toml("kind = ", &rise, &provenance(), &sd).is_err());
    }
}
