//! The time-stamp check of a source whose samples carry their own time and no sequence
//! number (the ASCII lines of docs/interfaces.md §7): which stamps are the next sample, which
//! reveal a hole, which are a device restart, and which are garbage to drop. A corrupt
//! stamp must never become a sample, a blow or a lost-sample count, so every stamp that
//! does not continue the timeline is held until the stamp after it confirms it. Pure code.
//!
//! The rule, with `P` the period and `last` the last accepted stamp:
//!
//! - **Start-up.** The period is not configured: it is taken from the first
//!   `WARMUP_STAMPS` stamps, and only when their steps are all positive and each within
//!   (0.5, 1.5) of their median. Otherwise the oldest is dropped and the window slides, so
//!   garbage in the first lines cannot set the period.
//! - **Next sample.** A stamp within (0.5, 1.5) periods after `last` is accepted at once.
//! - **Anything else is held**: behind `last`, within half a period of it, or 1.5 periods
//!   or more ahead. The next stamp decides:
//!   - it continues `last` at one period: the held stamp was garbage and is dropped
//!     (`out_of_sequence` if it was not past `last`, else `wild_stamps`);
//!   - it continues the held stamp at one period: the held stamp is confirmed. Ahead by
//!     `k` periods (`k ≥ 1.5`, at most `MAX_HOLE_S`): a hole of `round(k) − 1` samples.
//!     Behind, barely ahead, or further than `MAX_HOLE_S`: a new timeline (a device
//!     restart, a clock set), counted in `restarts` with no samples counted lost;
//!   - neither: the held stamp is dropped and the new one is held in its place.
//! - **Lost lock.** When `RESYNC_MISFITS` of the last `RESYNC_WINDOW` decided stamps were
//!   dropped or opened a hole (the device changed its rate: at a higher rate most stamps
//!   fall between periods, at a lower one every stamp looks like a hole), the period is
//!   established afresh as at start-up, and the timeline that follows is a new one. Random
//!   garbage (a line in a hundred) is far from that.

use std::collections::VecDeque;

/// Stamps needed, with consistent steps, before the period is trusted.
pub const WARMUP_STAMPS: usize = 3;
/// A step within (`NEXT_MIN_PERIODS`, `NEXT_MAX_PERIODS`) periods is the next sample.
pub const NEXT_MIN_PERIODS: f64 = 0.5;
pub const NEXT_MAX_PERIODS: f64 = 1.5;
/// A confirmed jump ahead up to this long is a hole of lost samples; a longer one (a clock
/// set, a device left off) starts a new timeline without a lost-sample count, s.
pub const MAX_HOLE_S: f64 = 600.0;
/// Decided stamps remembered for the lock check (at most 32).
pub const RESYNC_WINDOW: u32 = 16;
/// Misfits (drops and holes) among them that make the period be established afresh.
pub const RESYNC_MISFITS: u32 = 8;

/// `t_ns` as decimal seconds, exactly, without trailing zeros: `10.004`, `-79.95`, `0`.
pub fn seconds(t_ns: i64) -> String {
    let sign = if t_ns < 0 { "-" } else { "" };
    let abs = t_ns.unsigned_abs();
    let frac = format!("{:09}", abs % 1_000_000_000);
    let frac = frac.trim_end_matches('0');
    let dot = if frac.is_empty() { "" } else { "." };
    format!("{sign}{}{dot}{frac}", abs / 1_000_000_000)
}

/// What the check has dropped or restarted since it was created.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StampStats {
    /// Stamps ahead of the timeline that nothing confirmed (including those dropped while
    /// the period was being established).
    pub wild_stamps: u64,
    /// Stamps behind (or not half a period past) the last sample that nothing confirmed.
    pub out_of_sequence: u64,
    /// New timelines: a device restart, a clock jump beyond `MAX_HOLE_S`, a new period.
    pub restarts: u64,
}

/// Why a stamp was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DropReason {
    Wild,
    OutOfSequence,
}

/// What one stamp (or a stamp it confirms) became. Every payload offered comes back out,
/// in a `Sample` or a `Dropped`, so its owner can reuse it.
#[derive(Debug, Clone, PartialEq)]
pub enum Checked<T> {
    /// The next sample of the timeline, with `lost` samples missing before it.
    Sample {
        t_ns: i64,
        lost: u64,
        payload: T,
    },
    /// The samples from `t_ns` on form a new timeline; the last one before was `last_ns`.
    NewTimeline {
        t_ns: i64,
        last_ns: i64,
        reason: String,
    },
    Dropped {
        t_ns: i64,
        payload: T,
        why: DropReason,
    },
}

/// The check of one source's stamps (module docs); `T` is what travels with each stamp.
#[derive(Debug, Clone)]
pub struct StampCheck<T> {
    period_ns: Option<f64>,
    /// The last accepted stamp.
    last_ns: Option<i64>,
    /// Stamps waiting for the period to be established.
    warm: VecDeque<(i64, T)>,
    /// A stamp off the timeline, waiting for the next one to confirm it.
    held: Option<(i64, T)>,
    /// The last `RESYNC_WINDOW` decisions, newest in bit 0: 1 for a misfit.
    history: u32,
    /// The period before the lock was lost (for the resync's reason).
    old_period_ns: Option<f64>,
    stats: StampStats,
}

impl<T> Default for StampCheck<T> {
    fn default() -> Self {
        StampCheck {
            period_ns: None,
            last_ns: None,
            warm: VecDeque::with_capacity(WARMUP_STAMPS),
            held: None,
            history: 0,
            old_period_ns: None,
            stats: StampStats::default(),
        }
    }
}

impl<T> StampCheck<T> {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn stats(&self) -> StampStats {
        self.stats
    }

    /// The period, once established, ns.
    pub fn period_ns(&self) -> Option<f64> {
        self.period_ns
    }

    /// Stamps offered but not yet decided (start-up window, held stamp).
    pub fn pending(&self) -> usize {
        self.warm.len() + usize::from(self.held.is_some())
    }

    /// Adopt a period measured over a run of accepted samples, if it agrees with the
    /// current one to 5 % (a run cut short by a stray stamp does not move it).
    pub fn refine_period(&mut self, measured_ns: f64) {
        if let Some(p) = self.period_ns
            && measured_ns.is_finite()
            && (measured_ns / p - 1.0).abs() < 0.05
        {
            self.period_ns = Some(measured_ns);
        }
    }

    /// Check the stamp `t_ns` carrying `payload`; what it decides goes to `out`.
    pub fn offer(&mut self, t_ns: i64, payload: T, out: &mut Vec<Checked<T>>) {
        match (self.period_ns, self.last_ns) {
            (Some(p), Some(last)) => self.track(t_ns, payload, p, last, out),
            _ => self.warm_up(t_ns, payload, out),
        }
    }

    /// Steps in periods from `from_ns` to `t_ns`.
    fn periods(from_ns: i64, t_ns: i64, p: f64) -> f64 {
        (t_ns as i128 - from_ns as i128) as f64 / p
    }

    fn is_next(k: f64) -> bool {
        NEXT_MIN_PERIODS < k && k < NEXT_MAX_PERIODS
    }

    fn warm_up(&mut self, t_ns: i64, payload: T, out: &mut Vec<Checked<T>>) {
        self.warm.push_back((t_ns, payload));
        if self.warm.len() < WARMUP_STAMPS {
            return;
        }
        let mut steps: Vec<i128> =
            self.warm.iter().zip(self.warm.iter().skip(1)).map(|(a, b)| b.0 as i128 - a.0 as i128).collect();
        steps.sort_unstable();
        let median = steps[steps.len() / 2] as f64;
        let consistent = median > 0.0 && steps.iter().all(|s| Self::is_next(*s as f64 / median));
        if !consistent {
            if let Some((t, payload)) = self.warm.pop_front() {
                self.stats.wild_stamps += 1;
                out.push(Checked::Dropped { t_ns: t, payload, why: DropReason::Wild });
            }
            return;
        }
        let (first, last) = match (self.warm.front(), self.warm.back()) {
            (Some(f), Some(l)) => (f.0, l.0),
            _ => return,
        };
        let period = (last as i128 - first as i128) as f64 / (self.warm.len() - 1) as f64;
        if let Some(before) = self.last_ns {
            self.stats.restarts += 1;
            let reason = format!(
                "time_resync: stamps stopped fitting the period of {:.3} µs; new period {:.3} µs from t_s {}",
                self.old_period_ns.unwrap_or(f64::NAN) * 1e-3,
                period * 1e-3,
                seconds(first)
            );
            out.push(Checked::NewTimeline { t_ns: first, last_ns: before, reason });
        }
        self.period_ns = Some(period);
        while let Some((t, payload)) = self.warm.pop_front() {
            self.accept(t, payload, 0, out);
        }
    }

    fn track(&mut self, t_ns: i64, payload: T, p: f64, last: i64, out: &mut Vec<Checked<T>>) {
        let window = (1u32 << RESYNC_WINDOW) - 1;
        if (self.history & window).count_ones() >= RESYNC_MISFITS {
            // Lock lost: establish the period afresh, from the held stamp and this one.
            self.history = 0;
            self.old_period_ns = self.period_ns.take();
            if let Some(held) = self.held.take() {
                self.warm.push_back(held);
            }
            self.warm_up(t_ns, payload, out);
            return;
        }
        let next = Self::is_next(Self::periods(last, t_ns, p));
        if let Some((h, held)) = self.held.take() {
            if !next && Self::is_next(Self::periods(h, t_ns, p)) {
                self.confirm(h, held, p, last, out);
                self.accept(t_ns, payload, 0, out);
                return;
            }
            self.drop_stamp(h, held, p, last, out);
        }
        if next {
            self.accept(t_ns, payload, 0, out);
        } else {
            self.held = Some((t_ns, payload));
        }
    }

    /// The held stamp `h` was confirmed by the stamp after it: a hole, or a new timeline.
    fn confirm(&mut self, h: i64, held: T, p: f64, last: i64, out: &mut Vec<Checked<T>>) {
        let k = Self::periods(last, h, p);
        let ahead_s = (h as i128 - last as i128) as f64 * 1e-9;
        if k >= NEXT_MAX_PERIODS && ahead_s <= MAX_HOLE_S {
            let lost = (k.round() as u64).saturating_sub(1);
            self.accept(h, held, lost, out);
            return;
        }
        self.stats.restarts += 1;
        let (from_s, to_s) = (seconds(last), seconds(h));
        let reason = if h < last {
            format!("device_restart: t_s went back from {from_s} to {to_s}")
        } else if k <= NEXT_MIN_PERIODS {
            format!("time_shift: t_s moved {k:.2} periods, from {from_s} to {to_s}")
        } else {
            format!(
                "time_jump: t_s jumped {ahead_s:.3} s ahead (over {MAX_HOLE_S} s: no samples counted), from {from_s} to {to_s}"
            )
        };
        out.push(Checked::NewTimeline { t_ns: h, last_ns: last, reason });
        self.accept(h, held, 0, out);
    }

    fn drop_stamp(&mut self, h: i64, held: T, p: f64, last: i64, out: &mut Vec<Checked<T>>) {
        self.history = (self.history << 1) | 1;
        let why = if Self::periods(last, h, p) <= NEXT_MIN_PERIODS {
            self.stats.out_of_sequence += 1;
            DropReason::OutOfSequence
        } else {
            self.stats.wild_stamps += 1;
            DropReason::Wild
        };
        out.push(Checked::Dropped { t_ns: h, payload: held, why });
    }

    fn accept(&mut self, t_ns: i64, payload: T, lost: u64, out: &mut Vec<Checked<T>>) {
        self.last_ns = Some(t_ns);
        self.history = (self.history << 1) | u32::from(lost > 0);
        out.push(Checked::Sample { t_ns, lost, payload });
    }
}
