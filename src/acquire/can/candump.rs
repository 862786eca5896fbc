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
//! starting with `#` are skipped. Remote and error frames are not samples: they are
//! returned as [`LoggedFrame::Unsupported`] and counted by the decoder.
//!
//! CAN FD lines, `(1700000000.123456) can0 121##1AABBCC…`: `##`, one hex digit of FD
//! flags (BRS 1, ESI 2, FDF 4), then 0 to 64 data bytes of a valid FD length (0–8, 12,
//! 16, 20, 24, 32, 48 or 64). They are checked here first, so that an error says what is
//! wrong with the line (the flags digit, an odd or non-hex data field, a length FD does
//! not have, more than 64 bytes), and read as [`LoggedFrame::Fd`]. A decoder reads the
//! kind its mapping is for and counts the other kind as unsupported ([`LogFrame::feed`]).

use std::io::{BufRead, Write};

use socketcan::{CanAnyFrame, EmbeddedFrame, Id};

use crate::acquire::SourceEvent;

use super::CanError;
use super::decoder::CanDecoder;
use super::signal::{FD_LENGTHS, FD_MAX_LEN, FrameId};

/// The content of one log line (or one frame read from a socket).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LoggedFrame {
    /// A classic data frame: `len` bytes of `data` are the payload.
    Data { frame: FrameId, len: u8, data: [u8; 8] },
    /// A CAN FD data frame: `len` (a valid FD length) bytes of `data`, and its FD flags.
    Fd { frame: FrameId, flags: u8, len: u8, data: [u8; FD_MAX_LEN] },
    /// A remote or error frame.
    Unsupported,
}

impl LoggedFrame {
    /// The frame `socketcan` read (from a log line or a socket).
    pub fn from_any(f: &CanAnyFrame) -> LoggedFrame {
        let id = |id: Id| match id {
            Id::Standard(id) => FrameId::standard(id.as_raw()),
            Id::Extended(id) => FrameId::extended(id.as_raw()),
        };
        match f {
            CanAnyFrame::Normal(f) => {
                let payload = f.data();
                let mut data = [0u8; 8];
                let len = payload.len().min(8);
                data[..len].copy_from_slice(&payload[..len]);
                LoggedFrame::Data { frame: id(f.id()), len: len as u8, data }
            }
            CanAnyFrame::Fd(f) => {
                let payload = f.data();
                let mut data = [0u8; FD_MAX_LEN];
                let len = payload.len().min(FD_MAX_LEN);
                data[..len].copy_from_slice(&payload[..len]);
                LoggedFrame::Fd { frame: id(f.id()), flags: f.flags().bits(), len: len as u8, data }
            }
            CanAnyFrame::Remote(_) | CanAnyFrame::Error(_) => LoggedFrame::Unsupported,
        }
    }

    /// The identifier, whether it is a CAN FD frame, and the payload of a data frame.
    pub fn payload(&self) -> Option<(FrameId, bool, &[u8])> {
        match self {
            LoggedFrame::Data { frame, len, data } => Some((*frame, false, &data[..*len as usize])),
            LoggedFrame::Fd { frame, len, data, .. } => Some((*frame, true, &data[..*len as usize])),
            LoggedFrame::Unsupported => None,
        }
    }

    /// Give the frame to `decoder` received at `t_ns`: a data frame of the kind its
    /// mapping reads (classic or FD) is decoded, anything else counted as unsupported.
    pub fn feed(&self, t_ns: i64, decoder: &mut CanDecoder, out: &mut Vec<SourceEvent>) {
        match self.payload() {
            Some((frame, fd, data)) if fd == decoder.mapping().is_fd() => decoder.push(t_ns, frame, data, out),
            _ => decoder.skip_unsupported(),
        }
    }
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
    /// The payload of a data frame, classic or FD.
    pub fn data(&self) -> Option<(FrameId, &[u8])> {
        self.frame.payload().map(|(frame, _, data)| (frame, data))
    }

    /// Give the frame to `decoder` (see [`LoggedFrame::feed`]).
    pub fn feed(&self, decoder: &mut CanDecoder, out: &mut Vec<SourceEvent>) {
        self.frame.feed(self.t_ns, decoder, out);
    }
}

/// Check the frame field of a CAN FD line (`ID##F…`), so that the error says what is
/// wrong; `Ok` for a line that is not FD.
fn check_fd_field(text: &str) -> Result<(), String> {
    let Some(field) = text.split_whitespace().nth(2) else { return Ok(()) };
    let Some((_, rest)) = field.split_once("##") else { return Ok(()) };
    let mut chars = rest.chars();
    match chars.next() {
        Some(c) if c.is_ascii_hexdigit() => {}
        Some(c) => return Err(format!("CAN FD flags must be one hex digit after '##', got {c:?}")),
        None => return Err("CAN FD frame without its flags digit after '##'".into()),
    }
    let hex = chars.as_str();
    if let Some(c) = hex.chars().find(|c| !c.is_ascii_hexdigit()) {
        return Err(format!("CAN FD data is not hex: {c:?}"));
    }
    if hex.len() % 2 == 1 {
        return Err(format!("CAN FD data has an odd number of hex digits ({})", hex.len()));
    }
    let n = hex.len() / 2;
    if n > FD_MAX_LEN {
        return Err(format!("CAN FD data of {n} bytes is over {FD_MAX_LEN}"));
    }
    if !FD_LENGTHS.contains(&n) {
        return Err(format!("{n} bytes is not a CAN FD length (0-8, 12, 16, 20, 24, 32, 48 or 64)"));
    }
    Ok(())
}

/// Parse one line (without its newline). `Ok(None)` for blank and `#` comment lines.
pub fn parse_line(text: &str) -> Result<Option<(i64, String, LoggedFrame)>, String> {
    let t = text.trim();
    if t.is_empty() || t.starts_with('#') {
        return Ok(None);
    }
    check_fd_field(t)?;
    let mut reader = socketcan::dump::Reader::from_reader(t.as_bytes());
    let rec = match reader.next_record() {
        Ok(Some(rec)) => rec,
        Ok(None) => return Ok(None),
        Err(e) => return Err(e.to_string().to_lowercase()),
    };
    let t_ns = i64::try_from(rec.t_us).ok().and_then(|us| us.checked_mul(1000)).ok_or("timestamp out of range")?;
    Ok(Some((t_ns, rec.device, LoggedFrame::from_any(&rec.frame))))
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
            Ok(Some(f)) => f.feed(decoder, &mut out),
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

/// Write one CAN FD frame as a `candump -L` line: `(sec.usec) iface ID##FDATA`, `F` the
/// FD flags as one hex digit (BRS 1, ESI 2). `data` must have a valid FD length.
pub fn write_candump_fd_line<W: Write>(
    w: &mut W,
    t_ns: i64,
    iface: &str,
    frame: FrameId,
    flags: u8,
    data: &[u8],
) -> std::io::Result<()> {
    let t_us = t_ns.div_euclid(1000);
    write!(w, "({}.{:06}) {iface} {frame}##{:X}", t_us.div_euclid(1_000_000), t_us.rem_euclid(1_000_000), flags & 0xF)?;
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
        // CAN FD: flags, then the payload.
        let (_, _, f) = parse_line("(1.000000) can0 120##5112233").unwrap().unwrap();
        let LoggedFrame::Fd { frame, flags, len: 3, data } = f else { panic!("{f:?}") };
        assert_eq!((frame, flags & 0x3, &data[..3]), (FrameId::standard(0x120), 1, &[0x11u8, 0x22, 0x33][..]));
        // Remote and error frames are not samples.
        for l in ["(1.000000) can0 120#R", "(1.000000) can0 20000004#000C000000000000"] {
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

    /// Each way a CAN FD line can be wrong is said in the error.
    #[test]
    fn bad_fd_lines_say_what_is_wrong() {
        let full = "AB".repeat(64);
        let (_, _, f) = parse_line(&format!("(1.000000) can0 121##1{full}")).unwrap().unwrap();
        assert!(matches!(f, LoggedFrame::Fd { len: 64, flags: 0x5, .. }), "{f:?}");
        assert!(matches!(parse_line("(1.000000) can0 121##0").unwrap().unwrap().2, LoggedFrame::Fd { len: 0, .. }));
        for (line, why) in [
            ("(1.000000) can0 121##G00", "flags must be one hex digit"),
            ("(1.000000) can0 121##", "without its flags digit"),
            ("(1.000000) can0 121##1ABC", "odd number of hex digits (3)"),
            ("(1.000000) can0 121##1AZ", "not hex"),
            (&format!("(1.000000) can0 121##1{}", "00".repeat(9)), "9 bytes is not a CAN FD length"),
            (&format!("(1.000000) can0 121##1{}", "00".repeat(65)), "65 bytes is over 64"),
        ] {
            let e = parse_line(line).unwrap_err();
            assert!(e.contains(why), "{line}: {e}");
        }
        let mut w = Vec::new();
        write_candump_fd_line(&mut w, 1_500_000, "can0", FrameId::standard(0x121), 1, &[0xAB; 12]).unwrap();
        assert_eq!(String::from_utf8(w).unwrap(), format!("(0.001500) can0 121##1{}\n", "AB".repeat(12)));
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
