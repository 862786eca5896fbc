//! A blow's signature for a recipe: its §5 figures and its load against the compression,
//! the ram's travel since first contact as the encoder saw it, on the loading branch (first
//! contact to the deepest point). The travel includes the machine's elastic give, the same
//! on every blow of a machine, so the curve is a like-for-like fingerprint of the part.

use crate::signal::segment::Blow;

/// Most points kept of a curve.
pub const SIGNATURE_POINTS: usize = 200;

/// What a recipe judges of a blow.
#[derive(Debug, Clone, PartialEq)]
pub struct Signature {
    pub efficiency: f64,
    pub plastic_j: f64,
    pub peak_load_n: f64,
    /// (compression m, load N), compression strictly increasing from 0.
    pub curve: Vec<(f64, f64)>,
}

impl Signature {
    /// The deepest compression of the loading branch, m.
    pub fn max_compression_m(&self) -> f64 {
        self.curve.last().map_or(0.0, |p| p.0)
    }

    /// The load at compression `x_m`, linearly between points, held at the ends.
    pub fn load_at(&self, x_m: f64) -> f64 {
        let c = &self.curve;
        let Some(first) = c.first() else { return 0.0 };
        if x_m <= first.0 {
            return first.1;
        }
        let i = c.partition_point(|p| p.0 < x_m);
        match (c.get(i.wrapping_sub(1)), c.get(i)) {
            (Some(a), Some(b)) => a.1 + (b.1 - a.1) * (x_m - a.0) / (b.0 - a.0).max(f64::MIN_POSITIVE),
            (Some(a), None) => a.1,
            _ => first.1,
        }
    }
}

/// What a recipe takes from a blow's estimate (`estimate::BlowEstimate`'s fields of the
/// same names); `None` where the estimate has none, so that an incomplete blow has no
/// signature.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimated {
    pub efficiency: Option<f64>,
    pub plastic_j: Option<f64>,
    pub peak_load_n: f64,
    /// First contact, device time, s.
    pub t_contact_s: f64,
}

/// The signature of a blow estimated whole; `None` for an incomplete one (never judged).
/// The load is averaged over `ring_period_s` centred on each sample (the machine's second
/// mode, `Machine::second_mode_hz`): a box that long cancels the ring, whose phase moves
/// from billet to billet, and keeps the forming load the recipe is about.
pub fn signature(blow: &Blow, e: Estimated, ring_period_s: f64) -> Option<Signature> {
    let (efficiency, plastic_j) = (e.efficiency?, e.plastic_j?);
    let s = &blow.samples;
    let end = blow.i_end.min(s.len().checked_sub(1)?);
    let ic = blow.i_contact.min(end);
    // The encoder at first contact, between the samples around it.
    let x0 = match ic.checked_sub(1) {
        Some(ip) if s[ic].t_s > s[ip].t_s && e.t_contact_s < s[ic].t_s => {
            let f = ((e.t_contact_s - s[ip].t_s) / (s[ic].t_s - s[ip].t_s)).clamp(0.0, 1.0);
            s[ip].disp_m + f * (s[ic].disp_m - s[ip].disp_m)
        }
        _ => s[ic].disp_m,
    };
    let deepest = (ic..=end).max_by(|&a, &b| s[a].disp_m.total_cmp(&s[b].disp_m)).unwrap_or(ic);
    let half = ((0.5 * ring_period_s / blow.period_s).round() as usize).min(s.len() / 2);
    let smoothed = |k: usize| {
        let (a, b) = (k.saturating_sub(half), (k + half).min(s.len() - 1));
        s[a..=b].iter().map(|x| x.load_n).sum::<f64>() / (b - a + 1) as f64 - blow.load_zero_n
    };
    let mut curve: Vec<(f64, f64)> = vec![(0.0, 0.0)];
    for (k, smp) in s.iter().enumerate().take(deepest + 1).skip(ic) {
        let x = smp.disp_m - x0;
        let load = smoothed(k);
        match curve.last_mut() {
            // Encoder steps: samples on the same count share a point, the highest load kept.
            Some(last) if x <= last.0 => last.1 = last.1.max(load),
            _ => curve.push((x, load)),
        }
    }
    if curve.len() > SIGNATURE_POINTS {
        let step = curve.len().div_ceil(SIGNATURE_POINTS);
        let last = *curve.last()?;
        curve = curve.into_iter().step_by(step).collect();
        if curve.last() != Some(&last) {
            curve.push(last);
        }
    }
    Some(Signature { efficiency, plastic_j, peak_load_n: e.peak_load_n, curve })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn load_at_interpolates_and_holds_the_ends() {
        let s = Signature {
            efficiency: 0.9,
            plastic_j: 1.0,
            peak_load_n: 2.0,
            curve: vec![(0.0, 0.0), (1e-3, 1e5), (3e-3, 3e5)],
        };
        assert_eq!(s.load_at(-1.0), 0.0);
        assert!((s.load_at(0.5e-3) - 0.5e5).abs() < 1e-6);
        assert!((s.load_at(2e-3) - 2e5).abs() < 1e-6);
        assert_eq!(s.load_at(9.0), 3e5);
        assert_eq!(s.max_compression_m(), 3e-3);
    }
}
