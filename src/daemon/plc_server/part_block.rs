//! The PLC's part block (docs/interfaces.md §8, issue 44): holding registers 100–147, which
//! the PLC writes and reads back, holding the part id, the lot and the die set as text, and
//! the coils that act on them: coil 2 starts a new billet forged as the block says, coil 3
//! changes the dies to the block's die set.
//!
//! Each field is 16 registers, 32 ASCII characters, two a register, the first in the high
//! byte; it ends at its first NUL byte (or after 32 characters). A write may hold only NUL
//! and printable ASCII (0x20–0x7E); anything else is refused whole (exception 0x03). An
//! empty field keeps what is in force: a PLC that writes only the part id leaves the lot and
//! the die set as they are. A field that is not a valid id (`[part]`'s rule: no leading or
//! trailing spaces) refuses its coil with 0x03, and nothing is sent.

use tokio_modbus::ExceptionCode;

use crate::config::history::{TraceUpdate, check_id};

/// The block's first register.
pub const START: u16 = 100;
/// One field: 32 characters, two a register.
pub const FIELD_WORDS: usize = 16;
/// Part id, lot, die set.
pub const WORDS: usize = 3 * FIELD_WORDS;

/// The block's registers, as the PLC last wrote them (zero at the start).
pub type Block = [u16; WORDS];

/// The fields in register order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Field {
    PartId = 0,
    Lot = 1,
    DieSet = 2,
}

/// Where registers `addr..addr + n` are in the block: `None` when `addr` is not in it, an
/// illegal data address when they run past its end.
pub fn span(addr: u16, n: usize) -> Option<Result<std::ops::Range<usize>, ExceptionCode>> {
    let at = usize::from(addr.checked_sub(START)?);
    if at >= WORDS {
        return None;
    }
    Some(if at + n <= WORDS { Ok(at..at + n) } else { Err(ExceptionCode::IllegalDataAddress) })
}

/// Write `words` at `range`: each byte NUL or printable ASCII, or nothing is written.
pub fn write(block: &mut Block, range: std::ops::Range<usize>, words: &[u16]) -> Result<(), ExceptionCode> {
    let printable = |b: u8| b == 0 || (0x20..=0x7E).contains(&b);
    if !words.iter().flat_map(|w| w.to_be_bytes()).all(printable) {
        return Err(ExceptionCode::IllegalDataValue);
    }
    block[range].copy_from_slice(words);
    Ok(())
}

/// A field's text: `None` when empty; a text that is not a valid id is an illegal value.
fn text(block: &Block, field: Field) -> Result<Option<String>, ExceptionCode> {
    let at = field as usize * FIELD_WORDS;
    let bytes: Vec<u8> =
        block[at..at + FIELD_WORDS].iter().flat_map(|w| w.to_be_bytes()).take_while(|&b| b != 0).collect();
    if bytes.is_empty() {
        return Ok(None);
    }
    // `write` let only ASCII in.
    let s = String::from_utf8(bytes).map_err(|_| ExceptionCode::IllegalDataValue)?;
    check_id(&s).map_err(|_| ExceptionCode::IllegalDataValue)?;
    Ok(Some(s))
}

/// Coil 2's change: each field written replaces the one in force; an empty one keeps it.
pub fn billet_change(block: &Block) -> Result<TraceUpdate, ExceptionCode> {
    let given = |f| text(block, f).map(|t| t.map(Some));
    Ok(TraceUpdate { part_id: given(Field::PartId)?, lot: given(Field::Lot)?, die_set: given(Field::DieSet)? })
}

/// Coil 3's change: the die set the block names (empty: the one in force, started anew).
pub fn die_change(block: &Block) -> Result<TraceUpdate, ExceptionCode> {
    Ok(TraceUpdate { die_set: text(block, Field::DieSet)?.map(Some), ..TraceUpdate::default() })
}

/// `s` as a field's registers, as a PLC writes it (NUL-padded; for tests and benches).
pub fn encode(s: &str) -> [u16; FIELD_WORDS] {
    let mut bytes = [0u8; 2 * FIELD_WORDS];
    for (b, c) in bytes.iter_mut().zip(s.bytes()) {
        *b = c;
    }
    std::array::from_fn(|i| u16::from_be_bytes([bytes[2 * i], bytes[2 * i + 1]]))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(fields: [&str; 3]) -> Block {
        let mut b = [0u16; WORDS];
        for (k, s) in fields.iter().enumerate() {
            b[k * FIELD_WORDS..(k + 1) * FIELD_WORDS].copy_from_slice(&encode(s));
        }
        b
    }

    #[test]
    fn fields_read_to_their_first_nul_and_empty_ones_keep_what_is_in_force() {
        // "P-1" is 0x50 0x2D, 0x31 0x00: the first character in the high byte.
        assert_eq!(encode("P-1")[..2], [0x502D, 0x3100]);
        let b = with(["P-000418", "", "17"]);
        let u = billet_change(&b).unwrap();
        assert_eq!(u.part_id, Some(Some("P-000418".into())));
        assert_eq!(u.lot, None, "empty: kept");
        assert_eq!(u.die_set, Some(Some("17".into())));
        assert_eq!(die_change(&b).unwrap(), TraceUpdate { die_set: Some(Some("17".into())), ..Default::default() });
        // 32 characters fill the field with no NUL at all.
        let long = "A".repeat(32);
        assert_eq!(billet_change(&with([&long, "", ""])).unwrap().part_id, Some(Some(long)));
        // Text after the first NUL is not part of the field.
        let mut b = with(["AB", "", ""]);
        b[2] = u16::from_be_bytes(*b"ZZ");
        assert_eq!(billet_change(&b).unwrap().part_id, Some(Some("AB".into())));
    }

    #[test]
    fn a_write_outside_printable_ascii_and_a_field_with_spaces_are_refused() {
        let mut b = [0u16; WORDS];
        assert_eq!(write(&mut b, 0..2, &[0x4142, 0x0A00]), Err(ExceptionCode::IllegalDataValue), "a line feed");
        assert_eq!(b, [0u16; WORDS], "nothing written");
        assert_eq!(write(&mut b, 0..1, &[0xC3A4]), Err(ExceptionCode::IllegalDataValue), "UTF-8, not ASCII");
        assert!(write(&mut b, 0..2, &[0x2041, 0x4200]).is_ok(), "printable: taken");
        assert_eq!(billet_change(&b), Err(ExceptionCode::IllegalDataValue), "' AB' has a leading space");
        assert!(die_change(&b).is_ok(), "the die set field is sound");
    }

    #[test]
    fn spans_lie_in_the_block_or_are_refused() {
        assert_eq!(span(99, 1), None);
        assert_eq!(span(100, 48), Some(Ok(0..48)));
        assert_eq!(span(147, 1), Some(Ok(47..48)));
        assert_eq!(span(147, 2), Some(Err(ExceptionCode::IllegalDataAddress)));
        assert_eq!(span(148, 1), None);
    }
}
