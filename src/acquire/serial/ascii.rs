//! The ASCII variant of the serial DAQ stream (CONTRACTS.md §7), sans-IO: lines of
//! `t_s,v0,v1,...\n` with the values already in physical units, in the configured channel
//! order. `LineDecoder` is fed byte chunks, skips and counts malformed lines, and groups
//! the good ones into `SampleBatch`es of about `batch_s` each. There is no sequence number,
//! so the sample period is estimated from successive `t_s` and a jump in time is reported
//! as a `Gap`. No IO, no clock: the caller passes the host receive time.

use std::collections::VecDeque;

use crate::record::Gap;
use crate::signal::sample::{Role, SampleBatch};

/// Batch length when none is configured, s (DESIGN.md §3: 10–100 ms per message).
pub const DEFAULT_ASCII_BATCH_S: f64 = 0.02;
/// Most samples in one batch, whatever the period.
pub const MAX_BATCH_SAMPLES: usize = 4096;
/// A longer line is garbage: it is dropped up to its `\n` and counted once.
pub const MAX_LINE_BYTES: usize = 1024;
/// A step in `t_s` above this many estimated periods is a gap.
pub const GAP_PERIODS: f64 = 1.5;

/// What the line decoder produces.
#[derive(Debug, Clone, PartialEq)]
pub enum AsciiEvent {
    Batch(SampleBatch),
    /// Samples missing between two lines (a step in `t_s`), reason `"time_jump"`.
    Gap(Gap),
}

/// What a `LineDecoder` has seen since it was created.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LineStats {
    pub lines: u64,
    pub malformed: u64,
    pub samples: u64,
    /// `t_s` went backwards: the device restarted its clock.
    pub restarts: u64,
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
    t_first_s: f64,
    t_last_s: Option<f64>,
    n: usize,
    period_s: Option<f64>,
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
            t_first_s: 0.0,
            t_last_s: None,
            n: 0,
            period_s: None,
            seq: 0,
            ready: VecDeque::new(),
            stats: LineStats::default(),
        }
    }

    pub fn stats(&self) -> LineStats {
        self.stats
    }

    /// The estimated sample period, s.
    pub fn period_s(&self) -> Option<f64> {
        self.period_s
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
                            self.stats.malformed += 1;
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
    /// closed.
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
            self.stats.malformed += 1;
            return;
        }
        let t_s = self.fields[0];
        if let Some(last) = self.t_last_s {
            let dt = t_s - last;
            if dt <= 0.0 {
                // Time went backwards: a restarted device clock. Start over.
                self.stats.restarts += 1;
                self.close_batch(host_time_ns);
                self.t_last_s = None;
            } else {
                let period = *self.period_s.get_or_insert(dt);
                if dt > GAP_PERIODS * period {
                    self.close_batch(host_time_ns);
                    let lost = ((dt / period).round() as u64).saturating_sub(1);
                    if lost > 0 {
                        self.ready.push_back(AsciiEvent::Gap(Gap {
                            source: self.source.clone(),
                            t_s: last + period,
                            samples_lost: lost,
                            reason: "time_jump".to_string(),
                        }));
                    }
                }
            }
        }
        if self.n == 0 {
            self.t_first_s = t_s;
        }
        self.values.extend_from_slice(&self.fields[1..]);
        self.n += 1;
        self.t_last_s = Some(t_s);
        self.stats.samples += 1;
        // n samples cover n periods: close once that reaches the batch length (to half a period).
        let period = self.period_s.unwrap_or(0.0);
        let covered_s = t_s - self.t_first_s + period;
        if covered_s + 0.5 * period >= self.batch_s || self.n >= MAX_BATCH_SAMPLES {
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
        self.fields.len() == self.roles.len() + 1
    }

    fn close_batch(&mut self, host_time_ns: i64) {
        if self.n == 0 {
            return;
        }
        let t_last = self.t_last_s.unwrap_or(self.t_first_s);
        let period_s = if self.n >= 2 {
            let p = (t_last - self.t_first_s) / (self.n - 1) as f64;
            self.period_s = Some(p);
            p
        } else {
            self.period_s.unwrap_or(0.0)
        };
        self.seq += 1;
        let values = std::mem::take(&mut self.values);
        self.values.reserve(values.len());
        self.ready.push_back(AsciiEvent::Batch(SampleBatch {
            source: self.source.clone(),
            seq: self.seq,
            device_time_ns: (self.t_first_s * 1e9).round() as i64,
            host_time_ns,
            period_ns: period_s * 1e9,
            roles: self.roles.clone(),
            values,
        }));
        self.n = 0;
    }
}

#[cfg(test)]
mod tests {
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
        assert_eq!(dec.stats(), LineStats { lines: 25, malformed: 0, samples: 25, restarts: 0 });
    }

    #[test]
    fn malformed_lines_are_counted_and_skipped() {
        let mut dec = LineDecoder::new("daq", roles(), 1.0);
        let text = b"t_s,load_N,disp_m\n\
                    1.000,10,0.5\n\
                    1.001,11\n\
                    1.002,12,0.5,9\n\
                    1.003,abc,0.5\n\
                    1.004,NaN,0.5\n\
                    \xff\xfe,1,2\n\
                    \r\n\
                    1.005,15,0.5\r\n";
        dec.push(text, 0);
        // Split a line across pushes: partial input waits for its newline.
        dec.push(b"1.00", 0);
        dec.push(b"6,16,0.", 0);
        dec.push(b"5\n", 0);
        dec.flush(0);
        let ev = events(&mut dec);
        let b = batches(&ev);
        assert_eq!(b.len(), 1);
        assert_eq!(b[0].values, vec![10.0, 0.5, 15.0, 0.5, 16.0, 0.5]);
        // header, short, long, text, NaN, not UTF-8; the blank line is not counted
        assert_eq!(dec.stats().malformed, 6);
        assert_eq!(dec.stats().samples, 3);
    }

    #[test]
    fn empty_input_and_an_overlong_line_of_garbage() {
        let mut dec = LineDecoder::new("daq", roles(), 1.0);
        dec.push(b"", 0);
        dec.flush(0);
        assert_eq!(dec.next_event(), None);
        dec.push(&vec![b'7'; MAX_LINE_BYTES + 10], 0);
        dec.push(&vec![b'7'; 3000], 0);
        dec.push(b"\n2.0,1,1\n", 0);
        dec.flush(0);
        let ev = events(&mut dec);
        assert_eq!(batches(&ev)[0].values, vec![1.0, 1.0]);
        assert_eq!(dec.stats().malformed, 1);
    }

    #[test]
    fn a_step_in_time_is_a_gap() {
        let mut dec = LineDecoder::new("daq", roles(), 1.0);
        let mut text = String::new();
        for k in (0..10).chain(15..20) {
            text.push_str(&format!("{:.6},1,2\n", 5.0 + k as f64 * 1e-4));
        }
        dec.push(text.as_bytes(), 0);
        dec.flush(0);
        let ev = events(&mut dec);
        assert_eq!(ev.len(), 3);
        match &ev[1] {
            AsciiEvent::Gap(g) => {
                assert_eq!(g.samples_lost, 5); // samples 10..=14
                assert_eq!(g.reason, "time_jump");
                assert!((g.t_s - 5.001).abs() < 1e-9);
            }
            other => panic!("expected a gap, got {other:?}"),
        }
        let b = batches(&ev);
        assert_eq!((b[0].len(), b[1].len()), (10, 5));
        assert_eq!(b[1].device_time_ns, 5_001_500_000);
    }
}
