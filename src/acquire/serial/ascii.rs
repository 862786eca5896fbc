//! The ASCII variant of the serial DAQ stream (docs/interfaces.md §7), sans-IO: lines of
//! `t_s,v0,v1,...\n` with the values already in physical units, in the configured channel
//! order. `LineDecoder` is fed byte chunks, drops and counts malformed lines, checks every
//! time stamp against the source's period (`stamps.rs`: a corrupt stamp is dropped and
//! counted, never used; a hole is a `Gap`; a device restart is accepted once the lines
//! after it confirm it), and groups the good lines into `SampleBatch`es of about `batch_s`
//! each. No IO, no clock: the caller passes the host receive time.

use std::collections::VecDeque;

use super::stamps::{Checked, DropReason, StampCheck, seconds};
use crate::signal::sample::Gap;
use crate::signal::sample::{Role, SampleBatch};

/// Batch length when none is configured, s (DESIGN.md §3: 10–100 ms per message).
pub const DEFAULT_ASCII_BATCH_S: f64 = 0.02;
/// Most samples in one batch, whatever the period.
pub const MAX_BATCH_SAMPLES: usize = 4096;
/// A longer line is garbage: it is dropped up to its `\n` and counted once.
pub const MAX_LINE_BYTES: usize = 1024;
/// A stamp further from zero is not a time (i64 ns holds ±9.2e9 s): the line is malformed.
pub const MAX_ABS_T_S: f64 = 4e9;
/// Runs of at least this many samples refine the period (`StampCheck::refine_period`).
const REFINE_MIN_SAMPLES: usize = 8;

/// What the line decoder produces.
#[derive(Debug, Clone, PartialEq)]
pub enum AsciiEvent {
    Batch(SampleBatch),
    /// Samples missing between two lines (reason `time_jump: ...`), or a new timeline
    /// (`device_restart: ...`, `time_shift: ...`, `time_resync: ...`; no samples counted).
    Gap(Gap),
}

/// What a `LineDecoder` has seen since it was created. Every non-blank line is a sample,
/// dropped, or still pending: `lines = samples + malformed + pending`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LineStats {
    /// Non-blank lines (an overlong line counts once).
    pub lines: u64,
    /// Lines dropped, whatever the reason (the status's `decode_errors`): `unparsable +
    /// wild_stamps + out_of_sequence`.
    pub malformed: u64,
    pub samples: u64,
    /// New timelines (a device restart, a clock jump, a new period), each also a `Gap`
    /// with no samples lost.
    pub restarts: u64,
    /// Not UTF-8, a field that is not a finite number, the wrong number of fields, a stamp
    /// beyond `MAX_ABS_T_S`, or overlong.
    pub unparsable: u64,
    /// Stamps ahead of the timeline that the next line did not confirm.
    pub wild_stamps: u64,
    /// Stamps behind the last sample (or not half a period past it) that the next line
    /// did not confirm as a restart.
    pub out_of_sequence: u64,
    /// Lines held for the stamp check (start-up window, a stamp awaiting confirmation).
    pub pending: u64,
}

/// Sans-IO decoder of `t_s,v0,...` lines. Call [`push`](Self::push) with received bytes,
/// then [`next_event`](Self::next_event) until `None`; [`flush`](Self::flush) closes the
/// batch in progress (the line went quiet or closed).
#[derive(Debug)]
pub struct LineDecoder {
    source: String,
    roles: Vec<Role>,
    batch_s: f64,
    line: Vec<u8>,
    /// Dropping an overlong line up to its end.
    skipping: bool,
    values: Vec<f64>,
    fields: Vec<f64>,
    stamps: StampCheck<Vec<f64>>,
    checked: Vec<Checked<Vec<f64>>>,
    /// Value buffers of decided lines, reused for the next ones.
    spare: Vec<Vec<f64>>,
    t_first_ns: i64,
    t_last_ns: i64,
    n: usize,
    seq: u64,
    ready: VecDeque<AsciiEvent>,
    stats: LineStats,
}

impl LineDecoder {
    /// Lines carry one value per role, in this order.
    pub fn new(source: impl Into<String>, roles: Vec<Role>, batch_s: f64) -> Self {
        let batch_s = if batch_s.is_finite() && batch_s > 0.0 { batch_s } else { DEFAULT_ASCII_BATCH_S };
        LineDecoder {
            source: source.into(),
            fields: Vec::with_capacity(roles.len() + 1),
            roles,
            batch_s,
            line: Vec::with_capacity(MAX_LINE_BYTES),
            skipping: false,
            values: Vec::new(),
            stamps: StampCheck::new(),
            checked: Vec::new(),
            spare: Vec::new(),
            t_first_ns: 0,
            t_last_ns: 0,
            n: 0,
            seq: 0,
            ready: VecDeque::new(),
            stats: LineStats::default(),
        }
    }

    pub fn stats(&self) -> LineStats {
        let st = self.stamps.stats();
        LineStats {
            restarts: st.restarts,
            wild_stamps: st.wild_stamps,
            out_of_sequence: st.out_of_sequence,
            malformed: self.stats.unparsable + st.wild_stamps + st.out_of_sequence,
            pending: self.stamps.pending() as u64,
            ..self.stats
        }
    }

    /// The sample period, once the first lines have established it, s.
    pub fn period_s(&self) -> Option<f64> {
        self.stamps.period_ns().map(|p| p * 1e-9)
    }

    /// Append received bytes; complete lines are decoded at once and batches that fill up
    /// are stamped with `host_time_ns`.
    pub fn push(&mut self, bytes: &[u8], host_time_ns: i64) {
        let mut rest = bytes;
        while !rest.is_empty() {
            match rest.iter().position(|b| *b == b'\n') {
                Some(i) => {
                    if !self.skipping && self.line.len() + i <= MAX_LINE_BYTES {
                        self.line.extend_from_slice(&rest[..i]);
                        let line = std::mem::take(&mut self.line);
                        self.on_line(&line, host_time_ns);
                        self.line = line;
                    }
                    self.line.clear();
                    self.skipping = false;
                    rest = &rest[i + 1..];
                }
                None => {
                    if !self.skipping {
                        if self.line.len() + rest.len() > MAX_LINE_BYTES {
                            self.stats.lines += 1;
                            self.stats.unparsable += 1;
                            self.skipping = true;
                            self.line.clear();
                        } else {
                            self.line.extend_from_slice(rest);
                        }
                    }
                    rest = &[];
                }
            }
        }
    }

    /// Close the batch in progress (the line went quiet, or is closing).
    pub fn flush(&mut self, host_time_ns: i64) {
        self.close_batch(host_time_ns);
    }

    /// Forget a partial line (the link was closed and reopened); the batch in progress is
    /// closed. The stamp check keeps its timeline, so an outage shows as a hole.
    pub fn reset(&mut self, host_time_ns: i64) {
        self.line.clear();
        self.skipping = false;
        self.close_batch(host_time_ns);
    }

    pub fn next_event(&mut self) -> Option<AsciiEvent> {
        self.ready.pop_front()
    }

    fn on_line(&mut self, line: &[u8], host_time_ns: i64) {
        let line = match line.last() {
            Some(b'\r') => &line[..line.len() - 1],
            _ => line,
        };
        if line.iter().all(|b| b.is_ascii_whitespace()) {
            return; // blank lines carry nothing
        }
        self.stats.lines += 1;
        if !self.parse(line) {
            self.stats.unparsable += 1;
            return;
        }
        let t_ns = (self.fields[0] * 1e9).round() as i64;
        let mut payload = self.spare.pop().unwrap_or_default();
        payload.clear();
        payload.extend_from_slice(&self.fields[1..]);
        let mut checked = std::mem::take(&mut self.checked);
        self.stamps.offer(t_ns, payload, &mut checked);
        for c in checked.drain(..) {
            self.on_checked(c, host_time_ns);
        }
        self.checked = checked;
    }

    /// Act on what the stamp check decided about a line.
    fn on_checked(&mut self, c: Checked<Vec<f64>>, host_time_ns: i64) {
        match c {
            Checked::Sample { t_ns, lost, payload } => {
                if lost > 0 {
                    self.close_batch(host_time_ns);
                    let period_ns = self.stamps.period_ns().unwrap_or(0.0);
                    let from_ns = t_ns as f64 - lost as f64 * period_ns;
                    self.gap(
                        from_ns * 1e-9,
                        lost,
                        format!("time_jump: t_s jumped {} periods to {}", lost + 1, seconds(t_ns)),
                    );
                }
                self.add_sample(t_ns, &payload, host_time_ns);
                self.spare.push(payload);
            }
            Checked::NewTimeline { t_ns, reason, .. } => {
                self.close_batch(host_time_ns);
                self.gap(t_ns as f64 * 1e-9, 0, reason);
            }
            Checked::Dropped { payload, why, t_ns } => {
                let what = match why {
                    DropReason::Wild => "wild",
                    DropReason::OutOfSequence => "out-of-sequence",
                };
                tracing::trace!(source = %self.source, t_ns, "dropped a line with a {what} stamp");
                self.spare.push(payload);
            }
        }
    }

    fn gap(&mut self, t_s: f64, samples_lost: u64, reason: String) {
        self.ready.push_back(AsciiEvent::Gap(Gap { source: self.source.clone(), t_s, samples_lost, reason }));
    }

    fn add_sample(&mut self, t_ns: i64, values: &[f64], host_time_ns: i64) {
        if self.n == 0 {
            self.t_first_ns = t_ns;
        }
        self.values.extend_from_slice(values);
        self.n += 1;
        self.t_last_ns = t_ns;
        self.stats.samples += 1;
        // n samples cover n periods: close once that reaches the batch length (to half a period).
        let period_s = self.stamps.period_ns().unwrap_or(0.0) * 1e-9;
        let covered_s = (t_ns as i128 - self.t_first_ns as i128) as f64 * 1e-9 + period_s;
        if covered_s + 0.5 * period_s >= self.batch_s || self.n >= MAX_BATCH_SAMPLES {
            self.close_batch(host_time_ns);
        }
    }

    /// Parse `t_s` and one value per role into `self.fields`; false if malformed.
    fn parse(&mut self, line: &[u8]) -> bool {
        self.fields.clear();
        let Ok(text) = std::str::from_utf8(line) else { return false };
        for field in text.split(',') {
            if self.fields.len() > self.roles.len() {
                return false;
            }
            match field.trim().parse::<f64>() {
                Ok(v) if v.is_finite() => self.fields.push(v),
                _ => return false,
            }
        }
        self.fields.len() == self.roles.len() + 1 && self.fields[0].abs() <= MAX_ABS_T_S
    }

    fn close_batch(&mut self, host_time_ns: i64) {
        if self.n == 0 {
            return;
        }
        if self.n >= REFINE_MIN_SAMPLES {
            // Batches are cut at every hole, so the run's stamps are consecutive samples.
            let measured = (self.t_last_ns as i128 - self.t_first_ns as i128) as f64 / (self.n - 1) as f64;
            self.stamps.refine_period(measured);
        }
        self.seq += 1;
        let values = std::mem::take(&mut self.values);
        self.values.reserve(values.len());
        self.ready.push_back(AsciiEvent::Batch(SampleBatch {
            source: self.source.clone(),
            seq: self.seq,
            device_time_ns: self.t_first_ns,
            host_time_ns,
            period_ns: self.stamps.period_ns().unwrap_or(0.0),
            roles: self.roles.clone(),
            values,
        }));
        self.n = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::super::stamps::RESYNC_MISFITS;
    use super::*;

    fn roles() -> Vec<Role> {
        vec![Role::Load, Role::Disp]
    }

    fn events(dec: &mut LineDecoder) -> Vec<AsciiEvent> {
        std::iter::from_fn(|| dec.next_event()).collect()
    }

    fn batches(ev: &[AsciiEvent]) -> Vec<&SampleBatch> {
        ev.iter()
            .filter_map(|e| match e {
                AsciiEvent::Batch(b) => Some(b),
                _ => None,
            })
            .collect()
    }

    fn gaps(ev: &[AsciiEvent]) -> Vec<&Gap> {
        ev.iter()
            .filter_map(|e| match e {
                AsciiEvent::Gap(g) => Some(g),
                _ => None,
            })
            .collect()
    }

    /// Every sample's device time and first value, in order.
    fn samples(ev: &[AsciiEvent]) -> Vec<(i64, f64)> {
        batches(ev)
            .iter()
            .flat_map(|b| (0..b.len()).map(move |i| ((b.time_s(i) * 1e9).round() as i64, b.values[i * b.roles.len()])))
            .collect()
    }

    /// Feed `text`, flush, and return the events.
    fn decode(text: &str) -> (Vec<AsciiEvent>, LineStats) {
        let mut dec = LineDecoder::new("daq", roles(), 1.0);
        dec.push(text.as_bytes(), 0);
        dec.flush(0);
        (events(&mut dec), dec.stats())
    }

    /// Lines `t_s,k,0.5` at 1 kHz from 10 s, for each k.
    fn lines_at_1khz(ks: impl IntoIterator<Item = i64>) -> String {
        ks.into_iter().map(|k| format!("{:.3},{k},0.5\n", 10.0 + k as f64 * 1e-3)).collect()
    }

    #[test]
    fn good_lines_become_batches_of_the_configured_length() {
        // 1 kHz, 10 ms batches: 10 lines per batch.
        let mut dec = LineDecoder::new("daq", roles(), 0.01);
        let text: String = (0..25).map(|k| format!("{:.4},{},{}\n", 80.0 + k as f64 * 1e-3, k * 10, 0.5)).collect();
        dec.push(text.as_bytes(), 7);
        let ev = events(&mut dec);
        let b = batches(&ev);
        assert_eq!(b.len(), 2);
        assert_eq!(b[0].len(), 10);
        assert_eq!((b[0].seq, b[0].host_time_ns, b[0].device_time_ns), (1, 7, 80_000_000_000));
        assert!((b[0].period_ns - 1e6).abs() < 1.0);
        assert_eq!(b[0].roles, roles());
        assert_eq!(&b[0].values[..4], &[0.0, 0.5, 10.0, 0.5]);
        assert_eq!(b[1].device_time_ns, 80_010_000_000);
        // The remaining 5 lines come out on flush.
        dec.flush(8);
        let ev = events(&mut dec);
        assert_eq!(batches(&ev)[0].len(), 5);
        assert_eq!(dec.stats(), LineStats { lines: 25, samples: 25, ..LineStats::default() });
    }

    #[test]
    fn malformed_lines_are_counted_and_skipped() {
        let mut dec = LineDecoder::new("daq", roles(), 1.0);
        let text = b"t_s,load_N,disp_m\n\
                    1.000,10,0.5\n\
                    1.001,11\n\
                    1.001,12,0.5,9\n\
                    1.001,abc,0.5\n\
                    1.001,NaN,0.5\n\
                    1.001,inf,0.5\n\
                    \xff\xfe,1,2\n\
                    5e9,1,2\n\
                    \r\n\
                    1.001,11,0.5\r\n";
        dec.push(text, 0);
        // Split a line across pushes: partial input waits for its newline.
        dec.push(b"1.00", 0);
        dec.push(b"2,12,0.", 0);
        dec.push(b"5\n", 0);
        dec.flush(0);
        let ev = events(&mut dec);
        let b = batches(&ev);
        assert_eq!(b.len(), 1);
        assert_eq!(b[0].values, vec![10.0, 0.5, 11.0, 0.5, 12.0, 0.5]);
        // header, short, long, text, NaN, inf, not UTF-8, a stamp past MAX_ABS_T_S; the
        // blank line is not counted
        let s = dec.stats();
        assert_eq!((s.unparsable, s.malformed, s.samples, s.lines), (8, 8, 3, 11));
        assert_eq!(gaps(&ev).len(), 0, "an unparsable line is no hole when the next line is on time");
    }

    #[test]
    fn empty_input_partial_lines_and_an_overlong_line_of_garbage() {
        let mut dec = LineDecoder::new("daq", roles(), 1.0);
        dec.push(b"", 0);
        dec.flush(0);
        assert_eq!(dec.next_event(), None);
        dec.push(&vec![b'7'; MAX_LINE_BYTES + 10], 0);
        dec.push(&vec![b'7'; 3000], 0);
        dec.push(b"\n2.000,1,1\n2.001,2,2\n2.00", 0); // the third line is still partial
        dec.flush(0);
        assert_eq!(dec.next_event(), None, "two lines are not yet a period: nothing is a sample");
        assert_eq!(dec.stats().pending, 2);
        dec.push(b"2,3,3\n", 0);
        dec.flush(0);
        let ev = events(&mut dec);
        assert_eq!(batches(&ev)[0].values, vec![1.0, 1.0, 2.0, 2.0, 3.0, 3.0]);
        let s = dec.stats();
        assert_eq!((s.lines, s.unparsable, s.samples, s.pending), (4, 1, 3, 0));
    }

    #[test]
    fn a_step_in_time_is_a_gap() {
        let mut text = String::new();
        for k in (0..10).chain(15..20) {
            text.push_str(&format!("{:.6},1,2\n", 5.0 + k as f64 * 1e-4));
        }
        let (ev, stats) = decode(&text);
        assert_eq!(ev.len(), 3);
        match &ev[1] {
            AsciiEvent::Gap(g) => {
                assert_eq!(g.samples_lost, 5); // samples 10..=14
                assert_eq!(g.reason, "time_jump: t_s jumped 6 periods to 5.0015");
                assert!((g.t_s - 5.001).abs() < 1e-9);
            }
            other => panic!("expected a gap, got {other:?}"),
        }
        let b = batches(&ev);
        assert_eq!((b[0].len(), b[1].len()), (10, 5));
        assert_eq!(b[1].device_time_ns, 5_001_500_000);
        assert_eq!((stats.samples, stats.malformed), (15, 0));
    }

    #[test]
    fn a_wild_stamp_is_dropped_never_a_sample_a_gap_or_a_blow() {
        // Line k = 5 reads -79.95 s (the wild stamp), line 12 reads 90.012 (a
        // flipped digit, 80 s ahead): each is dropped and its sample counted lost.
        let mut text = lines_at_1khz(0..5);
        text.push_str("-79.950,5,0.5\n");
        text.push_str(&lines_at_1khz(6..12));
        text.push_str("90.012,12,0.5\n");
        text.push_str(&lines_at_1khz(13..20));
        let (ev, s) = decode(&text);
        assert_eq!((s.wild_stamps, s.out_of_sequence, s.malformed, s.samples, s.restarts), (1, 1, 2, 18, 0));
        let times: Vec<i64> = samples(&ev).iter().map(|(t, _)| *t).collect();
        let want: Vec<i64> = (0..20).filter(|k| *k != 5 && *k != 12).map(|k| 10_000_000_000 + k * 1_000_000).collect();
        assert_eq!(times, want, "no sample at a wild time");
        let g = gaps(&ev);
        assert_eq!(g.iter().map(|g| g.samples_lost).collect::<Vec<_>>(), vec![1, 1], "each dropped line's sample");
    }

    #[test]
    fn a_backwards_stamp_is_dropped_as_out_of_sequence() {
        // Line 7 repeats line 3's stamp (a buffer replayed): behind, and line 8 continues 6.
        let mut text = lines_at_1khz(0..7);
        text.push_str("10.003,99,0.5\n");
        text.push_str(&lines_at_1khz(7..10));
        let (ev, s) = decode(&text);
        assert_eq!((s.out_of_sequence, s.wild_stamps, s.samples), (1, 0, 10));
        assert!(gaps(&ev).is_empty(), "nothing lost: no gap");
        assert!(samples(&ev).iter().all(|(_, v)| *v != 99.0));
    }

    #[test]
    fn a_hole_is_confirmed_by_the_line_after_it() {
        // 0..5, then 9..12: the stamp of line 9 is 5 periods after line 4's, and line 10
        // continues it: lines 5..=8 are lost.
        let mut text = lines_at_1khz(0..5);
        text.push_str(&lines_at_1khz(9..12));
        let (ev, s) = decode(&text);
        let g = gaps(&ev);
        assert_eq!(g.len(), 1);
        assert_eq!(g[0].samples_lost, 4);
        assert!((g[0].t_s - 10.005).abs() < 1e-9);
        assert_eq!((s.samples, s.malformed), (8, 0));
    }

    #[test]
    fn a_device_restart_is_accepted_once_confirmed_and_reported() {
        // The device restarts: its clock goes from 10.004 back to 0.000, then runs on.
        let mut text = lines_at_1khz(0..5);
        text.push_str("0.000,100,0.5\n0.001,101,0.5\n0.002,102,0.5\n");
        let (ev, s) = decode(&text);
        assert_eq!((s.restarts, s.samples, s.malformed), (1, 8, 0));
        let g = gaps(&ev);
        assert_eq!(g.len(), 1);
        assert_eq!((g[0].samples_lost, g[0].t_s), (0, 0.0));
        assert_eq!(g[0].reason, "device_restart: t_s went back from 10.004 to 0");
        assert_eq!((seconds(-79_950_000_000), seconds(10_000_000_001)), ("-79.95".into(), "10.000000001".into()));
        let b = batches(&ev);
        assert_eq!(b.len(), 2, "no batch straddles the restart");
        assert_eq!((b[1].device_time_ns, b[1].values[0]), (0, 100.0));
    }

    #[test]
    fn garbage_in_the_first_lines_cannot_set_the_period() {
        // Line 1 is wild (-79.95): the start-up window slides past it, dropping line 0 too
        // (a window of 3 with a wild stamp cannot tell which line is wrong).
        let text = format!("10.000,0,0.5\n-79.950,1,0.5\n{}", lines_at_1khz(2..10));
        let (ev, s) = decode(&text);
        assert_eq!((s.wild_stamps, s.samples), (2, 8));
        let b = batches(&ev);
        assert!((b[0].period_ns - 1e6).abs() < 1.0, "{}", b[0].period_ns);
        assert_eq!(b[0].device_time_ns, 10_002_000_000);
        assert!(gaps(&ev).is_empty());
    }

    #[test]
    fn finite_but_absurd_values_pass_only_non_finite_ones_are_dropped() {
        // No sensor ranges in the config yet: 1e30 is a number and passes; NaN does not.
        let text = "1.000,1e30,0.5\n1.001,nan,0.5\n1.001,2,0.5\n1.002,3,0.5\n";
        let (ev, s) = decode(text);
        assert_eq!(batches(&ev)[0].values, vec![1e30, 0.5, 2.0, 0.5, 3.0, 0.5]);
        assert_eq!((s.unparsable, s.samples), (1, 3));
    }

    #[test]
    fn a_new_rate_is_taken_after_the_lock_is_lost() {
        // 1 kHz, then the device switches to 4 kHz (most stamps fall between periods, and
        // are dropped) or to 500 Hz (every stamp looks like a one-sample hole): once half
        // the recent stamps misfit, the period is established afresh, a new timeline.
        for (new_period_s, max_false_gaps) in [(0.25e-3, 0), (2e-3, RESYNC_MISFITS as usize)] {
            let mut text = lines_at_1khz(0..40);
            for k in 0..60 {
                text.push_str(&format!("{:.5},{},0.5\n", 10.040 + k as f64 * new_period_s, 100 + k));
            }
            let (ev, s) = decode(&text);
            assert_eq!(s.restarts, 1, "{new_period_s}");
            let g = gaps(&ev);
            let resync = g.iter().filter(|g| g.reason.starts_with("time_resync:")).count();
            assert_eq!(resync, 1, "{g:?}");
            assert!(g.len() - 1 <= max_false_gaps, "{g:?}");
            let last = batches(&ev).last().map(|b| b.period_ns).unwrap_or(0.0);
            assert!((last - new_period_s * 1e9).abs() < 1.0, "{last}");
            assert_eq!(s.lines, s.samples + s.malformed + s.pending);
        }
    }
}
