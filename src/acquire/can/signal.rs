//! CAN signals: where a value sits in a frame's payload (start bit, length, Intel or
//! Motorola byte order, signedness) and how its raw integer becomes a physical value
//! (`offset + factor * raw`, the DBC convention). [`CanMapping`] is the validated set of
//! signals one source reads. Pure code: bits in, numbers out, and the inverse for the
//! simulated device.

use crate::acquire::ChannelSpec;
use crate::signal::sample::Role;

use super::CanError;

/// The payload of a classic CAN data frame, bytes.
pub const CLASSIC_MAX_LEN: usize = 8;
/// The payload of a CAN FD frame, bytes (ISO 11898-1:2015).
pub const FD_MAX_LEN: usize = 64;
/// The payload lengths a CAN FD frame can have (its DLC codes 0..=15).
pub const FD_LENGTHS: [usize; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

/// The shortest valid CAN FD payload holding `n` bytes, or None above 64.
pub fn fd_len_for(n: usize) -> Option<usize> {
    FD_LENGTHS.iter().copied().find(|&l| l >= n)
}

/// Bit order of a signal (DBC `@1` / `@0`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ByteOrder {
    /// Intel, DBC `@1`: `start_bit` is the least significant bit; bit `b` of the payload
    /// is bit `b % 8` of byte `b / 8`.
    LittleEndian,
    /// Motorola, DBC `@0`: `start_bit` is the most significant bit, numbered as for
    /// Intel, and the signal continues into the next byte's bit 7.
    BigEndian,
}

/// A CAN identifier as candump and DBC files write it: 11-bit standard or 29-bit extended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct FrameId {
    pub id: u32,
    pub extended: bool,
}

impl FrameId {
    pub const fn standard(id: u16) -> FrameId {
        FrameId { id: id as u32, extended: false }
    }

    pub const fn extended(id: u32) -> FrameId {
        FrameId { id, extended: true }
    }

    /// Whether the identifier fits its width (11 or 29 bits).
    pub fn is_valid(&self) -> bool {
        if self.extended { self.id <= 0x1FFF_FFFF } else { self.id <= 0x7FF }
    }
}

impl std::fmt::Display for FrameId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.extended { write!(f, "{:08X}", self.id) } else { write!(f, "{:03X}", self.id) }
    }
}

/// The layout and scaling of one signal, without a role (the sequence counter has none).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalLayout {
    pub frame: FrameId,
    pub start_bit: u16,
    /// Bits, 1..=64.
    pub length: u16,
    pub byte_order: ByteOrder,
    pub signed: bool,
    /// Physical value = `offset + factor * raw`.
    pub factor: f64,
    pub offset: f64,
}

/// One measured channel on the bus: a role and where its value sits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CanSignalSpec {
    pub role: Role,
    pub layout: SignalLayout,
}

impl CanSignalSpec {
    /// The common channel description (`offset + gain * raw`) of `acquire`.
    pub fn channel(&self) -> ChannelSpec {
        ChannelSpec { role: self.role, gain: self.layout.factor, offset: self.layout.offset }
    }
}

impl SignalLayout {
    /// The payload bits the signal occupies, numbered Intel-style (byte * 8 + bit), LSB
    /// first for Intel and MSB first for Motorola, or None when it runs off 64 bytes.
    fn bit_positions(&self) -> Option<Vec<u16>> {
        let mut out = Vec::with_capacity(self.length as usize);
        match self.byte_order {
            ByteOrder::LittleEndian => {
                for i in 0..self.length {
                    out.push(self.start_bit.checked_add(i)?);
                }
            }
            ByteOrder::BigEndian => {
                // From the MSB down: within a byte bit 7..0, then the next byte's bit 7.
                let mut pos = self.start_bit;
                for i in 0..self.length {
                    out.push(pos);
                    if i + 1 < self.length {
                        pos = if pos.is_multiple_of(8) { pos.checked_add(15)? } else { pos - 1 };
                    }
                }
            }
        }
        if out.iter().any(|&p| p >= 512) { None } else { Some(out) }
    }

    /// Payload bytes needed to hold the signal.
    pub fn bytes_needed(&self) -> usize {
        self.bit_positions().map_or(usize::MAX, |p| p.iter().map(|&b| b as usize / 8 + 1).max().unwrap_or(0))
    }

    /// Check the layout once, when the mapping is built; `what` names it in the error.
    /// It must fit a classic 8-byte payload.
    pub fn validate(&self, what: &str) -> Result<(), CanError> {
        self.validate_within(what, CLASSIC_MAX_LEN)
    }

    /// As [`validate`](Self::validate), for a payload of `max_len` bytes (64 for CAN FD).
    pub fn validate_within(&self, what: &str, max_len: usize) -> Result<(), CanError> {
        let bad = |why: String| Err(CanError::BadSignal { signal: what.to_string(), why });
        if !self.frame.is_valid() {
            return bad(format!("identifier {} does not fit its width", self.frame));
        }
        if self.length == 0 || self.length > 64 {
            return bad(format!("length {} bits is not 1..=64", self.length));
        }
        if self.bytes_needed() > max_len {
            return bad(if max_len == CLASSIC_MAX_LEN {
                "does not fit an 8-byte classic CAN payload".to_string()
            } else {
                format!("does not fit a {max_len}-byte CAN FD payload")
            });
        }
        if !(self.factor.is_finite() && self.factor != 0.0 && self.offset.is_finite()) {
            return bad(format!("factor {} / offset {} must be finite, factor non-zero", self.factor, self.offset));
        }
        Ok(())
    }

    /// The raw integer in `data`, sign-extended when signed, or None when the payload is
    /// too short. Call on a validated layout.
    pub fn extract_raw(&self, data: &[u8]) -> Option<i64> {
        let n = self.length as u32;
        let mut value: u64 = 0;
        match self.byte_order {
            ByteOrder::LittleEndian => {
                for i in (0..self.length).rev() {
                    let pos = self.start_bit as usize + i as usize;
                    let bit = (*data.get(pos / 8)? >> (pos % 8)) & 1;
                    value = (value << 1) | bit as u64;
                }
            }
            ByteOrder::BigEndian => {
                let mut pos = self.start_bit as usize;
                for i in 0..self.length {
                    let bit = (*data.get(pos / 8)? >> (pos % 8)) & 1;
                    value = (value << 1) | bit as u64;
                    if i + 1 < self.length {
                        pos = if pos.is_multiple_of(8) { pos + 15 } else { pos - 1 };
                    }
                }
            }
        }
        if self.signed && n < 64 && value >> (n - 1) & 1 == 1 {
            value |= !0u64 << n;
        }
        Some(if self.signed { value as i64 } else { value.min(i64::MAX as u64) as i64 })
    }

    /// The physical value in `data`, or None when the payload is too short.
    pub fn extract(&self, data: &[u8]) -> Option<f64> {
        self.extract_raw(data).map(|raw| self.offset + self.factor * raw as f64)
    }

    /// Smallest and largest raw value.
    pub fn raw_range(&self) -> (i64, i64) {
        let n = self.length as u32;
        match (self.signed, n) {
            (true, 64) => (i64::MIN, i64::MAX),
            (true, _) => (-(1i64 << (n - 1)), (1i64 << (n - 1)) - 1),
            (false, 64) | (false, 63) => (0, i64::MAX),
            (false, _) => (0, (1i64 << n) - 1),
        }
    }

    /// Write the raw value of `physical` into `data` (the simulated device's side),
    /// rounded and saturated to the signal's range. Returns true when it saturated.
    pub fn insert(&self, physical: f64, data: &mut [u8]) -> bool {
        let (lo, hi) = self.raw_range();
        let x = ((physical - self.offset) / self.factor).round();
        let raw = if x.is_nan() { 0 } else { (x.max(lo as f64).min(hi as f64)) as i64 };
        let saturated = x < lo as f64 || x > hi as f64 || x.is_nan();
        self.insert_raw(raw, data);
        saturated
    }

    /// Write `raw` (truncated to the signal's width) into `data`.
    pub fn insert_raw(&self, raw: i64, data: &mut [u8]) {
        let Some(positions) = self.bit_positions() else { return };
        // positions run LSB-first for Intel, MSB-first for Motorola.
        let n = positions.len();
        for (i, &pos) in positions.iter().enumerate() {
            let k = match self.byte_order {
                ByteOrder::LittleEndian => i,
                ByteOrder::BigEndian => n - 1 - i,
            };
            let bit = ((raw as u64) >> k) & 1;
            if let Some(byte) = data.get_mut(pos as usize / 8) {
                let mask = 1u8 << (pos % 8);
                if bit == 1 { *byte |= mask } else { *byte &= !mask }
            }
        }
    }
}

/// The signals one CAN source reads, validated: at most one signal per role, an optional
/// sequence counter, and the *sample message*: the frame whose arrival completes a sample
/// (the sequence counter's frame, or else the first signal's). Values carried by other
/// frames are held until the next sample (sample-and-hold).
///
/// A *block* mapping carries several samples per sample frame: slot `k` holds sample `k`
/// of the block, every slot the same roles, all in the sample frame. Its counter counts
/// samples (the index of the block's first sample), so it advances by the block's length
/// from one frame to the next. A classic mapping is a block of one.
#[derive(Debug, Clone, PartialEq)]
pub struct CanMapping {
    signals: Vec<CanSignalSpec>,
    /// Slot `k`'s layouts, in the order of `signals`; slot 0 is `signals`' own.
    slots: Vec<Vec<SignalLayout>>,
    sequence: Option<SignalLayout>,
    sample_frame: FrameId,
    fd: bool,
}

impl CanMapping {
    /// Validate the signals: at least one, one per role, each fitting 8 bytes; the
    /// sequence counter, if any, unsigned. The roles are kept in `Role::ALL` order.
    pub fn new(signals: Vec<CanSignalSpec>, sequence: Option<SignalLayout>) -> Result<CanMapping, CanError> {
        CanMapping::block(vec![signals], sequence, false)
    }

    /// A mapping of `slots.len()` samples per sample frame (see the type's docs), read
    /// from CAN FD frames (64-byte payloads) when `fd`, else from classic ones.
    pub fn block(
        mut slots: Vec<Vec<CanSignalSpec>>,
        sequence: Option<SignalLayout>,
        fd: bool,
    ) -> Result<CanMapping, CanError> {
        let max_len = if fd { FD_MAX_LEN } else { CLASSIC_MAX_LEN };
        if slots.is_empty() || slots.iter().any(Vec::is_empty) {
            return Err(CanError::BadSignal { signal: "signals".into(), why: "no signal is mapped".into() });
        }
        for (k, signals) in slots.iter_mut().enumerate() {
            for s in signals.iter() {
                let what =
                    if k == 0 { s.role.column().to_string() } else { format!("{} (sample {k})", s.role.column()) };
                s.layout.validate_within(&what, max_len)?;
                if signals.iter().filter(|o| o.role == s.role).count() > 1 {
                    return Err(CanError::BadSignal { signal: what, why: "role mapped twice".into() });
                }
            }
            signals.sort_by_key(|s| s.role);
        }
        if let Some(seq) = &sequence {
            seq.validate_within("sequence", max_len)?;
            if seq.signed || seq.length > 32 {
                return Err(CanError::BadSignal {
                    signal: "sequence".into(),
                    why: "a sequence counter is unsigned and at most 32 bits".into(),
                });
            }
        }
        let signals = slots[0].clone();
        let sample_frame = sequence.map(|s| s.frame).unwrap_or(signals[0].layout.frame);
        if slots.len() > 1 {
            let roles: Vec<Role> = signals.iter().map(|s| s.role).collect();
            for (k, slot) in slots.iter().enumerate() {
                if slot.iter().map(|s| s.role).collect::<Vec<_>>() != roles {
                    return Err(CanError::BadSignal {
                        signal: format!("sample {k}"),
                        why: "every sample of a block carries the same roles".into(),
                    });
                }
                if let Some(s) = slot.iter().find(|s| s.layout.frame != sample_frame) {
                    return Err(CanError::BadSignal {
                        signal: format!("{} (sample {k})", s.role.column()),
                        why: format!("a block's samples all sit in the sample frame {sample_frame}"),
                    });
                }
            }
        }
        let slots = slots.into_iter().map(|slot| slot.into_iter().map(|s| s.layout).collect()).collect();
        Ok(CanMapping { signals, slots, sequence, sample_frame, fd })
    }

    /// The signals of the first sample of a frame (the only one of a classic mapping).
    pub fn signals(&self) -> &[CanSignalSpec] {
        &self.signals
    }

    /// Slot `k`'s layouts, in the order of [`signals`](Self::signals).
    pub fn slot(&self, k: usize) -> &[SignalLayout] {
        &self.slots[k]
    }

    /// Samples per sample frame (1 for a classic mapping).
    pub fn samples_per_frame(&self) -> usize {
        self.slots.len()
    }

    /// Whether the frames are CAN FD frames (`##` in candump, up to 64 bytes).
    pub fn is_fd(&self) -> bool {
        self.fd
    }

    pub fn sequence(&self) -> Option<&SignalLayout> {
        self.sequence.as_ref()
    }

    /// The frame whose arrival completes a sample.
    pub fn sample_frame(&self) -> FrameId {
        self.sample_frame
    }

    pub fn roles(&self) -> Vec<Role> {
        self.signals.iter().map(|s| s.role).collect()
    }

    /// Whether any signal or the counter lives in `frame`.
    pub fn reads(&self, frame: FrameId) -> bool {
        frame == self.sample_frame || self.signals.iter().any(|s| s.layout.frame == frame)
    }

    /// The frames this mapping reads, each with the payload length it needs.
    pub fn frames(&self) -> Vec<(FrameId, usize)> {
        let mut out: Vec<(FrameId, usize)> = Vec::new();
        let layouts = self.slots.iter().flatten().chain(self.sequence.iter());
        for l in layouts {
            match out.iter_mut().find(|(f, _)| *f == l.frame) {
                Some((_, n)) => *n = (*n).max(l.bytes_needed()),
                None => out.push((l.frame, l.bytes_needed())),
            }
        }
        out.sort();
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout(start_bit: u16, length: u16, byte_order: ByteOrder, signed: bool) -> SignalLayout {
        SignalLayout {
            frame: FrameId::standard(0x120),
            start_bit,
            length,
            byte_order,
            signed,
            factor: 1.0,
            offset: 0.0,
        }
    }

    #[test]
    fn intel_signals_read_lsb_first() {
        // byte 0 = 0x34, byte 1 = 0x12: a 16-bit Intel value 0x1234 from bit 0.
        let d = [0x34, 0x12, 0xFF, 0x7F];
        assert_eq!(layout(0, 16, ByteOrder::LittleEndian, false).extract_raw(&d), Some(0x1234));
        // bits 16..31 = 0x7FFF; signed still positive.
        assert_eq!(layout(16, 16, ByteOrder::LittleEndian, true).extract_raw(&d), Some(0x7FFF));
        // byte 2 = 0xFF as a signed 8-bit value is -1.
        assert_eq!(layout(16, 8, ByteOrder::LittleEndian, true).extract_raw(&d), Some(-1));
        // a 4-bit field at bit 4 of byte 0 (0x3).
        assert_eq!(layout(4, 4, ByteOrder::LittleEndian, false).extract_raw(&d), Some(0x3));
        // runs past the payload: None, not a panic.
        assert_eq!(layout(24, 16, ByteOrder::LittleEndian, false).extract_raw(&d), None);
    }

    #[test]
    fn motorola_signals_read_msb_first() {
        // A 16-bit Motorola value with start bit 7 (MSB of byte 0): bytes 0x12, 0x34.
        let d = [0x12, 0x34];
        assert_eq!(layout(7, 16, ByteOrder::BigEndian, false).extract_raw(&d), Some(0x1234));
        // 12 bits from bit 3 of byte 0: byte 0 bits 3..0 (0x2) then byte 1 (0x34).
        assert_eq!(layout(3, 12, ByteOrder::BigEndian, false).extract_raw(&d), Some(0x234));
        // 0xFFFE signed is -2.
        assert_eq!(layout(7, 16, ByteOrder::BigEndian, true).extract_raw(&[0xFF, 0xFE]), Some(-2));
    }

    #[test]
    fn insert_is_the_inverse_of_extract_in_both_orders() {
        for order in [ByteOrder::LittleEndian, ByteOrder::BigEndian] {
            let start = if order == ByteOrder::LittleEndian { 13 } else { 21 };
            let l = SignalLayout { factor: 0.25, offset: -3.0, ..layout(start, 20, order, true) };
            l.validate("x").unwrap();
            for v in [-3.0, 0.0, 1234.5, -100_000.25, 131_068.0] {
                let mut d = [0xA5u8; 8];
                assert!(!l.insert(v, &mut d), "{v} fits");
                assert_eq!(l.extract(&d), Some(v), "{order:?} {v}");
            }
            // Out of range saturates and says so.
            let mut d = [0u8; 8];
            assert!(l.insert(1e9, &mut d));
            assert_eq!(l.extract_raw(&d), Some((1 << 19) - 1));
        }
    }

    #[test]
    fn bad_layouts_are_refused_when_the_mapping_is_built() {
        assert!(layout(60, 8, ByteOrder::LittleEndian, false).validate("x").is_err());
        assert!(layout(0, 0, ByteOrder::LittleEndian, false).validate("x").is_err());
        assert!(layout(0, 65, ByteOrder::LittleEndian, false).validate("x").is_err());
        let mut l = layout(0, 8, ByteOrder::LittleEndian, false);
        l.frame = FrameId::standard(0x800);
        assert!(l.validate("x").is_err());
        l.frame = FrameId::standard(0x7FF);
        l.factor = 0.0;
        assert!(l.validate("x").is_err());
        let s = CanSignalSpec { role: Role::Load, layout: layout(0, 8, ByteOrder::LittleEndian, true) };
        assert!(CanMapping::new(vec![s, s], None).is_err());
        assert!(CanMapping::new(vec![], None).is_err());
        assert!(CanMapping::new(vec![s], Some(layout(8, 8, ByteOrder::LittleEndian, true))).is_err());
    }

    #[test]
    fn block_mappings_check_their_slots_and_payload_kind() {
        let at = |start_bit: u16, role: Role| CanSignalSpec {
            role,
            layout: layout(start_bit, 16, ByteOrder::LittleEndian, true),
        };
        let ok = vec![vec![at(64, Role::Load)], vec![at(80, Role::Load)]];
        let m = CanMapping::block(ok.clone(), None, true).unwrap();
        assert_eq!((m.samples_per_frame(), m.is_fd(), m.frames()), (2, true, vec![(FrameId::standard(0x120), 12)]));
        assert_eq!(m.slot(1)[0].start_bit, 80);
        // Past byte 8 only in an FD frame; past byte 64 never.
        let e = CanMapping::block(ok, None, false).unwrap_err().to_string();
        assert!(e.contains("8-byte classic"), "{e}");
        let e = CanMapping::block(vec![vec![at(504, Role::Load)]], None, true).unwrap_err().to_string();
        assert!(e.contains("64-byte CAN FD"), "{e}");
        // Every slot the same roles, all in the sample frame.
        let e = CanMapping::block(vec![vec![at(64, Role::Load)], vec![at(80, Role::Acc)]], None, true).unwrap_err();
        assert!(e.to_string().contains("same roles"), "{e}");
        let mut other = at(80, Role::Load);
        other.layout.frame = FrameId::standard(0x121);
        let e = CanMapping::block(vec![vec![at(64, Role::Load)], vec![other]], None, true).unwrap_err();
        assert!(e.to_string().contains("sample frame 120"), "{e}");
        assert_eq!(fd_len_for(9), Some(12));
        assert_eq!(fd_len_for(65), None);
    }
}
