//! The summary of a finished recording: its schemas, channels and chunk index, read from
//! the footer backwards and checked against the footer's summary CRC with the `mcap`
//! crate's own linear reader. The chunk index lets the reader skip a corrupt chunk and carry
//! on at the next; a summary that cannot be trusted is refused with the reason, and the
//! reader falls back to reading front to back (and says so).

use std::io::{Read, Seek, SeekFrom};

use mcap::records::{ChunkIndex, Record, op};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::channels::Channels;

/// Footer record (opcode, length, 20-byte body) and the closing magic.
const FOOTER_AND_MAGIC_BYTES: u64 = 9 + 20 + 8;

/// A checked summary.
#[derive(Debug, Default)]
pub(crate) struct Summary {
    pub channels: Channels,
    /// In file order.
    pub chunk_indexes: Vec<ChunkIndex>,
    /// From the statistics record, if any.
    pub message_count: Option<u64>,
}

/// What the end of a file says about its summary.
#[derive(Debug)]
pub(crate) enum Found {
    /// The file does not end with a footer and the magic: it was cut off (or never finished).
    NoFooter,
    /// A footer that says the file has no summary.
    NoSummary,
    /// The file ends like a finished one, but its summary cannot be used.
    Unreadable(String),
    Summary(Box<Summary>),
}

/// Read and check the summary of a file of `total_bytes`. Only IO errors are errors; every
/// problem with the bytes is a [`Found`] value.
pub(crate) fn read_summary<F: Read + Seek>(file: &mut F, total_bytes: u64, limit: usize) -> std::io::Result<Found> {
    if total_bytes < 8 + FOOTER_AND_MAGIC_BYTES {
        return Ok(Found::NoFooter);
    }
    let footer_at = total_bytes - FOOTER_AND_MAGIC_BYTES;
    let mut tail = [0u8; FOOTER_AND_MAGIC_BYTES as usize];
    file.seek(SeekFrom::Start(footer_at))?;
    file.read_exact(&mut tail)?;
    if tail[29..] != mcap::MAGIC[..] {
        return Ok(Found::NoFooter);
    }
    if tail[0] != op::FOOTER {
        return Ok(Found::Unreadable(format!("no footer record before the closing magic (opcode {:#04x})", tail[0])));
    }
    let footer = match mcap::parse_record(op::FOOTER, &tail[9..29]) {
        Ok(Record::Footer(footer)) => footer,
        Ok(_) => return Ok(Found::Unreadable("the footer record does not parse".into())),
        Err(e) => return Ok(Found::Unreadable(format!("the footer record does not parse: {e}"))),
    };
    if footer.summary_start == 0 {
        return Ok(Found::NoSummary);
    }
    if footer.summary_start < 8 || footer.summary_start > footer_at {
        return Ok(Found::Unreadable(format!(
            "the footer puts the summary at byte {}, outside the file's {total_bytes} bytes",
            footer.summary_start
        )));
    }
    let summary_bytes = total_bytes - footer.summary_start;
    if summary_bytes > limit as u64 {
        return Ok(Found::Unreadable(format!("the summary is {summary_bytes} bytes, over the {limit}-byte limit")));
    }
    let mut bytes = vec![0u8; summary_bytes as usize];
    file.seek(SeekFrom::Start(footer.summary_start))?;
    file.read_exact(&mut bytes)?;
    Ok(match parse_summary(&bytes, limit) {
        Ok(summary) => Found::Summary(Box::new(summary)),
        Err(why) => Found::Unreadable(why),
    })
}

/// Parse the summary section through the footer and closing magic (sans-IO). The crate's
/// reader hashes every byte from the summary's start and checks the footer's CRC (when the
/// writer stored one: forgemon's always does).
fn parse_summary(bytes: &[u8], limit: usize) -> Result<Summary, String> {
    let options = LinearReaderOptions::default()
        .with_skip_start_magic(true)
        // Hashing from the first byte fed, here the summary's start: the footer's CRC.
        .with_validate_data_section_crc(true)
        .with_record_length_limit(limit);
    let mut reader = LinearReader::new_with_options(options);
    reader.insert(bytes.len()).copy_from_slice(bytes);
    reader.notify_read(bytes.len());
    let mut summary = Summary::default();
    let mut eof_given = false;
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| format!("{e}"))? {
            LinearReadEvent::ReadRequest(_) if !eof_given => {
                reader.notify_read(0);
                eof_given = true;
            }
            LinearReadEvent::ReadRequest(_) => return Err("the summary runs past the end of the file".into()),
            LinearReadEvent::Record { opcode, data } => match mcap::parse_record(opcode, data) {
                Ok(Record::Schema { header, .. }) => {
                    summary.channels.add_schema(header.id, header.name, header.encoding)
                }
                Ok(Record::Channel(c)) => summary.channels.add_channel(c.id, c.schema_id, c.topic, c.message_encoding),
                Ok(Record::ChunkIndex(index)) => summary.chunk_indexes.push(index),
                Ok(Record::Statistics(stats)) => summary.message_count = Some(stats.message_count),
                Ok(_) => {}
                Err(e) => return Err(format!("a summary record (opcode {opcode:#04x}) does not parse: {e}")),
            },
        }
    }
    summary.chunk_indexes.sort_by_key(|c| c.chunk_start_offset);
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small_file() -> Vec<u8> {
        let mut out = std::io::Cursor::new(Vec::new());
        let mut w = mcap::WriteOptions::new().create(&mut out).expect("writer");
        let schema = w.add_schema("forgemon.Gap", "protobuf", b"descriptor").expect("schema");
        let channel = w.add_channel(schema, "/gaps", "protobuf", &Default::default()).expect("channel");
        let header = mcap::records::MessageHeader { channel_id: channel, sequence: 0, log_time: 5, publish_time: 5 };
        w.write_to_known_channel(&header, &[1, 2, 3]).expect("message");
        w.finish().expect("finish");
        drop(w);
        out.into_inner()
    }

    fn read(bytes: &[u8]) -> Found {
        read_summary(&mut std::io::Cursor::new(bytes), bytes.len() as u64, 1 << 20).expect("in memory")
    }

    #[test]
    fn a_finished_file_has_its_summary_read() {
        let Found::Summary(s) = read(&small_file()) else { panic!("no summary") };
        assert_eq!(s.chunk_indexes.len(), 1);
        assert_eq!(s.message_count, Some(1));
        assert_eq!(s.channels.topic(1), Some("/gaps"));
    }

    #[test]
    fn a_flipped_bit_in_the_summary_or_footer_is_refused_or_harmless_never_a_panic() {
        let bytes = small_file();
        let Found::Summary(intact) = read(&bytes) else { panic!("no summary") };
        // The footer's first field is the summary's start.
        let footer_body = bytes.len() - 8 - 20;
        let summary_start =
            u64::from_le_bytes(bytes[footer_body..footer_body + 8].try_into().expect("8 bytes")) as usize;
        assert!(summary_start > 8 && summary_start < footer_body);
        for i in summary_start..bytes.len() {
            for bit in 0..8 {
                let mut bad = bytes.clone();
                bad[i] ^= 1 << bit;
                match read(&bad) {
                    Found::Summary(s) => {
                        // Only bits the CRC does not cover (the footer's CRC field and its
                        // opcode/length prefix, unused by the reader) may leave it readable,
                        // and then it is the same summary.
                        assert_eq!(s.chunk_indexes, intact.chunk_indexes, "byte {i} bit {bit}");
                        assert_eq!(s.channels.topic(1), Some("/gaps"));
                    }
                    Found::Unreadable(why) => assert!(!why.is_empty()),
                    Found::NoFooter | Found::NoSummary => {}
                }
            }
        }
    }

    #[test]
    fn short_or_unfinished_files_have_no_footer() {
        assert!(matches!(read(b""), Found::NoFooter));
        assert!(matches!(read(mcap::MAGIC), Found::NoFooter));
        let bytes = small_file();
        assert!(matches!(read(&bytes[..bytes.len() - 1]), Found::NoFooter));
    }
}
