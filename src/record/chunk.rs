//! One MCAP chunk record, checked and unpacked (sans-IO): given the bytes of the whole
//! record, the `mcap` crate's own linear reader decompresses it and checks its CRC before
//! anything inside is handed out, so a chunk gives back all its records or none.
//!
//! The reader calls this for every chunk, whether it found the chunk through the summary's
//! index or front to back, and turns a failure into a [`super::CorruptChunk`] instead of
//! stopping. A chunk whose stored CRC is 0 was written without one and cannot be checked:
//! [`Unpacked::verified`] says so.

use mcap::records::{Record, op};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::error::ChunkError;

/// Opcode (1 byte) and record length (8 bytes) in front of every MCAP record.
pub(crate) const RECORD_PREFIX_BYTES: usize = 9;

/// A record found inside a chunk, owned.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Inner {
    Schema { id: u16, name: String, encoding: String },
    Channel { id: u16, schema_id: u16, topic: String, message_encoding: String },
    Message { channel_id: u16, log_time: u64, data: Vec<u8> },
}

/// The records of one chunk, in order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Unpacked {
    pub records: Vec<Inner>,
    /// The chunk carried a CRC and its content matched it (a stored CRC of 0 means none).
    pub verified: bool,
}

/// Check and unpack one chunk record (`record` = opcode, length and body, nothing more).
/// Records larger than `limit` bytes, compressed or not, are refused before any allocation.
pub(crate) fn unpack(record: &[u8], limit: usize) -> Result<Unpacked, ChunkError> {
    let Some((&[opcode], rest)) = record.split_first_chunk::<1>() else {
        return Err(ChunkError::Truncated { have: 0 });
    };
    if opcode != op::CHUNK {
        return Err(ChunkError::NotChunk { opcode });
    }
    let Some((len, body)) = rest.split_first_chunk::<8>() else {
        return Err(ChunkError::Truncated { have: record.len() as u64 });
    };
    let field = u64::from_le_bytes(*len);
    if field != body.len() as u64 {
        return Err(ChunkError::Length { field, actual: body.len() as u64 });
    }
    let verified = match mcap::parse_record(op::CHUNK, body).map_err(mcap_error)? {
        Record::Chunk { header, .. } => {
            if header.uncompressed_size > limit as u64 {
                return Err(ChunkError::TooLarge { bytes: header.uncompressed_size, limit: limit as u64 });
            }
            header.uncompressed_crc != 0
        }
        _ => return Err(ChunkError::NotChunk { opcode }),
    };
    let options = LinearReaderOptions::default()
        .with_skip_start_magic(true)
        .with_skip_end_magic(true)
        .with_prevalidate_chunk_crcs(true)
        .with_record_length_limit(limit);
    let mut reader = LinearReader::new_with_options(options);
    reader.insert(record.len()).copy_from_slice(record);
    reader.notify_read(record.len());
    let mut records = Vec::new();
    let mut eof_given = false;
    while let Some(event) = reader.next_event() {
        match event.map_err(mcap_error)? {
            LinearReadEvent::ReadRequest(_) => {
                // Everything was given at once: asking for more means the chunk claims more
                // than it holds. Say end of input once; the reader then reports the error.
                if eof_given {
                    return Err(ChunkError::Truncated { have: record.len() as u64 });
                }
                reader.notify_read(0);
                eof_given = true;
            }
            LinearReadEvent::Record { opcode, data } => match mcap::parse_record(opcode, data).map_err(mcap_error)? {
                Record::Schema { header, .. } => {
                    records.push(Inner::Schema { id: header.id, name: header.name, encoding: header.encoding })
                }
                Record::Channel(c) => records.push(Inner::Channel {
                    id: c.id,
                    schema_id: c.schema_id,
                    topic: c.topic,
                    message_encoding: c.message_encoding,
                }),
                Record::Message { header, data } => records.push(Inner::Message {
                    channel_id: header.channel_id,
                    log_time: header.log_time,
                    data: data.into_owned(),
                }),
                // Anything else inside a chunk (nothing a forgemon writer puts there) is
                // passed over, as the MCAP spec allows.
                _ => {}
            },
        }
    }
    Ok(Unpacked { records, verified })
}

/// The `mcap` crate's errors, with a CRC mismatch kept apart (it is the common case and the
/// one a report should name plainly).
pub(crate) fn mcap_error(e: mcap::McapError) -> ChunkError {
    match e {
        mcap::McapError::BadChunkCrc { saved, calculated } => ChunkError::Crc { saved, calculated },
        other => ChunkError::Mcap { what: other.to_string() },
    }
}

/// Whether the bytes at the start of `bytes` could be the start of a chunk record that ends
/// within `remaining` bytes (from the same position to the end of the file). Used only to
/// pick candidates when resynchronising after a damaged record; a candidate is accepted
/// only once [`unpack`] has checked its CRC. The layout is MCAP's Chunk record: opcode,
/// record length, start and end time, uncompressed size, CRC, compression string, compressed
/// size, data.
pub(crate) fn plausible_chunk_start(bytes: &[u8], remaining: u64, limit: usize) -> bool {
    const FIXED_HEADER: usize = 8 + 8 + 8 + 4 + 4 + 8;
    let at = |from: usize, n: usize| bytes.get(from..from + n);
    let u64_at = |from: usize| at(from, 8).and_then(|b| b.try_into().ok()).map(u64::from_le_bytes);
    let (Some(&opcode), Some(len)) = (bytes.first(), u64_at(1)) else { return false };
    if opcode != op::CHUNK || len > limit as u64 || len.saturating_add(RECORD_PREFIX_BYTES as u64) > remaining {
        return false;
    }
    let Some(compression_len) = at(RECORD_PREFIX_BYTES + 28, 4)
        .and_then(|b| b.try_into().ok())
        .map(|b: [u8; 4]| u32::from_le_bytes(b) as usize)
    else {
        return false;
    };
    if compression_len > 8 {
        return false;
    }
    let name_at = RECORD_PREFIX_BYTES + 32;
    let Some(name) = at(name_at, compression_len) else { return false };
    if !matches!(name, b"" | b"zstd" | b"lz4") {
        return false;
    }
    let Some(compressed) = u64_at(name_at + compression_len) else { return false };
    compressed.saturating_add((FIXED_HEADER + compression_len) as u64) <= len
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chunk written by the `mcap` crate itself: one schema, one channel, two messages.
    fn chunk_record(compression: Option<mcap::Compression>) -> Vec<u8> {
        let mut out = std::io::Cursor::new(Vec::new());
        let mut w = mcap::WriteOptions::new().compression(compression).create(&mut out).expect("writer");
        let schema = w.add_schema("forgemon.Gap", "protobuf", b"descriptor").expect("schema");
        let channel = w.add_channel(schema, "/gaps", "protobuf", &Default::default()).expect("channel");
        for (seq, t) in [(0u32, 10u64), (1, 20)] {
            let header =
                mcap::records::MessageHeader { channel_id: channel, sequence: seq, log_time: t, publish_time: t };
            w.write_to_known_channel(&header, &[1, 2, 3]).expect("message");
        }
        w.finish().expect("finish");
        drop(w);
        let bytes = out.into_inner();
        // The first record after the magic (8) and the header record is the chunk.
        let mut at = 8;
        loop {
            let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().expect("8 bytes")) as usize;
            if bytes[at] == op::CHUNK {
                return bytes[at..at + 9 + len].to_vec();
            }
            at += 9 + len;
        }
    }

    #[test]
    fn a_whole_chunk_unpacks_and_is_verified() {
        for compression in [None, Some(mcap::Compression::Zstd), Some(mcap::Compression::Lz4)] {
            let rec = chunk_record(compression);
            let got = unpack(&rec, 1 << 20).expect("unpack");
            assert!(got.verified);
            let messages: Vec<_> = got
                .records
                .iter()
                .filter_map(|r| match r {
                    Inner::Message { log_time, data, .. } => Some((*log_time, data.clone())),
                    _ => None,
                })
                .collect();
            assert_eq!(messages, vec![(10, vec![1, 2, 3]), (20, vec![1, 2, 3])]);
            assert!(got.records.iter().any(|r| matches!(r, Inner::Channel { topic, .. } if topic == "/gaps")));
            assert!(plausible_chunk_start(&rec, rec.len() as u64, 1 << 20));
        }
    }

    #[test]
    fn a_flipped_bit_anywhere_in_a_chunk_is_an_error_never_a_panic() {
        for compression in [None, Some(mcap::Compression::Zstd)] {
            let rec = chunk_record(compression);
            for i in 0..rec.len() {
                for bit in [0, 3, 7] {
                    let mut bad = rec.clone();
                    bad[i] ^= 1 << bit;
                    match unpack(&bad, 1 << 20) {
                        // Only the chunk header's time range and unused bits escape the CRC:
                        // the records themselves come out intact.
                        Ok(got) => assert_eq!(got.records, unpack(&rec, 1 << 20).expect("intact").records),
                        Err(e) => assert!(!e.to_string().is_empty()),
                    }
                }
            }
        }
    }

    #[test]
    fn a_changed_byte_of_data_is_a_crc_mismatch() {
        let mut rec = chunk_record(None);
        // The last byte is inside the last message's data (uncompressed chunk).
        let last = rec.len() - 1;
        rec[last] ^= 0x40;
        assert!(matches!(unpack(&rec, 1 << 20), Err(ChunkError::Crc { .. })));
    }

    #[test]
    fn empty_short_and_foreign_input_are_errors() {
        assert!(matches!(unpack(&[], 1024), Err(ChunkError::Truncated { .. })));
        assert!(matches!(unpack(&[op::CHUNK, 1, 0], 1024), Err(ChunkError::Truncated { .. })));
        // Opcode 0x05 (message), length 0.
        assert!(matches!(unpack(&[5, 0, 0, 0, 0, 0, 0, 0, 0], 1024), Err(ChunkError::NotChunk { opcode: 5 })));
        // Chunk opcode, length field 100 but only 2 body bytes.
        assert!(matches!(
            unpack(&[op::CHUNK, 100, 0, 0, 0, 0, 0, 0, 0, 1, 2], 1024),
            Err(ChunkError::Length { field: 100, actual: 2 })
        ));
    }

    #[test]
    fn a_chunk_claiming_more_than_the_limit_is_refused() {
        let rec = chunk_record(Some(mcap::Compression::Zstd));
        assert!(matches!(unpack(&rec, 16), Err(ChunkError::TooLarge { .. })));
        assert!(!plausible_chunk_start(&rec, rec.len() as u64 - 1, 1 << 20), "runs past the end");
        assert!(!plausible_chunk_start(&rec[..20], rec.len() as u64, 1 << 20), "header cut short");
    }
}
