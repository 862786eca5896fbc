//! The pipeline's input from several sources (DESIGN.md §3, issue #4): for example the load
//! and the accelerometer on one DAQ over serial, the ram encoder on another over CAN.
//!
//! A batch that carries all three roles goes to the pipeline as it is. Otherwise the roles
//! are merged onto one timeline: the samples of the source that carries the acceleration
//! (the trigger channel). Every source's device clock is mapped onto host time by its own
//! [`ClockModel`]; each missing role is interpolated linearly, at the host time of each
//! timeline sample, from the source that carries it. A timeline batch waits until every
//! other role has samples past its end, or until the newest batch from any source is
//! `max_lag_ns` younger than it; then a role whose source is late is held at its last value
//! (counted), and a role never seen drops the batch (counted).
//!
//! Pure and deterministic: everything depends on the batches and their recorded host
//! receive times, in arrival order. A recording stores exactly those, in that order, so a
//! replay merges exactly as the live service did.

use std::collections::{HashMap, VecDeque};

use super::align::ClockModel;
use super::sample::{Channels, Role, SampleBatch};

/// Source name of merged batches.
pub const MERGED_SOURCE: &str = "merged";

/// How long a timeline batch may wait for the other sources, host time. A Modbus poll every
/// 10–50 ms or a CAN batch of 20 ms arrives well within it; a source that is later than
/// this is treated as late and held.
pub const DEFAULT_MAX_LAG_NS: i64 = 250_000_000;

/// Host time an interpolation track keeps behind the newest sample (bounds its memory when
/// the timeline source stops).
const TRACK_KEEP_NS: f64 = 2e9;

/// What the merge did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct MergeStats {
    /// Timeline samples merged and handed on.
    pub merged_samples: u64,
    /// Role values held at the source's last sample because it was late (or had not
    /// started yet at the very beginning).
    pub held_values: u64,
    /// Timeline samples dropped because a role had never been seen.
    pub dropped_samples: u64,
}

/// One role from a source other than the timeline: (host ns, value), in time order.
#[derive(Debug, Clone)]
struct Track {
    source: String,
    points: VecDeque<(f64, f64)>,
}

/// Routes sample batches to the pipeline, merging partial ones.
#[derive(Debug, Clone)]
pub struct Merger {
    max_lag_ns: i64,
    clocks: HashMap<String, ClockModel>,
    /// The source whose sample times the merged batches take.
    timeline: Option<String>,
    /// The roles the timeline source carries.
    timeline_roles: Vec<Role>,
    tracks: HashMap<Role, Track>,
    pending: VecDeque<SampleBatch>,
    /// Newest host receive time of any batch.
    newest_host_ns: i64,
    stats: MergeStats,
    /// The roles no source carries (a hammer without a load cell): not waited for, the
    /// pipeline's batches go without them (`set_absent`).
    absent: Channels,
}

impl Default for Merger {
    fn default() -> Self {
        Merger::new(DEFAULT_MAX_LAG_NS)
    }
}

impl Merger {
    pub fn new(max_lag_ns: i64) -> Self {
        Merger {
            max_lag_ns,
            clocks: HashMap::new(),
            timeline: None,
            timeline_roles: Vec::new(),
            tracks: HashMap::new(),
            pending: VecDeque::new(),
            newest_host_ns: i64::MIN,
            stats: MergeStats::default(),
            absent: Channels::NONE,
        }
    }

    /// The roles no source carries: a batch is whole without them, and none is waited for.
    pub fn set_absent(&mut self, absent: Channels) {
        self.absent = absent;
    }

    pub fn absent(&self) -> Channels {
        self.absent
    }

    /// The roles a batch needs to go on: all but the absent ones.
    fn needed(&self) -> impl Iterator<Item = Role> + '_ {
        Role::ALL.into_iter().filter(|r| !self.absent.has(*r))
    }

    /// Take one batch from any source. Returns true when the batch itself carries every
    /// role and goes to the pipeline as it is; merged batches that became complete are
    /// appended to `out`.
    pub fn push(&mut self, batch: &SampleBatch, out: &mut Vec<SampleBatch>) -> bool {
        if batch.is_empty() {
            return false;
        }
        let clock = self.clocks.entry(batch.source.clone()).or_default();
        // The batch's last sample arrived with it.
        clock.observe(last_device_ns(batch), batch.host_time_ns);
        self.newest_host_ns = self.newest_host_ns.max(batch.host_time_ns);
        if self.needed().all(|r| batch.channel(r).is_some()) {
            return true;
        }
        if self.timeline.is_none() && batch.channel(Role::Acc).is_some() {
            self.timeline = Some(batch.source.clone());
            self.timeline_roles = batch.roles.clone();
        }
        if self.timeline.as_deref() == Some(batch.source.as_str()) {
            self.pending.push_back(batch.clone());
        } else {
            self.add_to_tracks(batch);
        }
        self.emit_ready(out);
        false
    }

    /// The clock model of a source, once it has sent a batch.
    pub fn clock(&self, source: &str) -> Option<&ClockModel> {
        self.clocks.get(source)
    }

    pub fn stats(&self) -> MergeStats {
        self.stats
    }

    fn add_to_tracks(&mut self, batch: &SampleBatch) {
        let clock = &self.clocks[&batch.source];
        for (c, role) in batch.roles.iter().enumerate() {
            if self.timeline_roles.contains(role) || *role == Role::Acc {
                continue;
            }
            let track = self
                .tracks
                .entry(*role)
                .or_insert_with(|| Track { source: batch.source.clone(), points: VecDeque::new() });
            // One source per role: the first one seen.
            if track.source != batch.source {
                continue;
            }
            let n_ch = batch.roles.len();
            for i in 0..batch.len() {
                let h = map_f64(clock, batch.device_time_ns as f64 + batch.period_ns * i as f64);
                let v = batch.values[i * n_ch + c];
                // Out-of-order host times (a clock estimate that moved) are dropped, not
                // interleaved: interpolation needs a monotonic track.
                if track.points.back().is_none_or(|(hb, _)| h > *hb) && v.is_finite() {
                    track.points.push_back((h, v));
                }
            }
            if let Some(&(newest, _)) = track.points.back() {
                while track.points.len() > 2 && track.points[1].0 < newest - TRACK_KEEP_NS {
                    track.points.pop_front();
                }
            }
        }
    }

    fn emit_ready(&mut self, out: &mut Vec<SampleBatch>) {
        while let Some(front) = self.pending.front() {
            let clock = &self.clocks[&front.source];
            let h_last = map_f64(clock, last_device_ns(front) as f64);
            let missing: Vec<Role> = self.needed().filter(|r| front.channel(*r).is_none()).collect();
            let covered = missing
                .iter()
                .all(|r| self.tracks.get(r).and_then(|t| t.points.back()).is_some_and(|(h, _)| *h >= h_last));
            let overdue = (self.newest_host_ns as f64) > h_last + self.max_lag_ns as f64;
            if !covered && !overdue {
                return;
            }
            let Some(batch) = self.pending.pop_front() else { return };
            if missing.iter().any(|r| self.tracks.get(r).is_none_or(|t| t.points.is_empty())) {
                self.stats.dropped_samples += batch.len() as u64;
                continue;
            }
            out.push(self.merge(&batch, &missing));
        }
    }

    fn merge(&mut self, batch: &SampleBatch, missing: &[Role]) -> SampleBatch {
        let clock = &self.clocks[&batch.source];
        let n = batch.len();
        let n_in = batch.roles.len();
        let mut roles = batch.roles.clone();
        roles.extend_from_slice(missing);
        let n_out = roles.len();
        let mut values = vec![0.0; n * n_out];
        for i in 0..n {
            values[i * n_out..i * n_out + n_in].copy_from_slice(&batch.values[i * n_in..(i + 1) * n_in]);
        }
        for (k, role) in missing.iter().enumerate() {
            let Some(track) = self.tracks.get_mut(role) else { continue };
            let pts = &track.points;
            let mut j = 0;
            for i in 0..n {
                let h = map_f64(clock, batch.device_time_ns as f64 + batch.period_ns * i as f64);
                while j + 1 < pts.len() && pts[j + 1].0 <= h {
                    j += 1;
                }
                let (h0, v0) = pts[j];
                let v = match pts.get(j + 1) {
                    Some(&(h1, v1)) if h >= h0 => v0 + (v1 - v0) * (h - h0) / (h1 - h0),
                    _ => {
                        self.stats.held_values += 1;
                        v0
                    }
                };
                values[i * n_out + n_in + k] = v;
            }
            // What lies before this batch is no longer needed (keep one point before it).
            let h_first = map_f64(clock, batch.device_time_ns as f64);
            while track.points.len() > 2 && track.points[1].0 <= h_first {
                track.points.pop_front();
            }
        }
        self.stats.merged_samples += n as u64;
        SampleBatch {
            source: MERGED_SOURCE.to_string(),
            seq: batch.seq,
            device_time_ns: batch.device_time_ns,
            host_time_ns: batch.host_time_ns,
            period_ns: batch.period_ns,
            roles,
            values,
        }
    }
}

/// Device time of a batch's last sample.
fn last_device_ns(b: &SampleBatch) -> i64 {
    b.device_time_ns + (b.period_ns * b.len().saturating_sub(1) as f64).round() as i64
}

/// Host time of a device time, sub-nanosecond (the mapped times of consecutive samples
/// must keep their order and spacing).
fn map_f64(clock: &ClockModel, device_ns: f64) -> f64 {
    let whole = device_ns.floor();
    clock.map(whole as i64) as f64 + (device_ns - whole) * clock.rate()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn batch(
        source: &str,
        roles: &[Role],
        t0_ns: i64,
        host_ns: i64,
        period_ns: f64,
        f: impl Fn(Role, f64) -> f64,
    ) -> SampleBatch {
        let n = 100;
        let mut values = Vec::new();
        for i in 0..n {
            let t = t0_ns as f64 + period_ns * i as f64;
            for r in roles {
                values.push(f(*r, t));
            }
        }
        SampleBatch {
            source: source.into(),
            seq: 0,
            device_time_ns: t0_ns,
            host_time_ns: host_ns,
            period_ns,
            roles: roles.to_vec(),
            values,
        }
    }

    #[test]
    fn a_full_batch_passes_through() {
        let mut m = Merger::default();
        let mut out = Vec::new();
        let b = batch("daq", &Role::ALL, 0, 0, 1e4, |_, t| t);
        assert!(m.push(&b, &mut out));
        assert!(out.is_empty());
    }

    /// An encoder on its own clock (3.7 s ahead, running 40 ppm fast, 10 kHz) merged onto
    /// a 100 kHz load/accelerometer timeline: the position at each timeline sample is the
    /// true one, because both clocks are mapped onto the host's.
    #[test]
    fn a_role_from_another_clock_lands_at_the_right_time() {
        let mut m = Merger::default();
        let mut out = Vec::new();
        // True position as a function of host time (ns): a slow sine, 1 mm amplitude.
        let pos = |h: f64| 1e-3 * (h * 1e-9 * 2.0 * std::f64::consts::PI * 3.0).sin();
        // Encoder device time d maps to host h = (d - 3.7e9) / (1 + 40e-6).
        let enc_host = |d: f64| (d - 3.7e9) / (1.0 + 40e-6);
        for k in 0..400i64 {
            // 1 ms timeline batches (100 samples at 10 µs) and 10 ms encoder batches, each
            // received 0.2 ms after its last sample. (Equal minimum delays: receive times
            // cannot tell a constant transport delay from a clock offset.)
            let t0 = k * 1_000_000;
            let daq = batch("daq", &[Role::Load, Role::Acc], t0, t0 + 1_190_000, 1e4, |_, _| 1.0);
            if k % 10 == 0 {
                let d0 = (3.7e9 + t0 as f64 * (1.0 + 40e-6)) as i64;
                let received = enc_host(d0 as f64 + 99e5) as i64 + 200_000;
                let enc = batch("enc", &[Role::Disp], d0, received, 1e5, |_, d| pos(enc_host(d)));
                m.push(&enc, &mut out);
            }
            m.push(&daq, &mut out);
        }
        assert!(out.len() > 350, "{} merged batches", out.len());
        let mut worst: f64 = 0.0;
        for b in out.iter().skip(200) {
            assert_eq!(b.roles, vec![Role::Load, Role::Acc, Role::Disp]);
            for i in 0..b.len() {
                let truth = pos(b.device_time_ns as f64 + b.period_ns * i as f64);
                worst = worst.max((b.values[i * 3 + 2] - truth).abs());
            }
        }
        // Receive delays are constant here, so the clocks map exactly; what is left is the
        // linear interpolation between 100 µs encoder samples of a 3 Hz, 1 mm sine:
        // (2π·3)²·1e-3·(1e-4)²/8 ≈ 4.4e-10 m, plus rounding. 1 nm is far below it and far
        // below an encoder step (1 µm).
        assert!(worst < 1e-9, "worst position error {worst} m");
        assert_eq!(m.stats().dropped_samples, 0);
    }

    #[test]
    fn a_late_source_is_held_and_a_missing_one_drops() {
        let mut m = Merger::new(50_000_000);
        let mut out = Vec::new();
        // No encoder at all: timeline batches wait up to 50 ms, then drop.
        for k in 0..100i64 {
            let t0 = k * 1_000_000;
            m.push(&batch("daq", &[Role::Load, Role::Acc], t0, t0 + 1_000_000, 1e4, |_, _| 0.0), &mut out);
        }
        assert!(out.is_empty());
        assert!(m.stats().dropped_samples >= 40 * 100, "{:?}", m.stats());
        // The encoder sends once, then falls silent: later batches are held at its value.
        m.push(&batch("enc", &[Role::Disp], 100_000_000, 100_000_000, 1e4, |_, _| 0.25), &mut out);
        for k in 100..300i64 {
            let t0 = k * 1_000_000;
            m.push(&batch("daq", &[Role::Load, Role::Acc], t0, t0 + 1_000_000, 1e4, |_, _| 0.0), &mut out);
        }
        let last = out.last().expect("merged batches once the encoder spoke");
        assert_eq!(last.values[2], 0.25);
        assert!(m.stats().held_values > 0);
        // Nothing waits longer than the lag: at most 50 ms of batches are pending.
        assert!(m.pending.len() <= 51, "{}", m.pending.len());
    }
}
