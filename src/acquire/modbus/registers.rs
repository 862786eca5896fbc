//! The register map (DESIGN.md §4, Modbus): which register holds which signal, in which
//! data type and word order, and how its raw value becomes a physical one. Pure code: the
//! driver reads registers and hands the words here; the simulated server encodes with the
//! same rules, so both sides agree by construction.
//!
//! Modbus registers are 16-bit words sent big-endian (Modbus Application Protocol
//! Specification V1.1b3 §4.2). The spec says nothing about 32-bit values: devices split
//! them over two consecutive registers, most significant word first ("big-endian", the
//! common default) or least significant word first ("little-endian", word-swapped).

use crate::signal::sample::Role;

/// Which of the two register tables (Modbus spec §4.3) holds a value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RegisterKind {
    /// Holding registers, read with function code 0x03.
    Holding,
    /// Input registers, read with function code 0x04.
    Input,
}

/// How the words of one value are interpreted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataType {
    U16,
    I16,
    U32,
    I32,
    /// IEEE 754 single precision over two registers.
    F32,
}

impl DataType {
    /// Registers the value occupies.
    pub fn words(&self) -> u16 {
        match self {
            DataType::U16 | DataType::I16 => 1,
            DataType::U32 | DataType::I32 | DataType::F32 => 2,
        }
    }
}

/// Order of the two words of a 32-bit value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WordOrder {
    /// Most significant word in the lower address (Modicon convention).
    #[default]
    BigEndian,
    /// Least significant word in the lower address ("word-swapped").
    LittleEndian,
}

/// What a register carries: one of the pipeline's sample roles, or another named slow
/// signal (a setpoint, a temperature) that is reported but not segmented.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Signal {
    Role(Role),
    /// A name with its unit, e.g. `"setpoint_J"`, `"temperature_C"`.
    Named(String),
}

impl Signal {
    pub fn name(&self) -> &str {
        match self {
            Signal::Role(r) => r.column(),
            Signal::Named(n) => n,
        }
    }
}

/// One entry of the register map: physical value = `offset + scale * raw`.
#[derive(Debug, Clone, PartialEq)]
pub struct RegisterSpec {
    pub signal: Signal,
    /// Protocol address (0-based, as sent on the wire).
    pub address: u16,
    pub kind: RegisterKind,
    pub data_type: DataType,
    /// Only used by 32-bit types.
    pub word_order: WordOrder,
    pub scale: f64,
    pub offset: f64,
}

impl RegisterSpec {
    /// The register after the value's last one (`u32` so a value at 0xFFFF cannot wrap).
    pub fn end(&self) -> u32 {
        self.address as u32 + self.data_type.words() as u32
    }
}

/// A register image that does not hold what the map asks for.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    #[error("register {address} ({words} words) lies outside the registers read ({start}..{end})")]
    OutOfRange { address: u16, words: u16, start: u16, end: u32 },
    #[error("register {address}: the value is not a finite number")]
    NotFinite { address: u16 },
}

/// The raw value (before scale and offset) of `words`, which holds exactly the value's
/// registers in address order.
pub fn raw_value(words: &[u16], data_type: DataType, order: WordOrder) -> f64 {
    let pair = |words: &[u16]| -> u32 {
        let (hi, lo) = match order {
            WordOrder::BigEndian => (words[0], words[1]),
            WordOrder::LittleEndian => (words[1], words[0]),
        };
        ((hi as u32) << 16) | lo as u32
    };
    match data_type {
        DataType::U16 => words[0] as f64,
        DataType::I16 => words[0] as i16 as f64,
        DataType::U32 => pair(words) as f64,
        DataType::I32 => pair(words) as i32 as f64,
        DataType::F32 => f32::from_bits(pair(words)) as f64,
    }
}

/// The words of a raw value (the inverse of [`raw_value`], used by the simulated server).
/// Integers are rounded and saturate at the type's range.
pub fn encode_raw(raw: f64, data_type: DataType, order: WordOrder) -> Vec<u16> {
    let split = |bits: u32| -> Vec<u16> {
        let (hi, lo) = ((bits >> 16) as u16, bits as u16);
        match order {
            WordOrder::BigEndian => vec![hi, lo],
            WordOrder::LittleEndian => vec![lo, hi],
        }
    };
    match data_type {
        DataType::U16 => vec![raw.round() as u16],
        DataType::I16 => vec![raw.round() as i16 as u16],
        DataType::U32 => split(raw.round() as u32),
        DataType::I32 => split(raw.round() as i32 as u32),
        DataType::F32 => split((raw as f32).to_bits()),
    }
}

/// Decode one value from the register image `words`, which starts at address `start`.
pub fn decode_one(words: &[u16], start: u16, spec: &RegisterSpec) -> Result<f64, DecodeError> {
    let n = spec.data_type.words();
    let end = start as u32 + words.len() as u32;
    if spec.address < start || spec.end() > end {
        return Err(DecodeError::OutOfRange { address: spec.address, words: n, start, end });
    }
    let i = (spec.address - start) as usize;
    let raw = raw_value(&words[i..i + n as usize], spec.data_type, spec.word_order);
    let value = spec.offset + spec.scale * raw;
    if value.is_finite() { Ok(value) } else { Err(DecodeError::NotFinite { address: spec.address }) }
}

/// Decode every entry of `specs` from the register image `words` starting at `start`
/// (all entries of one register kind; the caller reads holding and input registers
/// separately). Physical values in the order of `specs`.
pub fn decode_registers(words: &[u16], start: u16, specs: &[RegisterSpec]) -> Result<Vec<f64>, DecodeError> {
    specs.iter().map(|s| decode_one(words, start, s)).collect()
}

/// Largest number of registers one read may ask for (Modbus spec §6.3: 125).
pub const MAX_READ_REGISTERS: u16 = 125;

/// One read request: `count` registers of `kind` from `start`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadBlock {
    pub kind: RegisterKind,
    pub start: u16,
    pub count: u16,
}

/// The few reads that cover every entry of the map: entries of one kind are merged while
/// the span stays within [`MAX_READ_REGISTERS`].
pub fn plan_reads(specs: &[RegisterSpec]) -> Vec<ReadBlock> {
    let mut out: Vec<ReadBlock> = Vec::new();
    for kind in [RegisterKind::Holding, RegisterKind::Input] {
        let mut ranges: Vec<(u32, u32)> =
            specs.iter().filter(|s| s.kind == kind).map(|s| (s.address as u32, s.end())).collect();
        ranges.sort_unstable();
        let mut current: Option<(u32, u32)> = None;
        for (a, e) in ranges {
            current = match current {
                Some((s, ce)) if e.max(ce) - s <= MAX_READ_REGISTERS as u32 => Some((s, e.max(ce))),
                Some((s, ce)) => {
                    out.push(ReadBlock { kind, start: s as u16, count: (ce - s) as u16 });
                    Some((a, e))
                }
                None => Some((a, e)),
            };
        }
        if let Some((s, e)) = current {
            out.push(ReadBlock { kind, start: s as u16, count: (e - s) as u16 });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(address: u16, data_type: DataType, word_order: WordOrder) -> RegisterSpec {
        RegisterSpec {
            signal: Signal::Named("x".into()),
            address,
            kind: RegisterKind::Holding,
            data_type,
            word_order,
            scale: 1.0,
            offset: 0.0,
        }
    }

    #[test]
    fn sixteen_bit_types() {
        // 0xFFFE: 65534 unsigned, -2 as two's complement.
        let words = [0xFFFE];
        assert_eq!(decode_one(&words, 0, &spec(0, DataType::U16, WordOrder::BigEndian)), Ok(65534.0));
        assert_eq!(decode_one(&words, 0, &spec(0, DataType::I16, WordOrder::BigEndian)), Ok(-2.0));
    }

    #[test]
    fn thirty_two_bit_integers_in_both_word_orders() {
        // 0x0001_0002 = 65538: big-endian sends 0x0001 (high) then 0x0002 (low).
        let be = [0x0001, 0x0002];
        // Word-swapped: 0x0002 (low) then 0x0001 (high).
        let le = [0x0002, 0x0001];
        for t in [DataType::U32, DataType::I32] {
            assert_eq!(decode_one(&be, 0, &spec(0, t, WordOrder::BigEndian)), Ok(65538.0));
            assert_eq!(decode_one(&le, 0, &spec(0, t, WordOrder::LittleEndian)), Ok(65538.0));
        }
        // 0xFFFF_FFFE: 4294967294 unsigned, -2 signed.
        let words = [0xFFFF, 0xFFFE];
        assert_eq!(decode_one(&words, 0, &spec(0, DataType::U32, WordOrder::BigEndian)), Ok(4294967294.0));
        assert_eq!(decode_one(&words, 0, &spec(0, DataType::I32, WordOrder::BigEndian)), Ok(-2.0));
        // 0xFFFE_FFFF word-swapped is 0xFFFF_FFFE again: high 0xFFFF at the higher address.
        let swapped = [0xFFFE, 0xFFFF];
        assert_eq!(decode_one(&swapped, 0, &spec(0, DataType::I32, WordOrder::LittleEndian)), Ok(-2.0));
    }

    #[test]
    fn float_in_both_word_orders() {
        // 1.5f32 = 0x3FC0_0000: sign 0, exponent 127, mantissa 0.5.
        let be = [0x3FC0, 0x0000];
        let le = [0x0000, 0x3FC0];
        assert_eq!(decode_one(&be, 0, &spec(0, DataType::F32, WordOrder::BigEndian)), Ok(1.5));
        assert_eq!(decode_one(&le, 0, &spec(0, DataType::F32, WordOrder::LittleEndian)), Ok(1.5));
        // -1100.25 = 0xC489_8800.
        let words = [0xC489, 0x8800];
        assert_eq!(decode_one(&words, 0, &spec(0, DataType::F32, WordOrder::BigEndian)), Ok(-1100.25));
        // 0x7FC0_0000 is a NaN: a value, not a crash.
        let nan = [0x7FC0, 0x0000];
        assert_eq!(
            decode_one(&nan, 0, &spec(0, DataType::F32, WordOrder::BigEndian)),
            Err(DecodeError::NotFinite { address: 0 })
        );
    }

    #[test]
    fn scale_offset_and_addresses_relative_to_the_start() {
        // Registers 100..104: 0x000A at 100, then the i32 -3 (0xFFFF_FFFD) at 101..102.
        let words = [0x000A, 0xFFFF, 0xFFFD, 0x0000];
        let mut temp = spec(100, DataType::U16, WordOrder::BigEndian);
        temp.scale = 0.5;
        temp.offset = 20.0;
        let mut load = spec(101, DataType::I32, WordOrder::BigEndian);
        load.scale = 1000.0;
        assert_eq!(decode_registers(&words, 100, &[temp, load]), Ok(vec![25.0, -3000.0]));
    }

    #[test]
    fn a_value_outside_the_image_is_an_error() {
        let words = [0u16; 2];
        // An i32 at 101 needs 101..103; the image is 100..102.
        assert_eq!(
            decode_one(&words, 100, &spec(101, DataType::I32, WordOrder::BigEndian)),
            Err(DecodeError::OutOfRange { address: 101, words: 2, start: 100, end: 102 })
        );
        assert!(decode_one(&words, 100, &spec(99, DataType::U16, WordOrder::BigEndian)).is_err());
        assert!(decode_one(&[], 0, &spec(0, DataType::U16, WordOrder::BigEndian)).is_err());
    }

    #[test]
    fn encode_is_the_inverse_of_decode() {
        for t in [DataType::U16, DataType::I16, DataType::U32, DataType::I32, DataType::F32] {
            for o in [WordOrder::BigEndian, WordOrder::LittleEndian] {
                let raw = if matches!(t, DataType::U16 | DataType::U32) { 1234.0 } else { -1234.0 };
                assert_eq!(raw_value(&encode_raw(raw, t, o), t, o), raw, "{t:?} {o:?}");
            }
        }
    }

    #[test]
    fn reads_are_merged_per_kind_within_125_registers() {
        let mut a = spec(0, DataType::U16, WordOrder::BigEndian);
        let b = spec(10, DataType::F32, WordOrder::BigEndian);
        let c = spec(200, DataType::U16, WordOrder::BigEndian);
        let mut d = spec(0, DataType::U16, WordOrder::BigEndian);
        d.kind = RegisterKind::Input;
        a.address = 5;
        let plan = plan_reads(&[c, b, a, d]);
        assert_eq!(
            plan,
            vec![
                ReadBlock { kind: RegisterKind::Holding, start: 5, count: 7 },
                ReadBlock { kind: RegisterKind::Holding, start: 200, count: 1 },
                ReadBlock { kind: RegisterKind::Input, start: 0, count: 1 },
            ]
        );
    }
}
