//! `candump -L` logs (can-utils): `(1700000000.123456) can0 123#DEADBEEF`, one frame a
//! line, so bus traffic captured on the plant floor can be replayed, and the simulated
//! device writes them. Each line is parsed by `socketcan::dump` (which knows the
//! standard/extended width rule, remote, error and CAN FD lines); this file adds line
//! numbers, the file name in errors, and the writer.
//!
//! Policy: a malformed line is a [`CanError::LogLine`] naming the file and line. The
//! reader continues after it if asked for the next frame, so a caller chooses between
//! stopping ([`BadLines::Fail`], what `read_candump` does by default) and counting
//! ([`BadLines::Count`], into the decoder's `decode_errors`). Blank lines and lines
//! starting with `#` are skipped. Remote, error and CAN FD (`##`) frames are not
//! samples: they are returned as [`LoggedFrame::Unsupported`] and counted by the decoder.

use std::io::{BufRead, Write};

use socketcan::{CanAnyFrame, EmbeddedFrame, Id};

use crate::acquire::SourceEvent;

use super::CanError;
use super::decoder::CanDecoder;
use super::signal::FrameId;

/// The content of one log line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LoggedFrame {
    /// A classic data frame: `len` bytes of `data` are the payload.
    Data { frame: FrameId, len: u8, data: [u8; 8] },
    /// A remote, error or CAN FD frame.
    Unsupported,
}

/// One parsed log line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogFrame {
    /// 1-based line number.
    pub line: u64,
    /// Receive time, ns since the epoch (µs resolution in the log).
    pub t_ns: i64,
    pub iface: String,
    pub frame: LoggedFrame,
}

impl LogFrame {
    /// The payload of a data frame.
    pub fn data(&self) -> Option<(FrameId, &[u8])> {
        match &self.frame {
            LoggedFrame::Data { frame, len, data } => Some((*frame, &data[..*len as usize])),
            LoggedFrame::Unsupported => None,
        }
    }
}

/// Parse one line (without its newline). `Ok(None)` for blank and `#` comment lines.
pub fn parse_line(text: &str) -> Result<Option<(i64, String, LoggedFrame)>, String> {
    let t = text.trim();
    if t.is_empty() || t.starts_with('#') {
        return Ok(None);
    }
    let mut reader = socketcan::dump::Reader::from_reader(t.as_bytes());
    let rec = match reader.next_record() {
        Ok(Some(rec)) => rec,
        Ok(None) => return Ok(None),
        Err(e) => return Err(e.to_string().to_lowercase()),
    };
    let t_ns = i64::try_from(rec.t_us).ok().and_then(|us| us.checked_mul(1000)).ok_or("timestamp out of range")?;
    let frame = match &rec.frame {
        CanAnyFrame::Normal(f) => {
            let frame = match f.id() {
                Id::Standard(id) => FrameId::standard(id.as_raw()),
                Id::Extended(id) => FrameId::extended(id.as_raw()),
            };
            let payload = f.data();
            let mut data = [0u8; 8];
            let len = payload.len().min(8);
            data[..len].copy_from_slice(&payload[..len]);
            LoggedFrame::Data { frame, len: len as u8, data }
        }
        CanAnyFrame::Remote(_) | CanAnyFrame::Error(_) | CanAnyFrame::Fd(_) => LoggedFrame::Unsupported,
    };
    Ok(Some((t_ns, rec.device, frame)))
}

/// Reads a `candump -L` log line by line.
#[derive(Debug)]
pub struct CandumpReader<R> {
    origin: String,
    input: R,
    line: u64,
    buf: String,
}

impl<R: BufRead> CandumpReader<R> {
    /// `origin` (the file name) is named in errors.
    pub fn new(origin: impl Into<String>, input: R) -> Self {
        CandumpReader { origin: origin.into(), input, line: 0, buf: String::with_capacity(64) }
    }

    /// Lines read so far.
    pub fn line(&self) -> u64 {
        self.line
    }

    /// The next frame, `Ok(None)` at the end. After an error naming a malformed line the
    /// reader is positioned on the next line.
    pub fn next_frame(&mut self) -> Result<Option<LogFrame>, CanError> {
        loop {
            self.buf.clear();
            let n = self
                .input
                .read_line(&mut self.buf)
                .map_err(|source| CanError::Io { origin: format!("{}:{}", self.origin, self.line + 1), source })?;
            if n == 0 {
                return Ok(None);
            }
            self.line += 1;
            match parse_line(&self.buf) {
                Ok(Some((t_ns, iface, frame))) => return Ok(Some(LogFrame { line: self.line, t_ns, iface, frame })),
                Ok(None) => continue,
                Err(why) => {
                    return Err(CanError::LogLine {
                        origin: self.origin.clone(),
                        line: self.line,
                        why,
                        text: self.buf.trim_end().chars().take(120).collect(),
                    });
                }
            }
        }
    }
}

/// What to do with a malformed log line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BadLines {
    /// Stop with the error naming the file and line.
    Fail,
    /// Count it in the decoder's `decode_errors` and go on.
    Count,
}

/// Feed a whole log to `decoder` and return its events (batches and gaps), the last
/// partial batch included.
pub fn read_candump<R: BufRead>(
    reader: &mut CandumpReader<R>,
    decoder: &mut CanDecoder,
    bad_lines: BadLines,
) -> Result<Vec<SourceEvent>, CanError> {
    let mut out = Vec::new();
    loop {
        match reader.next_frame() {
            Ok(Some(f)) => match f.data() {
                Some((frame, data)) => decoder.push(f.t_ns, frame, data, &mut out),
                None => decoder.skip_unsupported(),
            },
            Ok(None) => break,
            Err(e @ CanError::LogLine { .. }) if bad_lines == BadLines::Count => {
                let _ = e;
                decoder.counters_mut().decode_errors += 1;
            }
            Err(e) => return Err(e),
        }
    }
    decoder.flush(&mut out);
    Ok(out)
}

/// Write one frame as a `candump -L` line: `(sec.usec) iface ID#DATA`, the identifier
/// 3 hex digits (standard) or 8 (extended), the data in upper-case hex.
pub fn write_candump_line<W: Write>(
    w: &mut W,
    t_ns: i64,
    iface: &str,
    frame: FrameId,
    data: &[u8],
) -> std::io::Result<()> {
    let t_us = t_ns.div_euclid(1000);
    write!(w, "({}.{:06}) {iface} {frame}#", t_us.div_euclid(1_000_000), t_us.rem_euclid(1_000_000))?;
    for b in data {
        write!(w, "{b:02X}")?;
    }
    writeln!(w)
}

#[cfg(test)]
mod tests {
    use super::super::{CanTiming, SAMPLE_FRAME, forgemon_mapping};
    use super::*;

    #[test]
    fn lines_of_every_kind() {
        let (t, iface, f) = parse_line("(1700000000.123456) can0 123#DEADBEEF\n").unwrap().unwrap();
        assert_eq!(t, 1_700_000_000_123_456_000);
        assert_eq!(iface, "can0");
        let mut data = [0u8; 8];
        data[..4].copy_from_slice(&[0xDE, 0xAD, 0xBE, 0xEF]);
        assert_eq!(f, LoggedFrame::Data { frame: FrameId::standard(0x123), len: 4, data });
        // Eight digits: extended, even when the value would fit 11 bits.
        let (_, _, f) = parse_line("(1.000000) can1 00000123#01").unwrap().unwrap();
        assert!(matches!(f, LoggedFrame::Data { frame, len: 1, .. } if frame == FrameId::extended(0x123)));
        // FD, remote and error frames are not samples.
        for l in ["(1.000000) can0 120##5112233", "(1.000000) can0 120#R", "(1.000000) can0 20000004#000C000000000000"]
        {
            assert_eq!(parse_line(l).unwrap().unwrap().2, LoggedFrame::Unsupported, "{l}");
        }
        assert_eq!(parse_line("   ").unwrap(), None);
        assert_eq!(parse_line("# a comment").unwrap(), None);
        for bad in [
            "1.000000 can0 123#00",
            "(1.0) can0 123#00",
            "(1.000000) can0 1234#00",
            "(1.000000) can0 123#0",
            "(1.000000) can0",
        ] {
            assert!(parse_line(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_writer_round_trips_through_the_parser() {
        let mut w = Vec::new();
        write_candump_line(&mut w, 79_962_098_000, "can0", SAMPLE_FRAME, &[1, 2, 0xAB]).unwrap();
        write_candump_line(&mut w, 5_000, "vcan1", FrameId::extended(0x1ABCDEF0), &[]).unwrap();
        let text = String::from_utf8(w).unwrap();
        assert_eq!(text, "(79.962098) can0 120#0102AB\n(0.000005) vcan1 1ABCDEF0#\n");
        let mut r = CandumpReader::new("x.log", text.as_bytes());
        let a = r.next_frame().unwrap().unwrap();
        assert_eq!((a.t_ns, a.data()), (79_962_098_000, Some((SAMPLE_FRAME, &[1u8, 2, 0xAB][..]))));
        let b = r.next_frame().unwrap().unwrap();
        assert_eq!((b.line, b.data()), (2, Some((FrameId::extended(0x1ABCDEF0), &[][..]))));
        assert!(r.next_frame().unwrap().is_none());
    }

    #[test]
    fn a_bad_line_names_file_and_line_and_reading_can_go_on() {
        let log =
            "(1.000000) can0 120#0000000000000000\n\n(1.000200) can0 12#00\n(1.000400) can0 120#0100000000000000\n";
        let mut r = CandumpReader::new("bus.log", log.as_bytes());
        assert!(r.next_frame().unwrap().is_some());
        let e = r.next_frame().unwrap_err().to_string();
        assert!(e.starts_with("bus.log:3: not a candump -L line"), "{e}");
        assert!(e.contains("12#00"), "{e}");
        assert_eq!(r.next_frame().unwrap().unwrap().line, 4);

        let timing = CanTiming { period_ns: 200_000.0, batch_samples: 10, trust_timestamps: true };
        let mut d = CanDecoder::new("can", forgemon_mapping(), timing);
        let e = read_candump(&mut CandumpReader::new("bus.log", log.as_bytes()), &mut d, BadLines::Fail).unwrap_err();
        assert!(matches!(e, CanError::LogLine { line: 3, .. }));
        let mut d = CanDecoder::new("can", forgemon_mapping(), timing);
        let ev = read_candump(&mut CandumpReader::new("bus.log", log.as_bytes()), &mut d, BadLines::Count).unwrap();
        assert_eq!(d.counters().decode_errors, 1);
        assert_eq!(d.counters().samples, 2);
        assert_eq!(ev.len(), 1, "one batch, no gap: the bad line was not a sample frame");
    }
}
