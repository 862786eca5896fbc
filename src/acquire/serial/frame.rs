//! The binary serial DAQ framing of docs/interfaces.md §7, sans-IO: `FrameDecoder` is fed byte
//! chunks of any size and hands back whole frames, resyncing after garbage at the next
//! `0x00` (a frame glued to garbage with no `0x00` between them is lost with it, as §7
//! says); `encode_frame` builds the wire bytes (the simulated device uses it). The
//! frames become samples in `tracker.rs`. No IO, no clock.
//!
//! ```text
//! wire:    COBS( payload || crc32c(payload) as u32 LE ) || 0x00
//! payload: u8 version = 1 | u8 channel_count 1..=16 | u16 sample_count 1..=4096
//!          | u32 sequence | u64 device_time_ns | u32 sample_period_ns
//!          | i32 counts[N][C] (interleaved), all little-endian
//! ```

use crc::{CRC_32_ISCSI, Crc, Table};

/// The only framing version (docs/interfaces.md §7).
pub const FRAME_VERSION: u8 = 1;
/// Channel count limits.
pub const MAX_CHANNELS: u8 = 16;
/// Sample count limit per frame.
pub const MAX_SAMPLES: u16 = 4096;
/// Payload header: version, channel_count, sample_count, sequence, device_time_ns,
/// sample_period_ns.
pub const HEADER_LEN: usize = 1 + 1 + 2 + 4 + 8 + 4;
/// The CRC-32C trailer.
pub const CRC_LEN: usize = 4;
/// The longest payload the limits allow: 16 channels × 4096 samples of i32.
pub const MAX_PAYLOAD_LEN: usize = HEADER_LEN + 4 * MAX_CHANNELS as usize * MAX_SAMPLES as usize;
/// The longest COBS-encoded frame (without its delimiter): anything longer is garbage.
pub const MAX_ENCODED_LEN: usize = cobs::max_encoding_length(MAX_PAYLOAD_LEN + CRC_LEN);

/// CRC-32C (Castagnoli), the iSCSI polynomial; slice-by-16 tables (16 KiB, built at compile time).
pub static CRC32C: Crc<u32, Table<16>> = Crc::<u32, Table<16>>::new(&CRC_32_ISCSI);

/// One decoded frame (docs/interfaces.md §7).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    pub channel_count: u8,
    pub sample_count: u16,
    /// +1 per frame, wrapping.
    pub sequence: u32,
    /// Time of the first sample, device clock, ns.
    pub device_time_ns: u64,
    pub sample_period_ns: u32,
    /// `sample_count × channel_count` counts, interleaved (sample 0 of every channel first).
    pub counts: Vec<i32>,
}

/// Why a segment between two delimiters was not a frame. Each is counted and dropped.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    #[error("invalid COBS encoding ({len} bytes)")]
    Cobs { len: usize },
    #[error("frame of {len} bytes is shorter than header and CRC ({min} bytes)")]
    TooShort { len: usize, min: usize },
    #[error("no delimiter within {len} bytes (longest frame is {max}): discarded as garbage")]
    TooLong { len: usize, max: usize },
    #[error("unknown framing version {version} (expected {FRAME_VERSION})")]
    BadVersion { version: u8 },
    #[error("channel_count {count} outside 1..={MAX_CHANNELS}")]
    BadChannelCount { count: u8 },
    #[error("sample_count {count} outside 1..={MAX_SAMPLES}")]
    BadSampleCount { count: u16 },
    #[error("payload of {actual} bytes, but its header announces {expected}")]
    BadLength { expected: usize, actual: usize },
    #[error("CRC-32C mismatch: frame says {expected:#010x}, payload gives {computed:#010x}")]
    BadCrc { expected: u32, computed: u32 },
}

impl FrameError {
    /// True for a CRC failure (counted as `crc_errors`), false for every other decode
    /// failure (counted as `decode_errors`).
    pub fn is_crc(&self) -> bool {
        matches!(self, FrameError::BadCrc { .. })
    }
}

/// What a `FrameDecoder` has seen since it was created.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DecoderStats {
    pub frames: u64,
    pub crc_errors: u64,
    pub decode_errors: u64,
    /// Bytes thrown away (garbage, bad frames, overlong runs).
    pub bytes_discarded: u64,
}

/// The wire bytes of `frame`, delimiter included. Panics only if the frame breaks the
/// limits it is built with (a programming error of the caller, never outside data).
pub fn encode_frame(frame: &Frame) -> Vec<u8> {
    let mut payload = Vec::with_capacity(HEADER_LEN + 4 * frame.counts.len() + CRC_LEN);
    payload.push(FRAME_VERSION);
    payload.push(frame.channel_count);
    payload.extend_from_slice(&frame.sample_count.to_le_bytes());
    payload.extend_from_slice(&frame.sequence.to_le_bytes());
    payload.extend_from_slice(&frame.device_time_ns.to_le_bytes());
    payload.extend_from_slice(&frame.sample_period_ns.to_le_bytes());
    for c in &frame.counts {
        payload.extend_from_slice(&c.to_le_bytes());
    }
    let crc = CRC32C.checksum(&payload);
    payload.extend_from_slice(&crc.to_le_bytes());
    let mut wire = vec![0u8; cobs::max_encoding_length(payload.len()) + 1];
    let n = cobs::encode(&payload, &mut wire);
    wire.truncate(n);
    wire.push(0x00);
    wire
}

/// Parse a COBS-decoded segment (payload || crc): structure first, then the CRC.
fn parse_decoded(bytes: &[u8]) -> Result<Frame, FrameError> {
    let min = HEADER_LEN + 4 + CRC_LEN;
    if bytes.len() < min {
        return Err(FrameError::TooShort { len: bytes.len(), min });
    }
    let version = bytes[0];
    if version != FRAME_VERSION {
        return Err(FrameError::BadVersion { version });
    }
    let channel_count = bytes[1];
    if channel_count == 0 || channel_count > MAX_CHANNELS {
        return Err(FrameError::BadChannelCount { count: channel_count });
    }
    let sample_count = u16::from_le_bytes([bytes[2], bytes[3]]);
    if sample_count == 0 || sample_count > MAX_SAMPLES {
        return Err(FrameError::BadSampleCount { count: sample_count });
    }
    let n_counts = channel_count as usize * sample_count as usize;
    let payload_len = HEADER_LEN + 4 * n_counts;
    if bytes.len() != payload_len + CRC_LEN {
        return Err(FrameError::BadLength { expected: payload_len + CRC_LEN, actual: bytes.len() });
    }
    let (payload, crc_bytes) = bytes.split_at(payload_len);
    let expected = u32::from_le_bytes([crc_bytes[0], crc_bytes[1], crc_bytes[2], crc_bytes[3]]);
    let computed = CRC32C.checksum(payload);
    if expected != computed {
        return Err(FrameError::BadCrc { expected, computed });
    }
    let le4 = |i: usize| [payload[i], payload[i + 1], payload[i + 2], payload[i + 3]];
    let sequence = u32::from_le_bytes(le4(4));
    let mut t = [0u8; 8];
    t.copy_from_slice(&payload[8..16]);
    let device_time_ns = u64::from_le_bytes(t);
    let sample_period_ns = u32::from_le_bytes(le4(16));
    let counts = payload[HEADER_LEN..].chunks_exact(4).map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    Ok(Frame { channel_count, sample_count, sequence, device_time_ns, sample_period_ns, counts })
}

/// Sans-IO decoder of the §7 byte stream. Feed it with [`push`](Self::push), then call
/// [`next_frame`](Self::next_frame) until it returns `None` ("need more bytes").
///
/// - Every `0x00` ends a segment; a segment that fails COBS, the limits, its length or its
///   CRC is returned as an error, counted, and decoding resumes after that `0x00`
///   (docs/interfaces.md §7). Garbage glued in front of a frame, with no `0x00` between them,
///   makes one failed segment with the frame: the frame is dropped with it, and the
///   tracker reports the sequence jump as a gap. The decoder does not search a failed
///   segment for a frame inside it.
/// - The buffer is bounded: a run of more than `MAX_ENCODED_LEN` bytes without a delimiter
///   is discarded (one decode error) and bytes are dropped until the next `0x00`.
#[derive(Debug, Default)]
pub struct FrameDecoder {
    buf: Vec<u8>,
    /// Start of the unconsumed bytes in `buf`.
    start: usize,
    /// Bytes of `buf[start..]` already known to hold no delimiter.
    scanned: usize,
    /// Dropping bytes until the next delimiter (after an overlong run).
    skipping: bool,
    scratch: Vec<u8>,
    stats: DecoderStats,
}

impl FrameDecoder {
    pub fn new() -> Self {
        FrameDecoder::default()
    }

    /// Append received bytes.
    pub fn push(&mut self, mut bytes: &[u8]) {
        if self.skipping {
            match bytes.iter().position(|b| *b == 0) {
                None => {
                    self.stats.bytes_discarded += bytes.len() as u64;
                    return;
                }
                Some(i) => {
                    self.stats.bytes_discarded += i as u64 + 1;
                    self.skipping = false;
                    bytes = &bytes[i + 1..];
                }
            }
        }
        if self.start > 0 {
            self.buf.drain(..self.start);
            self.start = 0;
        }
        self.buf.extend_from_slice(bytes);
    }

    /// Forget any partial frame (the link was closed and reopened).
    pub fn reset(&mut self) {
        self.stats.bytes_discarded += (self.buf.len() - self.start) as u64;
        self.buf.clear();
        self.start = 0;
        self.scanned = 0;
        self.skipping = false;
    }

    pub fn stats(&self) -> DecoderStats {
        self.stats
    }

    /// Bytes held waiting for a delimiter.
    pub fn buffered(&self) -> usize {
        self.buf.len() - self.start
    }

    /// The next frame, or the next dropped segment's error, or `None` when more bytes are
    /// needed.
    pub fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        loop {
            let rest = &self.buf[self.start + self.scanned..];
            let Some(i) = rest.iter().position(|b| *b == 0) else {
                self.scanned = self.buf.len() - self.start;
                if self.scanned > MAX_ENCODED_LEN {
                    let len = self.scanned;
                    self.stats.bytes_discarded += len as u64;
                    self.stats.decode_errors += 1;
                    self.buf.clear();
                    self.start = 0;
                    self.scanned = 0;
                    self.skipping = true;
                    return Some(Err(FrameError::TooLong { len, max: MAX_ENCODED_LEN }));
                }
                return None;
            };
            let seg_start = self.start;
            let seg_end = self.start + self.scanned + i;
            self.start = seg_end + 1;
            self.scanned = 0;
            if seg_end == seg_start {
                // Back-to-back delimiters (an idle line, a leading 0x00): nothing to decode.
                continue;
            }
            let result = self.decode_segment(seg_start, seg_end);
            if self.start >= self.buf.len() {
                self.buf.clear();
                self.start = 0;
            }
            return Some(result);
        }
    }

    fn decode_segment(&mut self, seg_start: usize, seg_end: usize) -> Result<Frame, FrameError> {
        let len = seg_end - seg_start;
        if len > MAX_ENCODED_LEN {
            self.stats.decode_errors += 1;
            self.stats.bytes_discarded += len as u64 + 1;
            return Err(FrameError::TooLong { len, max: MAX_ENCODED_LEN });
        }
        match decode_cobs(&self.buf[seg_start..seg_end], &mut self.scratch) {
            Ok(()) => match parse_decoded(&self.scratch) {
                Ok(frame) => {
                    self.stats.frames += 1;
                    Ok(frame)
                }
                Err(e) => self.failed(seg_start, seg_end, e),
            },
            Err(e) => self.failed(seg_start, seg_end, e),
        }
    }

    /// A segment failed: count it and drop it with its delimiter.
    fn failed(&mut self, seg_start: usize, seg_end: usize, err: FrameError) -> Result<Frame, FrameError> {
        if err.is_crc() {
            self.stats.crc_errors += 1;
        } else {
            self.stats.decode_errors += 1;
        }
        self.stats.bytes_discarded += (seg_end - seg_start) as u64 + 1;
        Err(err)
    }
}

/// COBS-decode `src` (no delimiter inside) into `dest`.
fn decode_cobs(src: &[u8], dest: &mut Vec<u8>) -> Result<(), FrameError> {
    dest.clear();
    dest.resize(src.len(), 0);
    match cobs::decode(src, dest) {
        Ok(report) => {
            dest.truncate(report.frame_size());
            Ok(())
        }
        Err(_) => Err(FrameError::Cobs { len: src.len() }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The hand-built frame below: 2 channels, 2 samples, sequence 5, t = 1000 ns,
    /// period 10 µs, counts [[1, -1], [256, 2]].
    fn small_frame() -> Frame {
        Frame {
            channel_count: 2,
            sample_count: 2,
            sequence: 5,
            device_time_ns: 1000,
            sample_period_ns: 10_000,
            counts: vec![1, -1, 256, 2],
        }
    }

    /// `small_frame()` on the wire, built by hand. The payload is
    /// `01 02 0200 05000000 E803000000000000 10270000 01000000 FFFFFFFF 00010000 02000000`
    /// followed by its CRC-32C 0xA5152FE3 (LE `E3 2F 15 A5`); COBS replaces each zero by
    /// the distance to the next one.
    #[rustfmt::skip]
    const SMALL_WIRE: [u8; 42] = [
        0x04,                   // COBS code 4: 3 bytes, then a zero (sample_count high byte)
        0x01,                   //   version = 1
        0x02,                   //   channel_count = 2
        0x02,                   //   sample_count low byte = 2
        0x02,                   // COBS code 2: 1 byte, then a zero (sequence byte 1)
        0x05,                   //   sequence low byte = 5
        0x01,                   // COBS code 1: a zero (sequence byte 2)
        0x01,                   // COBS code 1: a zero (sequence byte 3)
        0x03,                   // COBS code 3: 2 bytes, then a zero (device_time_ns byte 2)
        0xE8, 0x03,             //   device_time_ns = 1000 = 0x03E8, bytes 0..=1
        0x01, 0x01, 0x01,       // COBS codes 1: zeros (device_time_ns bytes 3..=5)
        0x01, 0x01,             // COBS codes 1: zeros (device_time_ns bytes 6..=7)
        0x03,                   // COBS code 3: 2 bytes, then a zero (sample_period_ns byte 2)
        0x10, 0x27,             //   sample_period_ns = 10000 = 0x2710, bytes 0..=1
        0x01,                   // COBS code 1: a zero (sample_period_ns byte 3)
        0x02,                   // COBS code 2: 1 byte, then a zero (counts[0][0] byte 1)
        0x01,                   //   counts[0][0] = 1, byte 0
        0x01, 0x01,             // COBS codes 1: zeros (counts[0][0] bytes 2..=3)
        0x05,                   // COBS code 5: 4 bytes, then a zero (counts[1][0] byte 0)
        0xFF, 0xFF, 0xFF, 0xFF, //   counts[0][1] = -1
        0x02,                   // COBS code 2: 1 byte, then a zero (counts[1][0] byte 2)
        0x01,                   //   counts[1][0] = 256 = 0x100, byte 1
        0x01,                   // COBS code 1: a zero (counts[1][0] byte 3)
        0x02,                   // COBS code 2: 1 byte, then a zero (counts[1][1] byte 1)
        0x02,                   //   counts[1][1] = 2, byte 0
        0x01, 0x01,             // COBS codes 1: zeros (counts[1][1] bytes 2..=3)
        0x05,                   // COBS code 5: 4 bytes, and the end of the data
        0xE3, 0x2F, 0x15, 0xA5, //   CRC-32C of the payload = 0xA5152FE3, LE
        0x00,                   // delimiter
    ];

    fn decode_all(dec: &mut FrameDecoder) -> Vec<Result<Frame, FrameError>> {
        std::iter::from_fn(|| dec.next_frame()).collect()
    }

    fn big_frame(seq: u32) -> Frame {
        let counts = (0..300).map(|k| (k * 7919 - 100_000) * if k % 2 == 0 { 1 } else { -1 }).collect();
        Frame {
            channel_count: 3,
            sample_count: 100,
            sequence: seq,
            device_time_ns: 1_000_000 * seq as u64,
            sample_period_ns: 10_000,
            counts,
        }
    }

    #[test]
    fn crc32c_is_castagnoli() {
        // The standard check value of CRC-32C over "123456789".
        assert_eq!(CRC32C.checksum(b"123456789"), 0xE306_9283);
    }

    #[test]
    fn the_hand_built_frame_matches_the_encoder_and_decodes() {
        assert_eq!(encode_frame(&small_frame()), SMALL_WIRE.to_vec());
        let mut dec = FrameDecoder::new();
        dec.push(&SMALL_WIRE);
        assert_eq!(decode_all(&mut dec), vec![Ok(small_frame())]);
        assert_eq!(dec.stats(), DecoderStats { frames: 1, ..DecoderStats::default() });
        assert_eq!(dec.buffered(), 0);
    }

    #[test]
    fn round_trip_of_many_frames_fed_one_byte_at_a_time() {
        let frames: Vec<Frame> = (0..5).map(big_frame).collect();
        let wire: Vec<u8> = frames.iter().flat_map(encode_frame).collect();
        let mut dec = FrameDecoder::new();
        let mut got = Vec::new();
        for b in &wire {
            dec.push(std::slice::from_ref(b));
            while let Some(r) = dec.next_frame() {
                got.push(r.unwrap());
            }
        }
        assert_eq!(got, frames);
        assert_eq!(dec.stats().frames, 5);
    }

    #[test]
    fn partial_input_needs_more_and_empty_input_is_nothing() {
        let mut dec = FrameDecoder::new();
        dec.push(&[]);
        assert_eq!(dec.next_frame(), None);
        dec.push(&SMALL_WIRE[..41]); // everything but the delimiter
        assert_eq!(dec.next_frame(), None);
        dec.push(&[]);
        assert_eq!(dec.next_frame(), None);
        dec.push(&SMALL_WIRE[41..]); // the delimiter
        assert_eq!(dec.next_frame(), Some(Ok(small_frame())));
        assert_eq!(dec.next_frame(), None);
        // Lone delimiters (an idle line) are not errors.
        dec.push(&[0x00, 0x00, 0x00]);
        assert_eq!(dec.next_frame(), None);
        assert_eq!(dec.stats().decode_errors, 0);
    }

    #[test]
    fn garbage_ended_by_a_delimiter_is_counted_and_the_next_frame_decodes() {
        let mut dec = FrameDecoder::new();
        dec.push(&[0x13, 0x37, 0x42, 0x00]); // line noise, then a delimiter
        dec.push(&SMALL_WIRE);
        let got = decode_all(&mut dec);
        assert_eq!(got.len(), 2);
        assert!(got[0].is_err());
        assert_eq!(got[1], Ok(small_frame()));
        assert_eq!(dec.stats().decode_errors, 1);
        assert_eq!(dec.stats().crc_errors, 0);
    }

    /// docs/interfaces.md §7: a segment that fails to decode is dropped and decoding resumes
    /// after the next `0x00`, so a frame glued to garbage (no `0x00` between them) is lost
    /// with it; the frame after the next delimiter decodes.
    #[test]
    fn a_frame_glued_to_garbage_is_lost_with_it_and_decoding_resumes_at_the_next_delimiter() {
        let mut wire = encode_frame(&big_frame(1));
        let noise = [0xAA, 0x03, 0x55, 0x10, 0xFE, 0x07, 0x99];
        wire.extend_from_slice(&noise);
        let glued = encode_frame(&big_frame(2));
        wire.extend(&glued);
        wire.extend([0x31, 0x32, 0x33, 0x00]); // noise ended by a delimiter
        wire.extend(encode_frame(&big_frame(3)));
        let mut dec = FrameDecoder::new();
        dec.push(&wire);
        let got = decode_all(&mut dec);
        let frames: Vec<u32> = got.iter().filter_map(|r| r.as_ref().ok()).map(|f| f.sequence).collect();
        assert_eq!(frames, vec![1, 3]);
        assert_eq!(got.iter().filter(|r| r.is_err()).count(), 2);
        assert_eq!((dec.stats().frames, dec.stats().decode_errors, dec.stats().crc_errors), (2, 2, 0));
        // Noise and frame 2 with its delimiter, then the delimited noise.
        assert_eq!(dec.stats().bytes_discarded, (noise.len() + glued.len() + 4) as u64);
    }

    #[test]
    fn a_corrupt_crc_is_counted_and_the_next_frame_still_decodes() {
        let mut bad = SMALL_WIRE;
        bad[37] ^= 0x01; // flip a bit of the CRC's first byte (0xE3 -> 0xE2)
        let mut dec = FrameDecoder::new();
        dec.push(&bad);
        dec.push(&SMALL_WIRE);
        let got = decode_all(&mut dec);
        assert_eq!(got.len(), 2);
        match &got[0] {
            Err(FrameError::BadCrc { expected, computed }) => {
                assert_eq!(*expected, 0xA515_2FE2);
                assert_eq!(*computed, 0xA515_2FE3);
            }
            other => panic!("expected a CRC error, got {other:?}"),
        }
        assert_eq!(got[1], Ok(small_frame()));
        // A flipped sample bit is a CRC error too.
        let mut wire = encode_frame(&big_frame(9));
        wire[200] ^= 0x40;
        dec.push(&wire);
        assert!(matches!(dec.next_frame(), Some(Err(FrameError::BadCrc { .. }))));
        assert_eq!(dec.stats().crc_errors, 2);
        assert_eq!(dec.stats().decode_errors, 0);
        assert_eq!(dec.stats().frames, 1);
    }

    /// The wire bytes of a payload given as is (limits not checked), with a correct CRC.
    fn raw_wire(payload: &[u8]) -> Vec<u8> {
        let mut p = payload.to_vec();
        p.extend_from_slice(&CRC32C.checksum(payload).to_le_bytes());
        let mut wire = cobs::encode_vec(&p);
        wire.push(0);
        wire
    }

    fn header(version: u8, channels: u8, samples: u16) -> Vec<u8> {
        let mut p = vec![version, channels];
        p.extend_from_slice(&samples.to_le_bytes());
        p.extend_from_slice(&[0; 16]); // sequence, time, period
        p
    }

    #[test]
    fn limits_violated_are_decode_errors() {
        let cases: Vec<(Vec<u8>, FrameError)> = vec![
            // channel_count 0, one (ignored) count
            ([header(1, 0, 1), vec![0; 4]].concat(), FrameError::BadChannelCount { count: 0 }),
            // channel_count 17
            ([header(1, 17, 1), vec![0; 68]].concat(), FrameError::BadChannelCount { count: 17 }),
            // sample_count 0
            ([header(1, 1, 0), vec![0; 4]].concat(), FrameError::BadSampleCount { count: 0 }),
            // sample_count 4097
            ([header(1, 1, 4097), vec![0; 4]].concat(), FrameError::BadSampleCount { count: 4097 }),
            // version 2
            ([header(2, 1, 1), vec![0; 4]].concat(), FrameError::BadVersion { version: 2 }),
            // 1 channel × 2 samples announced, 1 sample sent
            ([header(1, 1, 2), vec![0; 4]].concat(), FrameError::BadLength { expected: 32, actual: 28 }),
            // header cut short
            (vec![1, 1, 1, 0], FrameError::TooShort { len: 8, min: 28 }),
        ];
        let mut dec = FrameDecoder::new();
        for (payload, want) in &cases {
            dec.push(&raw_wire(payload));
            assert_eq!(dec.next_frame(), Some(Err(want.clone())), "{payload:02X?}");
        }
        assert_eq!(dec.stats().decode_errors, cases.len() as u64);
        assert_eq!(dec.stats().crc_errors, 0);
        // The limits themselves decode: 16 channels × 1 sample, 1 channel × 4096 samples.
        for (c, n) in [(16u8, 1u16), (1, 4096)] {
            let f = Frame {
                channel_count: c,
                sample_count: n,
                sequence: 0,
                device_time_ns: 0,
                sample_period_ns: 1,
                counts: vec![-7; c as usize * n as usize],
            };
            dec.push(&encode_frame(&f));
            assert_eq!(dec.next_frame(), Some(Ok(f)));
        }
    }

    #[test]
    fn an_overlong_run_without_delimiter_is_dropped_and_the_buffer_stays_bounded() {
        let mut dec = FrameDecoder::new();
        let noise = vec![0x5Au8; 64 * 1024];
        let mut errors = 0;
        for _ in 0..8 {
            dec.push(&noise);
            while let Some(r) = dec.next_frame() {
                assert!(matches!(r, Err(FrameError::TooLong { .. })));
                errors += 1;
            }
            assert!(dec.buffered() <= MAX_ENCODED_LEN + noise.len());
        }
        assert_eq!(errors, 1);
        // The delimiter ends the garbage; the next frame decodes.
        dec.push(&[0x00]);
        dec.push(&SMALL_WIRE);
        assert_eq!(decode_all(&mut dec), vec![Ok(small_frame())]);
        assert_eq!(dec.stats().decode_errors, 1);
    }
}
