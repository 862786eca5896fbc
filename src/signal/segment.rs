//! Blow segmentation by acceleration trigger. The ram's deceleration crossing a threshold
//! arms a blow; a pre-trigger ring buffer keeps the approach (for the impact-speed fit and
//! the load zero); the load confirms the contact; the blow ends when the load has stayed
//! near zero for a hold time, or at a maximum length. A rebound that loads the sensor
//! again within the hold time belongs to the same blow (double blow). After a blow the
//! trigger re-arms only once the deceleration has fallen below the hysteresis level.
//!
//! It works sample by sample on continuous streams and on triggered captures alike, and
//! does not allocate per sample once its buffers have grown.

use super::pretrigger::PreTrigger;

use super::sample::{ABSENT, Role, SampleBatch};
use crate::physics::machine::MachineKind;

/// Segmentation thresholds. Defaults per machine kind are named constructors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentConfig {
    /// Trigger when the ram's acceleration falls below `-trigger_acc_mps2`.
    pub trigger_acc_mps2: f64,
    /// Re-arm when it is back above `-rearm_acc_mps2` for `rearm_s`.
    pub rearm_acc_mps2: f64,
    pub rearm_s: f64,
    /// Samples kept before the trigger, s.
    pub pre_trigger_s: f64,
    /// Zeroed load above which the tools are in contact, N.
    pub contact_load_n: f64,
    /// Zeroed load below which the blow may end, N.
    pub end_load_n: f64,
    /// How long the load must stay below `end_load_n` to end the blow, s.
    pub hold_s: f64,
    /// Longest blow, s; a trigger with no contact within it is dropped.
    pub max_blow_s: f64,
}

impl SegmentConfig {
    /// Drop hammer: the ram decelerates at F/m1, 400 m/s² on the paper's steel blow 1 and
    /// thousands on hard blows; free fall reads +9.81 and lifting a few m/s² upward.
    pub const HAMMER: SegmentConfig = SegmentConfig {
        trigger_acc_mps2: 100.0,
        rearm_acc_mps2: 50.0,
        rearm_s: 0.005,
        pre_trigger_s: 0.025,
        contact_load_n: 20e3,
        end_load_n: 10e3,
        hold_s: 0.002,
        max_blow_s: 0.1,
    };

    /// Screw press: the heavy ram decelerates at the link force over its mass, about
    /// 10 m/s² on the paper's copper blows; it approaches at constant speed.
    pub const SCREW_PRESS: SegmentConfig = SegmentConfig {
        trigger_acc_mps2: 1.0,
        rearm_acc_mps2: 0.5,
        rearm_s: 0.02,
        pre_trigger_s: 0.1,
        contact_load_n: 50e3,
        end_load_n: 30e3,
        hold_s: 0.01,
        max_blow_s: 0.5,
    };

    pub fn for_kind(kind: MachineKind) -> SegmentConfig {
        match kind {
            MachineKind::Hammer => Self::HAMMER,
            MachineKind::ScrewPress => Self::SCREW_PRESS,
        }
    }
}

/// The segmenter's sample (defined beside the batches, `signal::sample`).
pub use super::sample::Sample;

/// A segmented blow: the samples from the start of the pre-trigger buffer to the end.
#[derive(Debug, Clone, PartialEq)]
pub struct Blow {
    pub samples: Vec<Sample>,
    /// Index of the trigger sample.
    pub i_trigger: usize,
    /// Index of the first sample in contact.
    pub i_contact: usize,
    /// Index of the first sample of the quiet run that ended the blow (or the last sample).
    pub i_end: usize,
    /// Load zero from the pre-trigger window, N.
    pub load_zero_n: f64,
    pub period_s: f64,
    /// Time lost inside the blow that no sample stands for, s: the stream broke (a hole
    /// longer than a blow, a link pulled, the end of a file) while the tools were still
    /// loaded. A blow with any is cut short and cannot be estimated whole.
    pub lost_s: f64,
    /// The stream ended before the load had stayed below the end level for the hold time (a
    /// triggered capture's or a file's end, a stop, a link lost for good), with the tools no
    /// longer loaded at its last sample: the end level, N. The estimator then looks for the
    /// spring-back after the blow's own end of forming (`None`: the blow ended by its hold,
    /// at its maximum length, or was cut loaded, `lost_s`).
    pub open_end_n: Option<f64>,
    /// The contact and end samples the ram's deceleration gives (`contact_force_n` without a
    /// load), where the blow has a load, an accelerometer and the ram's mass: the cut a
    /// source without the load would have made. The estimator takes it when it leaves a
    /// load out of the blow (`estimate::faults`). `None` otherwise, or when the deceleration
    /// never crossed the contact level.
    pub ram_cut: Option<(usize, usize)>,
}

/// The force the segmenter watches for contact, N: the load sensor's, or, on a stream
/// without a load channel, the ram's deceleration times its mass `ram_kg` (zeroed like the
/// load over the pre-trigger window, which takes the approach's own acceleration out). On
/// a hammer that is the billet's push on the ram; on a press it also holds the link's, so
/// it confirms contact there, where the model fit then places it between samples.
pub fn contact_force_n(s: &Sample, ram_kg: f64) -> f64 {
    if s.load_n.is_nan() { -ram_kg * s.acc_mps2 } else { s.load_n }
}

/// Without an accelerometer the trigger watches the load over the ram's mass, as the
/// deceleration the billet would give the ram, its offset left in: a load cell's offset
/// (5–10 kN on the papers' machines) is 7–14 m/s² on the LG1000's 732 kg, well inside the
/// 50 m/s² rearm level, and 0.1 m/s² on the SPR 400's 106 t against its 0.5.
pub fn trigger_acc_without_accelerometer(load_n: f64, ram_kg: f64) -> f64 {
    -load_n / ram_kg
}

impl Blow {
    /// The channels the blow's samples carry: a channel the source lacks reads NaN.
    pub fn channels(&self) -> crate::signal::sample::Channels {
        let at = self.samples.get(self.i_contact).or(self.samples.first());
        Role::ALL.iter().fold(crate::signal::sample::Channels::NONE, |c, r| {
            let v = at.map_or(f64::NAN, |s| match r {
                Role::Load => s.load_n,
                Role::Disp => s.disp_m,
                Role::Acc => s.acc_mps2,
            });
            c.with(*r, !v.is_nan())
        })
    }

    /// Samples interpolated across holes within `range` (indices into `samples`).
    pub fn filled_in(&self, range: std::ops::Range<usize>) -> usize {
        self.samples.get(range).map_or(0, |s| s.iter().filter(|s| s.filled).count())
    }
}

/// Counters of what the segmenter saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SegmentStats {
    pub samples: u64,
    pub triggers: u64,
    pub blows: u64,
    /// Triggers that never saw the load confirm a contact.
    pub triggers_without_contact: u64,
    /// Blows cut at the maximum length.
    pub cut_at_max_length: u64,
    /// Batches that lacked a role, or held a non-finite value.
    pub batches_dropped: u64,
    /// Samples interpolated across holes no longer than a blow.
    pub samples_filled: u64,
    /// Blows cut short by a break in the stream while the tools were loaded.
    pub blows_cut_short: u64,
    /// Blows whose contact the load never confirmed and the ram's deceleration did (a
    /// load channel that died).
    pub contacts_by_deceleration: u64,
}

/// How a blow's samples ended: `Blow::lost_s` and `Blow::open_end_n`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Tail {
    lost_s: f64,
    open_end_n: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum State {
    Armed,
    /// `zero`: the load zero, fixed at the trigger; `contact`: the first contact sample once
    /// the load has confirmed it; `quiet`: samples in a row below the end level since.
    InBlow {
        i_trigger: usize,
        zero: f64,
        contact: Option<usize>,
        quiet: usize,
    },
    Refractory {
        quiet_since: Option<f64>,
    },
}

/// The streaming segmenter.
#[derive(Debug)]
pub struct Segmenter {
    cfg: SegmentConfig,
    state: State,
    /// The pre-trigger window.
    ring: PreTrigger,
    ring_cap: usize,
    blow: Vec<Sample>,
    period_s: f64,
    stats: SegmentStats,
    /// The last sample stepped, the left end of a hole's interpolation.
    last: Option<Sample>,
    /// Samples missing before the next one pushed (`hole`).
    pending_fill: usize,
    /// The ram's mass, kg: without a load channel, the ram's deceleration times it stands
    /// for the load (`contact_force_n`).
    ram_kg: f64,
}

impl Segmenter {
    pub fn new(cfg: SegmentConfig) -> Self {
        Segmenter {
            cfg,
            state: State::Armed,
            ring: PreTrigger::default(),
            ring_cap: 0,
            blow: Vec::new(),
            period_s: 0.0,
            stats: SegmentStats::default(),
            last: None,
            pending_fill: 0,
            ram_kg: f64::NAN,
        }
    }

    /// The ram's mass, kg, for the stand-in of a missing load channel (`contact_force_n`);
    /// unset, a stream without a load channel confirms no contact.
    pub fn with_ram_kg(mut self, ram_kg: f64) -> Self {
        self.set_ram_kg(ram_kg);
        self
    }

    /// A new ram mass from the next sample on (a new machine model).
    pub fn set_ram_kg(&mut self, ram_kg: f64) {
        self.ram_kg = ram_kg;
    }

    fn force(&self, s: &Sample) -> f64 {
        contact_force_n(s, self.ram_kg)
    }

    /// The acceleration the trigger watches: the accelerometer's, or without one, the
    /// load's stand-in (`trigger_acc_without_accelerometer`).
    fn trigger_acc(&self, s: &Sample) -> f64 {
        if s.acc_mps2.is_nan() { trigger_acc_without_accelerometer(s.load_n, self.ram_kg) } else { s.acc_mps2 }
    }

    /// `missing` samples were lost before the next batch (a lost frame, a dropped line, a
    /// device-time slip). A hole no longer than the longest blow is bridged: the next push
    /// first steps `missing` samples interpolated linearly between the samples on either
    /// side, flagged `filled`, so a blow in progress stays one blow on one time grid. A
    /// longer hole breaks the stream: a blow in progress is closed as it stands, and if the
    /// tools were still loaded it is marked cut short by the time it lost (at most the rest
    /// of the longest blow).
    pub fn hole(&mut self, missing: usize, out: &mut Vec<Blow>) {
        let hole_s = missing as f64 * self.period_s;
        if self.last.is_some() && self.period_s > 0.0 && hole_s <= self.cfg.max_blow_s {
            self.pending_fill += missing;
        } else {
            self.finish_losing(hole_s, false, out);
        }
    }

    pub fn stats(&self) -> SegmentStats {
        self.stats
    }

    pub fn config(&self) -> &SegmentConfig {
        &self.cfg
    }

    /// Replace the thresholds (takes effect from the next sample).
    pub fn set_config(&mut self, cfg: SegmentConfig) {
        self.cfg = cfg;
        self.ring_cap = 0;
    }

    /// Feed a batch; completed blows are appended to `out`.
    pub fn push(&mut self, batch: &SampleBatch, out: &mut Vec<Blow>) {
        // A batch without one of the channels (a source without that sensor) is cut all the
        // same, the channel reading NaN; one with neither the accelerometer nor the load has
        // nothing to trigger on.
        let il = batch.channel(Role::Load).unwrap_or(ABSENT);
        let id = batch.channel(Role::Disp).unwrap_or(ABSENT);
        let ia = batch.channel(Role::Acc).unwrap_or(ABSENT);
        if ia == ABSENT && (il == ABSENT || !self.ram_kg.is_finite()) {
            self.stats.batches_dropped += 1;
            return;
        }
        if batch.values.iter().any(|v| !v.is_finite()) || batch.period_ns.is_nan() || batch.period_ns <= 0.0 {
            self.stats.batches_dropped += 1;
            return;
        }
        let period_s = batch.period_ns * 1e-9;
        if self.ring_cap == 0 || (period_s - self.period_s).abs() > 1e-3 * period_s {
            self.period_s = period_s;
            self.ring_cap = ((self.cfg.pre_trigger_s / period_s).ceil() as usize).max(2);
            self.ring.set_cap(self.ring_cap);
        }
        let nc = batch.roles.len();
        let sample = |i: usize| Sample::from_row(batch.time_s(i), &batch.values[i * nc..(i + 1) * nc], [il, id, ia]);
        let (n, mut i) = (batch.len(), 0);
        while i < n {
            // Between blows (no hole to bridge first), whole runs of samples at once.
            if self.pending_fill == 0 {
                i += self.idle_run(batch, i, [il, id, ia], sample);
                if i == n {
                    break;
                }
            }
            let s = sample(i);
            self.fill_to(&s, out);
            self.step(s, out);
            i += 1;
        }
    }

    /// From sample `from` of `batch`, the samples `step` would take without a trigger
    /// (armed) or until it rearms (refractory, the rearming sample included), taken as
    /// `step` takes them: counted, the last kept, the ring holding the latest. How many.
    fn idle_run(
        &mut self,
        batch: &SampleBatch,
        from: usize,
        cols: [usize; 3],
        sample: impl Fn(usize) -> Sample,
    ) -> usize {
        let nc = batch.roles.len();
        let ram_kg = self.ram_kg;
        let acc = |i: usize| match cols[2] {
            ABSENT => trigger_acc_without_accelerometer(batch.values[i * nc + cols[0]], ram_kg),
            c => batch.values[i * nc + c],
        };
        let n = batch.len();
        let taken = match self.state {
            State::Armed => {
                let to = (from..n).find(|&i| acc(i) < -self.cfg.trigger_acc_mps2).unwrap_or(n);
                self.ring.extend_from(batch, from, to, cols);
                to - from
            }
            State::Refractory { quiet_since } => {
                let mut since = quiet_since;
                let rearm = (from..n).find(|&i| {
                    let t_s = batch.time_s(i);
                    since = if acc(i) > -self.cfg.rearm_acc_mps2 { since.or(Some(t_s)) } else { None };
                    since.is_some_and(|t0| t_s - t0 >= self.cfg.rearm_s)
                });
                match rearm {
                    Some(i) => {
                        self.state = State::Armed;
                        self.ring.clear();
                        self.ring.extend_from(batch, i, i + 1, cols);
                        i + 1 - from
                    }
                    None => {
                        self.state = State::Refractory { quiet_since: since };
                        self.ring.extend_from(batch, from, n, cols);
                        n - from
                    }
                }
            }
            State::InBlow { .. } => 0,
        };
        if taken > 0 {
            self.stats.samples += taken as u64;
            self.last = Some(sample(from + taken - 1));
        }
        taken
    }

    /// Step the samples of a pending hole, interpolated from the last sample to `next`.
    fn fill_to(&mut self, next: &Sample, out: &mut Vec<Blow>) {
        let missing = std::mem::take(&mut self.pending_fill);
        let Some(a) = self.last.filter(|_| missing > 0) else { return };
        let n = (missing + 1) as f64;
        let lerp = |x: f64, y: f64, f: f64| x + (y - x) * f;
        for j in 1..=missing {
            let f = j as f64 / n;
            self.stats.samples_filled += 1;
            self.step(
                Sample {
                    t_s: lerp(a.t_s, next.t_s, f),
                    load_n: lerp(a.load_n, next.load_n, f),
                    disp_m: lerp(a.disp_m, next.disp_m, f),
                    acc_mps2: lerp(a.acc_mps2, next.acc_mps2, f),
                    filled: true,
                },
                out,
            );
        }
    }

    /// Every blow of a whole, finite stream (a capture file, a synthetic session), the last
    /// one closed as it stands.
    pub fn cut_all<'a>(cfg: SegmentConfig, batches: impl IntoIterator<Item = &'a SampleBatch>) -> Vec<Blow> {
        let mut seg = Segmenter::new(cfg);
        let mut out = Vec::new();
        for b in batches {
            seg.push(b, &mut out);
        }
        seg.finish(&mut out);
        out
    }

    /// End of the stream: a blow in progress is closed as it stands. Where the tools were
    /// still loaded at the last sample (the load above the end level), the blow is cut short
    /// by an unknown time: it is marked with the time left to the longest blow.
    pub fn finish(&mut self, out: &mut Vec<Blow>) {
        self.finish_losing(f64::INFINITY, false, out);
    }

    /// The source stopped (the service's stop, the end of a recording it made): a blow in
    /// progress after its contact is cut short, however quiet its last samples were. Its
    /// ring-down was not seen through, so a dip of the load under the end level (the lower
    /// tool's ring at impact carries it below zero) is no evidence that the blow ended.
    pub fn stop(&mut self, out: &mut Vec<Blow>) {
        self.finish_losing(f64::INFINITY, true, out);
    }

    /// End of the stream after a hole of `hole_s`; `stopped`: cut short whenever in contact.
    fn finish_losing(&mut self, hole_s: f64, stopped: bool, out: &mut Vec<Blow>) {
        if let State::InBlow { i_trigger, zero, contact, quiet } = self.state {
            let n = self.blow.len();
            let loaded = contact.is_some() && (quiet == 0 || stopped);
            let lost_s = if loaded {
                self.stats.blows_cut_short += 1;
                let left_s = self.cfg.max_blow_s - (self.blow[n - 1].t_s - self.blow[i_trigger].t_s);
                hole_s.min(left_s).max(self.period_s)
            } else {
                0.0
            };
            let open_end_n = (contact.is_some() && !loaded).then_some(self.cfg.end_load_n);
            self.close_with(i_trigger, zero, contact, n.saturating_sub(1), Tail { lost_s, open_end_n }, out);
        }
        self.state = State::Armed;
        self.ring.clear();
        self.last = None;
        self.pending_fill = 0;
    }

    fn step(&mut self, s: Sample, out: &mut Vec<Blow>) {
        self.stats.samples += 1;
        self.last = Some(s);
        match self.state {
            State::Armed => {
                // A sample interpolated across a hole never arms a trigger by itself.
                if self.trigger_acc(&s) < -self.cfg.trigger_acc_mps2 && !s.filled {
                    self.stats.triggers += 1;
                    self.blow.clear();
                    self.ring.drain_into(&mut self.blow);
                    let i_trigger = self.blow.len();
                    self.blow.push(s);
                    // The zero and any contact already in the pre-trigger window are known
                    // now; later samples only extend them.
                    let zero = self.zero(i_trigger);
                    let first = Self::first_searched(i_trigger, self.blow.len());
                    let contact = (first..self.blow.len())
                        .find(|&i| self.force(&self.blow[i]) - zero > self.cfg.contact_load_n)
                        .map(|i| self.walk_back(i, first, zero));
                    let quiet = usize::from(self.force(&s) - zero < self.cfg.end_load_n);
                    self.state = State::InBlow { i_trigger, zero, contact, quiet };
                } else {
                    self.ring.push(s);
                }
            }
            State::InBlow { i_trigger, zero, mut contact, mut quiet } => {
                self.blow.push(s);
                let n = self.blow.len();
                if contact.is_none() && self.force(&s) - zero > self.cfg.contact_load_n {
                    let first = Self::first_searched(i_trigger, n);
                    contact = Some(self.walk_back(n - 1, first, zero));
                }
                quiet = if self.force(&s) - zero < self.cfg.end_load_n { quiet + 1 } else { 0 };
                // The blow ends when, after contact, the load has been quiet for the hold time.
                let hold = (self.cfg.hold_s / self.period_s).ceil() as usize;
                let end =
                    (quiet >= hold && n > hold).then(|| n - hold).filter(|start| contact.is_some_and(|c| *start > c));
                let duration = s.t_s - self.blow[i_trigger].t_s;
                if let Some(i_end) = end {
                    self.close(i_trigger, zero, contact, i_end, out);
                } else if duration > self.cfg.max_blow_s {
                    if contact.is_some() {
                        self.stats.cut_at_max_length += 1;
                    }
                    self.close(i_trigger, zero, contact, n - 1, out);
                } else {
                    self.state = State::InBlow { i_trigger, zero, contact, quiet };
                }
            }
            State::Refractory { quiet_since } => {
                let calm = self.trigger_acc(&s) > -self.cfg.rearm_acc_mps2;
                let since = if calm { quiet_since.or(Some(s.t_s)) } else { None };
                if since.is_some_and(|t0| s.t_s - t0 >= self.cfg.rearm_s) {
                    self.state = State::Armed;
                    self.ring.clear();
                } else {
                    self.state = State::Refractory { quiet_since: since };
                }
                self.ring.push(s);
            }
        }
    }

    /// Load zero: the mean load over the first half of the pre-trigger window. The ram's
    /// deceleration that stands in for a missing load is taken as it is (zero 0): it has no
    /// offset to take out, and the window may hold the ram at rest as well as in free fall,
    /// which differ by its weight (7 kN on the LG1000, above half the end level).
    fn zero(&self, i_trigger: usize) -> f64 {
        if self.blow.get(i_trigger).is_some_and(|s| s.load_n.is_nan()) {
            return 0.0;
        }
        let n = (i_trigger / 2).max(1).min(self.blow.len());
        self.blow[..n].iter().map(|s| self.force(s)).sum::<f64>() / n as f64
    }

    /// Where the contact search starts: after the zero's window.
    fn first_searched(i_trigger: usize, len: usize) -> usize {
        (i_trigger / 2).max(1).min(len)
    }

    /// From the first sample above the contact level, walk back to where the load left its
    /// noise band (the contact level is set well above the noise, so the true first
    /// contact is a few samples earlier).
    fn walk_back(&self, i: usize, first: usize, zero: f64) -> usize {
        let mut j = i;
        while j > first && self.force(&self.blow[j - 1]) - zero > self.cfg.end_load_n * 0.5 {
            j -= 1;
        }
        j
    }

    fn close(&mut self, i_trigger: usize, load_zero_n: f64, contact: Option<usize>, i_end: usize, out: &mut Vec<Blow>) {
        self.close_with(i_trigger, load_zero_n, contact, i_end, Tail { lost_s: 0.0, open_end_n: None }, out);
    }

    fn close_with(
        &mut self,
        i_trigger: usize,
        load_zero_n: f64,
        contact: Option<usize>,
        i_end: usize,
        Tail { lost_s, open_end_n }: Tail,
        out: &mut Vec<Blow>,
    ) {
        let whole = match contact {
            // A blow cut short right at its contact is still a blow (an incomplete one).
            Some(i_contact) if i_end > i_contact || lost_s > 0.0 => Some((i_contact, i_end, open_end_n)),
            // The load never confirmed a contact the ram's deceleration shows: a load channel
            // that died (issue 43). The blow goes on, for the estimator to judge the channel.
            None if lost_s == 0.0 => self.contact_by_deceleration(i_trigger).map(|(i_contact, i_end)| {
                self.stats.contacts_by_deceleration += 1;
                (i_contact, i_end, None)
            }),
            _ => None,
        };
        match whole {
            Some((i_contact, i_end, open_end_n)) => {
                self.stats.blows += 1;
                let ram_cut = self.ram_cut(i_trigger);
                out.push(Blow {
                    samples: std::mem::take(&mut self.blow),
                    i_trigger,
                    i_contact,
                    i_end,
                    load_zero_n,
                    period_s: self.period_s,
                    lost_s,
                    open_end_n,
                    ram_cut,
                });
            }
            None => {
                self.stats.triggers_without_contact += 1;
                self.blow.clear();
            }
        }
        self.state = State::Refractory { quiet_since: None };
    }

    /// A blow the load never confirmed, when the load channel is stuck (it read one value
    /// from the trigger on: a dead channel): where the ram's deceleration times its mass
    /// (`contact_force_n` without a load, zero 0) confirms a contact, walked back as the
    /// load's is, and where it then stays below the end level for the hold time:
    /// `(contact, end)`. `None` when the load lives (a ram braked without touching anything
    /// is no blow), or the deceleration shows no whole contact.
    fn contact_by_deceleration(&self, i_trigger: usize) -> Option<(usize, usize)> {
        let (lo, hi) = self.blow[i_trigger.min(self.blow.len())..]
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| (lo.min(s.load_n), hi.max(s.load_n)));
        let stuck = crate::signal::sample::same_reading(lo, hi);
        if !stuck {
            return None;
        }
        self.ram_contact(i_trigger)
    }

    /// `Blow::ram_cut` of the blow being closed: only where the load would have cut it.
    fn ram_cut(&self, i_trigger: usize) -> Option<(usize, usize)> {
        let s = self.blow.get(i_trigger)?;
        if s.load_n.is_nan() || s.acc_mps2.is_nan() {
            return None;
        }
        self.ram_contact(i_trigger)
    }

    /// The contact and end the ram's deceleration times its mass gives, as the segmenter
    /// finds them on a stream without a load (zero 0, the same levels and hold).
    fn ram_contact(&self, i_trigger: usize) -> Option<(usize, usize)> {
        if !self.ram_kg.is_finite() {
            return None;
        }
        let ram = |s: &Sample| -self.ram_kg * s.acc_mps2;
        let first = Self::first_searched(i_trigger, self.blow.len());
        let above = (first..self.blow.len()).find(|&i| ram(&self.blow[i]) > self.cfg.contact_load_n)?;
        let mut contact = above;
        while contact > first && ram(&self.blow[contact - 1]) > self.cfg.end_load_n * 0.5 {
            contact -= 1;
        }
        let hold = (self.cfg.hold_s / self.period_s).ceil() as usize;
        let mut quiet = 0;
        for i in above..self.blow.len() {
            quiet = if ram(&self.blow[i]) < self.cfg.end_load_n { quiet + 1 } else { 0 };
            if quiet >= hold {
                return Some((contact, i + 1 - hold));
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One second at 100 kHz with three blows: the ram decelerating at 5000 m/s² and the
    /// load a half sine of 500 kN over 5 ms; between them a little deterministic noise.
    fn stream() -> Vec<[f64; 3]> {
        let mut noise = 12345u64;
        let mut jitter = move || {
            noise = noise.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            ((noise >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        (0..100_000)
            .map(|i| {
                let t = i as f64 * 1e-5;
                let blow = [0.2, 0.5, 0.8].iter().find(|&&tb| (tb..tb + 0.005).contains(&t));
                match blow {
                    Some(tb) => {
                        let load = 500e3 * (std::f64::consts::PI * (t - tb) / 0.005).sin();
                        [load + 100.0 * jitter(), 0.1 - t * 0.01, -5000.0 + jitter()]
                    }
                    None => [100.0 * jitter(), 0.1 - t * 0.01, 2.0 * jitter()],
                }
            })
            .collect()
    }

    fn batches(rows: &[[f64; 3]], size: usize) -> Vec<SampleBatch> {
        rows.chunks(size)
            .enumerate()
            .map(|(k, chunk)| SampleBatch {
                source: "s".into(),
                seq: k as u64,
                device_time_ns: (k * size * 10_000) as i64,
                host_time_ns: 0,
                period_ns: 10_000.0,
                // Not the roles' own order.
                roles: vec![Role::Acc, Role::Load, Role::Disp],
                values: chunk.iter().flat_map(|r| [r[2], r[0], r[1]]).collect(),
            })
            .collect()
    }

    /// Between blows the segmenter takes runs of a batch at once (`idle_run`): however
    /// the stream is cut into batches, the blows are the same, sample for sample, as when
    /// each sample comes in a batch of its own (every run one sample long).
    #[test]
    fn the_blows_do_not_depend_on_where_the_batches_end() {
        let rows = stream();
        let one_by_one = Segmenter::cut_all(SegmentConfig::HAMMER, &batches(&rows, 1));
        assert_eq!(one_by_one.len(), 3, "three blows in the stream");
        // Each opens with the pre-trigger window whole: the 25 ms (2500 samples, one more
        // where the division rounds up) before its trigger, on one 10 µs grid.
        for (b, tb) in one_by_one.iter().zip([0.2, 0.5, 0.8]) {
            assert!((2500..=2501).contains(&b.i_trigger), "{} samples before the trigger", b.i_trigger);
            assert!((b.samples[b.i_trigger].t_s - tb).abs() < 1.5e-5, "triggered at {}", b.samples[b.i_trigger].t_s);
            assert!(b.samples.windows(2).all(|w| ((w[1].t_s - w[0].t_s) - 1e-5).abs() < 1e-9), "a hole in the blow");
        }
        for size in [7, 250, 1000, 4096, rows.len()] {
            let cut = Segmenter::cut_all(SegmentConfig::HAMMER, &batches(&rows, size));
            assert!(cut == one_by_one, "batches of {size}: other blows than one sample at a time");
        }
    }
}
