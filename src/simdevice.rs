//! The simulated machine behind the simulated devices (DESIGN.md §4): a hammer or press
//! forging billet after billet (approach, blow, rebound, a pause, the next blow; a new
//! billet when one is finished), as one continuous stream of samples at the DAQ's rate,
//! with the sensor imperfections of `synth`. Transports (a pty with the serial framing, a
//! Modbus server, a candump log) encode what it yields. Pure: the caller paces it.

use std::collections::VecDeque;

use crate::physics::effects::EffectSet;
use crate::physics::machine::Machine;
use crate::physics::process::Process;
use crate::physics::sequence::SequenceError;
use crate::signal::capture::CaptureRow;
use crate::synth::{CaptureSpec, idle_rows, synth_blows};

/// One billet's worth of forging.
#[derive(Debug, Clone, PartialEq)]
pub struct BilletPlan {
    pub process: Process,
    /// Impact speed of each blow, m/s.
    pub v0s_mps: Vec<f64>,
}

/// A machine forging a list of billets, blow after blow, with `interval_s` between blows.
pub struct SimMachine {
    machine: Machine,
    effects: EffectSet,
    plans: Vec<BilletPlan>,
    spec: CaptureSpec,
    interval_s: f64,
    next_billet: usize,
    queue: VecDeque<CaptureRow>,
    /// Samples emitted so far (the stream's clock is `t0 + n / rate`).
    emitted: u64,
    t0_s: f64,
    last_disp_m: f64,
    seed: u64,
}

impl SimMachine {
    pub fn new(
        machine: Machine,
        effects: EffectSet,
        plans: Vec<BilletPlan>,
        spec: CaptureSpec,
        interval_s: f64,
    ) -> Self {
        let seed = spec.seed;
        SimMachine {
            machine,
            effects,
            plans,
            t0_s: spec.t_origin_s,
            spec,
            interval_s,
            next_billet: 0,
            queue: VecDeque::new(),
            emitted: 0,
            last_disp_m: 0.4375,
            seed,
        }
    }

    pub fn sample_rate_hz(&self) -> f64 {
        self.spec.sample_rate_hz
    }

    /// Whether every billet has been forged and every sample handed out.
    pub fn finished(&self) -> bool {
        self.next_billet >= self.plans.len() && self.queue.is_empty()
    }

    /// Billets started so far.
    pub fn billets_started(&self) -> usize {
        self.next_billet
    }

    /// Forge the next billet into the queue: for each blow, a pause, then the blow.
    fn forge_next_billet(&mut self) -> Result<(), SequenceError> {
        let plan = &self.plans[self.next_billet];
        self.next_billet += 1;
        let mut spec = self.spec;
        spec.seed = self.seed.wrapping_add(self.next_billet as u64);
        let blows = synth_blows(&self.machine, &self.effects, &plan.process, &plan.v0s_mps, &spec)?;
        for (i, b) in blows.iter().enumerate() {
            let pause = ((self.interval_s * self.spec.sample_rate_hz) as usize).saturating_sub(b.rows.len());
            let disp0 = b.rows.first().map_or(self.last_disp_m, |r| r.disp_m);
            self.queue.extend(idle_rows(pause, 0.0, &spec, disp0, spec.seed.wrapping_mul(31).wrapping_add(i as u64)));
            self.queue.extend(b.rows.iter().copied());
            self.last_disp_m = b.rows.last().map_or(self.last_disp_m, |r| r.disp_m);
        }
        Ok(())
    }

    /// The next `n` samples (fewer once the last billet is done), on one continuous clock.
    pub fn next_rows(&mut self, n: usize) -> Result<Vec<CaptureRow>, SequenceError> {
        while self.queue.len() < n && self.next_billet < self.plans.len() {
            self.forge_next_billet()?;
        }
        let take = n.min(self.queue.len());
        let dt = 1.0 / self.spec.sample_rate_hz;
        let mut out: Vec<CaptureRow> = self.queue.drain(..take).collect();
        for r in &mut out {
            r.t_s = self.t0_s + self.emitted as f64 * dt;
            self.emitted += 1;
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{parse_machine, parse_process};

    #[test]
    fn a_session_is_one_continuous_stream_holding_every_blow() {
        let m = parse_machine("m", include_str!("../config/hammer-lg1000.machine.toml")).unwrap().machine;
        let p = parse_process("p", include_str!("../config/steel-16NiCrMo13.process.toml")).unwrap();
        let plan = BilletPlan { process: p, v0s_mps: vec![3.9, 5.3] };
        let mut sim = SimMachine::new(m, EffectSet::NONE, vec![plan.clone(), plan], CaptureSpec::hammer(3), 0.5);
        let mut rows = Vec::new();
        while !sim.finished() {
            rows.extend(sim.next_rows(7919).unwrap());
        }
        // Four blows of 0.5 s each at 100 kHz.
        assert_eq!(rows.len(), 4 * 50_000);
        assert!(rows.windows(2).all(|w| ((w[1].t_s - w[0].t_s) - 1e-5).abs() < 1e-9));
        // Four distinct load peaks well above the noise.
        let peaks = rows.windows(2).filter(|w| w[0].load_n < 200e3 && w[1].load_n >= 200e3).count();
        assert!(peaks >= 4, "{peaks}");
    }
}
