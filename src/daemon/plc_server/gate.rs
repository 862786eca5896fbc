//! The PLC server's frame gate: each Modbus TCP request judged from its bytes before
//! tokio-modbus's codec sees it (sans-IO: fed the bytes read so far, it says what to do).
//!
//! tokio-modbus 0.17's server ends the connection on any request it cannot decode, and a
//! read of 0 or 300 registers decodes. The gate instead answers a request whose MBAP frame
//! is sound but whose PDU is not (a quantity outside the function's range, a byte count
//! that does not match, a truncated or overlong PDU, a coil value other than 0x0000 or
//! 0xFF00) with exception 0x03 Illegal Data Value, as the Modbus Application Protocol
//! v1.1b3 §7 asks, and the connection goes on. A frame that is not Modbus TCP at all (a
//! protocol identifier other than 0, a length outside 2..=254: MBAP, Modbus Messaging on
//! TCP/IP Implementation Guide v1.0b §3.1.3) cannot be resynchronised, since the length
//! field is all that separates requests: the gate says close.

use thiserror::Error;

/// The MBAP header: transaction id (2), protocol id (2), length (2), unit id (1).
pub const MBAP_LEN: usize = 7;
/// The largest MBAP length field: the unit id and a PDU of at most 253 bytes.
pub const MAX_LENGTH_FIELD: u16 = 254;
/// The largest request ADU.
pub const MAX_ADU: usize = MBAP_LEN - 1 + MAX_LENGTH_FIELD as usize;
/// Exception 0x01 Illegal Function (MODBUS Application Protocol v1.1b3 §7).
pub const ILLEGAL_FUNCTION: u8 = 0x01;
/// Exception 0x03 Illegal Data Value.
pub const ILLEGAL_DATA_VALUE: u8 = 0x03;

/// Bytes that are not Modbus TCP: the connection is closed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum FramingError {
    #[error("MBAP protocol identifier {found:#06x} is not Modbus (0)")]
    ProtocolId { found: u16 },
    #[error("MBAP length {found} is outside 2..={MAX_LENGTH_FIELD}")]
    Length { found: u16 },
}

/// What to do with the bytes read so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Judged {
    /// The first request is not complete yet.
    NeedMore,
    /// The first `len` bytes are a well-formed request: hand them to the codec.
    Pass { len: usize },
    /// The first `len` bytes are a request with a malformed PDU: drop them and write
    /// `reply`, its exception response.
    Answer { len: usize, reply: [u8; 9] },
    /// Not Modbus TCP.
    Close(FramingError),
}

/// Judge the first request in `buf`, the bytes read from a client and not yet judged.
pub fn judge(buf: &[u8]) -> Judged {
    if buf.len() < MBAP_LEN {
        return Judged::NeedMore;
    }
    let word = |at: usize| u16::from_be_bytes([buf[at], buf[at + 1]]);
    let (protocol, length) = (word(2), word(4));
    if protocol != 0 {
        return Judged::Close(FramingError::ProtocolId { found: protocol });
    }
    if !(2..=MAX_LENGTH_FIELD).contains(&length) {
        return Judged::Close(FramingError::Length { found: length });
    }
    let len = MBAP_LEN - 1 + usize::from(length);
    let Some(adu) = buf.get(..len) else { return Judged::NeedMore };
    let (function, data) = (adu[MBAP_LEN], &adu[MBAP_LEN + 1..]);
    match check_pdu(function, data) {
        Ok(()) => Judged::Pass { len },
        Err(code) => Judged::Answer { len, reply: exception(adu, function, code) },
    }
}

/// The exception response to `adu`: its transaction and unit, function | 0x80, `code`.
fn exception(adu: &[u8], function: u8, code: u8) -> [u8; 9] {
    [adu[0], adu[1], 0, 0, 0, 3, adu[6], function | 0x80, code]
}

/// A request PDU's data against its function's layout (MODBUS Application Protocol
/// v1.1b3 §6): `Err(exception code)` when it does not fit. Functions the gate does not
/// know pass; the image refuses them with Illegal Function.
fn check_pdu(function: u8, data: &[u8]) -> Result<(), u8> {
    let word = |at: usize| data.get(at..at + 2).map_or(0, |w| u16::from_be_bytes([w[0], w[1]]));
    let fits = |ok: bool| if ok { Ok(()) } else { Err(ILLEGAL_DATA_VALUE) };
    // A multiple write: address, quantity in `range`, byte count, then that many bytes.
    let write = |range: std::ops::RangeInclusive<u16>, bytes_per: fn(u16) -> usize| {
        let q = word(2);
        fits(
            data.len() >= 5
                && range.contains(&q)
                && usize::from(data[4]) == bytes_per(q)
                && data.len() == 5 + bytes_per(q),
        )
    };
    match function {
        0x80.. => Err(ILLEGAL_FUNCTION),
        // Read coils, discrete inputs: 1..=2000 bits.
        0x01 | 0x02 => fits(data.len() == 4 && (1..=2000).contains(&word(2))),
        // Read holding, input registers: 1..=125 words.
        0x03 | 0x04 => fits(data.len() == 4 && (1..=125).contains(&word(2))),
        // Write single coil: 0xFF00 on, 0x0000 off.
        0x05 => fits(data.len() == 4 && matches!(word(2), 0x0000 | 0xFF00)),
        0x06 => fits(data.len() == 4),
        0x0F => write(1..=1968, |q| usize::from(q).div_ceil(8)),
        0x10 => write(1..=123, |q| 2 * usize::from(q)),
        // Report server id: no data.
        0x11 => fits(data.is_empty()),
        // Mask write register: address, AND mask, OR mask.
        0x16 => fits(data.len() == 6),
        // Read/write multiple registers: read 1..=125, write 1..=121 words.
        0x17 => {
            let (read, written) = (word(2), word(6));
            let bytes = 2 * usize::from(written);
            fits(
                data.len() >= 9
                    && (1..=125).contains(&read)
                    && (1..=121).contains(&written)
                    && usize::from(data[8]) == bytes
                    && data.len() == 9 + bytes,
            )
        }
        // Encapsulated interface transport: only Read Device Identification (MEI 0x0E,
        // read code 1..=4, object id).
        0x2B => fits(data.len() == 3 && data[0] == 0x0E && (1..=4).contains(&data[1])),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An ADU of transaction 0x0102, unit 1 around `pdu`.
    fn adu(pdu: &[u8]) -> Vec<u8> {
        let length = (pdu.len() + 1) as u16;
        let mut v = vec![0x01, 0x02, 0x00, 0x00]; // transaction 0x0102, protocol 0
        v.extend(length.to_be_bytes()); // length: unit id + PDU
        v.push(0x01); // unit id 1
        v.extend(pdu);
        v
    }

    fn answer_code(pdu: &[u8]) -> Option<u8> {
        match judge(&adu(pdu)) {
            Judged::Answer { reply, .. } => Some(reply[8]),
            Judged::Pass { .. } => None,
            other => panic!("{pdu:02x?}: {other:?}"),
        }
    }

    #[test]
    fn a_well_formed_read_passes_whole() {
        // 0x03 read holding registers, address 0, quantity 20.
        let a = adu(&[0x03, 0x00, 0x00, 0x00, 0x14]);
        assert_eq!(judge(&a), Judged::Pass { len: 12 });
        // A second request behind it does not change the first's verdict.
        let mut two = a.clone();
        two.extend(&a[..5]);
        assert_eq!(judge(&two), Judged::Pass { len: 12 });
    }

    #[test]
    fn partial_and_empty_input_needs_more() {
        let a = adu(&[0x03, 0x00, 0x00, 0x00, 0x14]);
        for cut in 0..a.len() {
            assert_eq!(judge(&a[..cut]), Judged::NeedMore, "cut at {cut}");
        }
    }

    #[test]
    fn a_malformed_pdu_is_answered_with_illegal_data_value() {
        // Quantity 0 and 126 words (max 125).
        assert_eq!(answer_code(&[0x03, 0x00, 0x00, 0x00, 0x00]), Some(0x03));
        assert_eq!(answer_code(&[0x03, 0x00, 0x00, 0x00, 0x7E]), Some(0x03));
        assert_eq!(answer_code(&[0x03, 0x00, 0x00, 0x00, 0x7D]), None, "125 is allowed");
        // Truncated: the quantity's low byte missing; overlong: one byte too many.
        assert_eq!(answer_code(&[0x03, 0x00, 0x00, 0x00]), Some(0x03));
        assert_eq!(answer_code(&[0x03, 0x00, 0x00, 0x00, 0x01, 0xAA]), Some(0x03));
        // A coil written with 0x1234 (only 0xFF00 and 0x0000 are values).
        assert_eq!(answer_code(&[0x05, 0x00, 0x00, 0x12, 0x34]), Some(0x03));
        assert_eq!(answer_code(&[0x05, 0x00, 0x00, 0xFF, 0x00]), None);
        // Write multiple registers: 2 registers but a byte count of 3.
        assert_eq!(answer_code(&[0x10, 0x00, 0x00, 0x00, 0x02, 0x03, 0, 1, 0]), Some(0x03));
        assert_eq!(answer_code(&[0x10, 0x00, 0x00, 0x00, 0x01, 0x02, 0, 1]), None);
        // Write multiple coils: 9 coils need 2 bytes.
        assert_eq!(answer_code(&[0x0F, 0x00, 0x00, 0x00, 0x09, 0x01, 0xFF]), Some(0x03));
        // A function code with the exception bit: illegal function.
        assert_eq!(answer_code(&[0x83, 0x02]), Some(0x01));
        // Unknown functions pass to the image, which refuses them.
        assert_eq!(answer_code(&[0x41, 0x01, 0x02]), None);
    }

    #[test]
    fn the_exception_keeps_the_transaction_and_unit() {
        let Judged::Answer { len, reply } = judge(&adu(&[0x03, 0x00, 0x00, 0x00, 0x00])) else { panic!() };
        assert_eq!(len, 12);
        // transaction 0x0102, protocol 0, length 3, unit 1, function 0x83, code 0x03
        assert_eq!(reply, [0x01, 0x02, 0x00, 0x00, 0x00, 0x03, 0x01, 0x83, 0x03]);
    }

    #[test]
    fn garbage_is_a_framing_error() {
        // "GET / HTTP/1.1": bytes 2 and 3, "T ", are the protocol id 0x5420.
        assert_eq!(judge(b"GET / HTTP/1.1\r\n"), Judged::Close(FramingError::ProtocolId { found: 0x5420 }));
        // Protocol 0 but a length of 0, 1 (no function code) or 0xFFFF.
        for length in [0u16, 1, 255, 0xFFFF] {
            let mut a = vec![0, 1, 0, 0];
            a.extend(length.to_be_bytes());
            a.push(1);
            assert_eq!(judge(&a), Judged::Close(FramingError::Length { found: length }));
        }
    }
}
