//! A blow's energies and end height from each of the estimator's methods: the model fit's
//! simulated blow, or the model observer run on the samples, split by the billet's law
//! into plastic and friction work. Methods of `Estimator`, after `estimate` has found the
//! impact and the start height.

use super::result::{BlowEstimate, HeightSource};
use super::{Estimator, MIN_TRACKED_HEIGHT_FRACTION, Method, curve, fit, observer};
use crate::physics::billet::BilletLaw;
use crate::physics::machine::Machine;
use crate::signal::sample::Role;
use crate::signal::segment::Blow;

impl Estimator {
    /// The energies and the end height from the fitted simulated blow. Returns the height.
    pub(super) fn fill_from_fit(&mut self, e: &mut BlowEstimate, blow: &Blow, f: &fit::ModelFit) -> Option<f64> {
        self.last_method = Some(Method::ModelFit);
        e.method = self.last_method;
        self.last_course = Some(curve::Course {
            model_load: f.blow.trace.iter().map(|p| (p.t_s, p.out.sensor_n)).collect(),
            forming_time_s: f.blow.forming.map(|fm| fm.forming_time_s),
            spring_back_time_s: f.blow.forming.and_then(|fm| fm.spring_back_time_s),
        });
        let l = f.blow.energy;
        // The model supplies the set, corrected by what the encoder saw in the spring-back
        // (`fit::spring_back_set_offset`); the start is the billet's (the encoder chain's),
        // which the fit's own start may miss by up to `REFIT_HEIGHT_M`.
        let h0 = e.h_start_m.unwrap_or(f.h_start_m);
        let missed_m = f.set_offset_m.unwrap_or(0.0);
        let h_end = f.blow.forming.map(|fm| h0 - (f.h_start_m - fm.h_end_m) - missed_m);
        let lost = match (&self.process, h_end) {
            (Some(p), Some(h)) => h < MIN_TRACKED_HEIGHT_FRACTION * p.billet.height_m,
            _ => true,
        };
        let (plastic_j, friction_j, h_end_m) = if lost {
            self.h_m = None;
            self.chain = None;
            (l.plastic_j + l.friction_j, None, None)
        } else {
            self.h_m = h_end;
            self.h_source = HeightSource::Model;
            (l.plastic_j, Some(l.friction_j), h_end)
        };
        // Checked, not clamped: `plausibility::settle`.
        let efficiency = plastic_j / l.kinetic_in_j;
        e.t_contact_s = f.t_contact_s;
        e.v_impact_mps = f.v0_mps;
        e.kinetic_in_j = Some(l.kinetic_in_j);
        e.plastic_j = Some(plastic_j);
        e.friction_j = friction_j;
        e.damped_j = Some(l.damped_j);
        e.elastic_j = Some(l.elastic_j);
        e.efficiency = Some(efficiency);
        e.final_load_n = f.blow.forming.map_or(0.0, |fm| fm.final_load_n);
        e.h_end_m = h_end_m;
        e.class = self.cfg.classify(efficiency);
        // Without a load channel, the fitted model's peak at the sensor.
        e.peak_load_n = if e.channels.has(Role::Load) {
            blow.samples[blow.i_contact..=blow.i_end].iter().map(|s| s.load_n - blow.load_zero_n).fold(0.0, f64::max)
        } else {
            f.blow.trace.iter().map(|p| p.out.sensor_n).fold(0.0, f64::max)
        };
        // The ram's energy measured needs the accelerometer.
        e.residual = Some(f.ram_energy_residual).filter(|r| r.is_finite());
        e.flow_stress_scale = Some(f.scale);
        h_end_m
    }

    /// The energies and the end height from the model observer run on the samples, contact
    /// `delta0` samples after the contact sample. Returns the height.
    pub(super) fn fill_from_observer(
        &mut self,
        e: &mut BlowEstimate,
        blow: &Blow,
        h_start_m: Option<f64>,
        delta0: f64,
    ) -> Option<f64> {
        self.last_method = Some(Method::Observer);
        e.method = self.last_method;
        let v0 = e.v_impact_mps;
        let o = observer::observe(&self.machine, blow, v0);
        let forming_s = (o.forming_end as f64 - delta0) * blow.period_s;
        self.last_course = Some(curve::Course { forming_time_s: Some(forming_s), ..curve::Course::default() });
        // The observer's compression starts at the contact sample. On a press the support
        // is massless, so the ram's travel from the located contact to that sample was all
        // compression already; on a hammer the lower tool first moves with the ram and the
        // part missed is second order.
        let before_m = match self.machine {
            Machine::ScrewPress(_) => (-delta0).max(0.0) * blow.period_s * v0,
            Machine::Hammer(_) => 0.0,
        };
        let max_comp = o.set_m.max(0.0) + before_m;
        let (plastic_j, friction_j, h_end_m) = match (&self.billet_process, h_start_m) {
            (Some(p), Some(h0)) => {
                // The split's share (π r² σ over the whole load) is the friction's: the
                // flow-stress effects cancel from it, `friction_rise` does not.
                let law = BilletLaw::of(p, self.effects.load, self.billet_blows);
                let (mut plastic, mut friction, mut law_j) = (0.0, 0.0, 0.0);
                // The work and the law's work over each half of the compression.
                let half_m = 0.5 * (o.compression_m.iter().copied().fold(0.0, f64::max) + before_m);
                let (mut half_work, mut half_law) = ([0.0; 2], [0.0; 2]);
                let mut h_min = h0;
                for (comp, dw) in o.compression_m.iter().zip(&o.work_j) {
                    // The billet only gets flatter: its height is the running minimum.
                    let h = h_min.min(h0 - comp - before_m);
                    let l = law.load(h.max(1e-6), 0.0);
                    let half = usize::from(h0 - h > half_m);
                    half_law[half] += l.total_n * (h_min - h);
                    half_work[half] += dw;
                    law_j += l.total_n * (h_min - h);
                    h_min = h;
                    let share = if l.total_n > 0.0 { l.frictionless_n / l.total_n } else { 1.0 };
                    plastic += dw * share;
                    friction += dw * (1.0 - share);
                }
                e.flow_stress_scale = (law_j > 0.0).then(|| o.deform_j / law_j);
                e.scale_by_half = (half_law[0] > 0.0 && half_law[1] > 0.0)
                    .then(|| [half_work[0] / half_law[0], half_work[1] / half_law[1]]);
                let h_end = h0 - max_comp;
                if h_end < MIN_TRACKED_HEIGHT_FRACTION * p.billet.height_m {
                    // Lost track of the billet: report the work unsplit and no height.
                    self.h_m = None;
                    self.chain = None;
                    (o.deform_j, None, None)
                } else {
                    self.h_m = Some(h_end);
                    self.h_source = HeightSource::Model;
                    (plastic, Some(friction), Some(h_end))
                }
            }
            _ => (o.deform_j, None, None),
        };
        // Noise can make a soft blow's work a hair above the energy in, or a bounce's below
        // zero: `plausibility::settle` reports it at the bound, or the blow implausible.
        let efficiency = plastic_j / o.kinetic_in_j;
        e.kinetic_in_j = Some(o.kinetic_in_j);
        e.plastic_j = Some(plastic_j);
        e.friction_j = friction_j;
        e.damped_j = Some(o.damped_j);
        e.elastic_j = Some(o.elastic_j);
        e.efficiency = Some(efficiency);
        e.final_load_n = o.final_load_n;
        e.h_end_m = h_end_m;
        e.class = self.cfg.classify(efficiency);
        e.peak_load_n = o.peak_load_n;
        e.residual = Some((o.kinetic_in_j - o.deform_j - o.damped_j - o.elastic_j) / o.kinetic_in_j);
        h_end_m
    }
}
