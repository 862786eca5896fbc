//! The binary serial DAQ framing of CONTRACTS.md §7, sans-IO: `FrameDecoder` is fed byte
//! chunks of any size and hands back whole frames, resyncing after garbage at the next
//! `0x00`; `encode_frame` builds the wire bytes (the simulated device uses it); and
//! `FrameTracker` turns frames into `SampleBatch`es in physical units, reporting a jump in
//! the sequence number as a `Gap`. No IO, no clock.
//!
//! ```text
//! wire:    COBS( payload || crc32c(payload) as u32 LE ) || 0x00
//! payload: u8 version = 1 | u8 channel_count 1..=16 | u16 sample_count 1..=4096
//!          | u32 sequence | u64 device_time_ns | u32 sample_period_ns
//!          | i32 counts[N][C] (interleaved), all little-endian
//! ```

use crc::{CRC_32_ISCSI, Crc};

use crate::acquire::ChannelSpec;
use crate::record::Gap;
use crate::signal::sample::SampleBatch;

/// The only framing version (CONTRACTS.md §7).
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

/// CRC-32C (Castagnoli), the iSCSI polynomial.
pub const CRC32C: Crc<u32> = Crc::<u32>::new(&CRC_32_ISCSI);

/// How many bytes of a failed segment the decoder searches for a frame that follows
/// garbage (a frame whose start was glued to line noise). Bounded so a long burst of
/// garbage costs a bounded amount of work.
pub const RESYNC_SEARCH_BYTES: usize = 4096;

/// One decoded frame (CONTRACTS.md §7).
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
    #[error("{len} bytes of garbage in front of a frame")]
    Garbage { len: usize },
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
///   CRC is returned as an error, counted, and decoding resumes after that `0x00`.
/// - Garbage glued in front of a valid frame (no delimiter between them) is cut off: the
///   last `RESYNC_SEARCH_BYTES` of a failed segment are searched for a valid frame that
///   ends it; the garbage counts as one decode error and the frame is still delivered.
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
    /// A frame found behind garbage, returned on the next call.
    pending: Option<Frame>,
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
        self.pending = None;
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
        if let Some(frame) = self.pending.take() {
            self.stats.frames += 1;
            return Some(Ok(frame));
        }
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

    /// A segment failed: look for a valid frame at its end (garbage glued in front of a
    /// frame); otherwise count the failure.
    fn failed(&mut self, seg_start: usize, seg_end: usize, err: FrameError) -> Result<Frame, FrameError> {
        let from = seg_start + 1;
        let search_from = from.max(seg_end.saturating_sub(RESYNC_SEARCH_BYTES));
        let seg = &self.buf[..seg_end];
        // valid[p]: the COBS code chain starting at p lands exactly on seg_end.
        let mut valid = vec![false; seg_end - search_from];
        for p in (search_from..seg_end).rev() {
            let next = p + seg[p] as usize;
            valid[p - search_from] = next == seg_end || (next < seg_end && valid[next - search_from]);
        }
        for p in search_from..seg_end {
            if !valid[p - search_from] || seg_end - p < HEADER_LEN + CRC_LEN {
                continue;
            }
            if decode_cobs(&seg[p..seg_end], &mut self.scratch).is_ok()
                && let Ok(frame) = parse_decoded(&self.scratch)
            {
                // The garbage in front is the error; the frame comes on the next call.
                self.stats.decode_errors += 1;
                self.stats.bytes_discarded += (p - seg_start) as u64;
                self.pending = Some(frame);
                return Err(FrameError::Garbage { len: p - seg_start });
            }
        }
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

/// Why a well-formed frame could not become samples.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TrackError {
    #[error("frame has {got} channels, the config gives {expected}")]
    ChannelMismatch { expected: usize, got: u8 },
    #[error("frame has sample_period_ns 0")]
    ZeroPeriod,
}

/// A frame turned into samples, with the gap its sequence number reveals.
#[derive(Debug, Clone, PartialEq)]
pub struct Tracked {
    /// Samples lost before this batch (a sequence jump), if any.
    pub gap: Option<Gap>,
    pub batch: SampleBatch,
}

/// Turns frames into `SampleBatch`es with the configured channels (`offset + gain * count`)
/// and watches the sequence: a jump of `j` (wrapping u32) loses `(j − 1) × N` samples
/// (CONTRACTS.md §7). A backwards jump (more than 2³¹ ahead) is a device restart: no gap,
/// the count starts over.
#[derive(Debug, Clone)]
pub struct FrameTracker {
    source: String,
    channels: Vec<ChannelSpec>,
    last_seq: Option<u32>,
    /// The unwrapped sequence of the last frame (`SampleBatch::seq`).
    seq: u64,
    /// Device time just after the last frame's last sample, ns.
    next_device_ns: u64,
    restarts: u64,
}

impl FrameTracker {
    pub fn new(source: impl Into<String>, channels: Vec<ChannelSpec>) -> Self {
        FrameTracker { source: source.into(), channels, last_seq: None, seq: 0, next_device_ns: 0, restarts: 0 }
    }

    /// How often the sequence went backwards (device restarts).
    pub fn restarts(&self) -> u64 {
        self.restarts
    }

    /// The samples of `frame`, received at host time `host_time_ns`.
    pub fn track(&mut self, frame: &Frame, host_time_ns: i64) -> Result<Tracked, TrackError> {
        if frame.channel_count as usize != self.channels.len() {
            return Err(TrackError::ChannelMismatch { expected: self.channels.len(), got: frame.channel_count });
        }
        if frame.sample_period_ns == 0 {
            return Err(TrackError::ZeroPeriod);
        }
        let mut gap = None;
        match self.last_seq {
            None => self.seq = frame.sequence as u64,
            Some(last) => {
                let jump = frame.sequence.wrapping_sub(last);
                if jump == 0 || jump > u32::MAX / 2 {
                    // Repeated or backwards: the device restarted its count.
                    self.restarts += 1;
                    self.seq += 1;
                } else {
                    self.seq += jump as u64;
                    if jump > 1 {
                        gap = Some(Gap {
                            source: self.source.clone(),
                            t_s: self.next_device_ns as f64 * 1e-9,
                            samples_lost: (jump as u64 - 1) * frame.sample_count as u64,
                            reason: "sequence_jump".to_string(),
                        });
                    }
                }
            }
        }
        self.last_seq = Some(frame.sequence);
        self.next_device_ns =
            frame.device_time_ns.saturating_add(frame.sample_period_ns as u64 * frame.sample_count as u64);
        let c = self.channels.len();
        let mut values = Vec::with_capacity(frame.counts.len());
        for (k, count) in frame.counts.iter().enumerate() {
            values.push(self.channels[k % c].physical(*count as f64));
        }
        let batch = SampleBatch {
            source: self.source.clone(),
            seq: self.seq,
            device_time_ns: i64::try_from(frame.device_time_ns).unwrap_or(i64::MAX),
            host_time_ns,
            period_ns: frame.sample_period_ns as f64,
            roles: self.channels.iter().map(|ch| ch.role).collect(),
            values,
        };
        Ok(Tracked { gap, batch })
    }
}
