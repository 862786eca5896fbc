//! Reading a recording front to back, for a file without a usable summary: one cut off by
//! a crash (`.mcap.part`), or one whose summary is damaged. The `mcap` crate's linear
//! reader splits the file into records and hands over each chunk whole; the caller checks
//! and unpacks it (`chunk.rs`), so a chunk with bad content is skipped by its own length
//! field and reading goes on at the next record.
//!
//! When the record boundaries themselves are lost (a damaged length field, an opcode MCAP
//! does not have), the reader resynchronises: it looks for the next position where an
//! intact chunk starts (one that passes its CRC) and carries on there; the bytes between
//! are reported as damaged. With none further on, an end inside a record is a cut-off file,
//! as after a crash, and anything else is damage to the end of the file.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};

use mcap::records::{Record, op};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::chunk::{self, Inner, RECORD_PREFIX_BYTES};
use super::error::ChunkError;

/// The highest opcode MCAP defines (Data End); anything above, or 0, means the reader has
/// lost the record boundaries.
const LAST_OPCODE: u8 = op::DATA_END;

/// What front-to-back reading found next.
#[derive(Debug)]
pub(crate) enum Step {
    /// A whole chunk record (opcode, length, body), not yet checked.
    Chunk { offset: u64, record: Vec<u8> },
    /// A message index record, which follows its chunk and names a channel it held.
    MessageIndex { channel_id: u16 },
    /// A schema, channel or message record outside any chunk.
    Loose { offset: u64, length: u64, record: Inner },
    /// Bytes that could not be read as records, skipped.
    Damaged { offset: u64, length: u64, error: ChunkError },
    /// The end: the closing magic was read (`complete`), or the file stops inside a record.
    End { complete: bool, stopped_by: Option<String> },
}

/// Front-to-back reader over a file.
pub(crate) struct Linear {
    file: BufReader<File>,
    reader: LinearReader,
    /// Offset of the next record the reader will hand over.
    pos: u64,
    total_bytes: u64,
    limit: usize,
    /// Past the data section: the summary records that follow are not needed.
    data_ended: bool,
    /// The step to give once everything else has been given; `None` afterwards.
    end: Option<Step>,
    finished: bool,
}

impl Linear {
    /// Start after the magic (which the caller has checked), at byte 8.
    pub fn new(mut file: File, total_bytes: u64, limit: usize) -> std::io::Result<Linear> {
        file.seek(SeekFrom::Start(mcap::MAGIC.len() as u64))?;
        Ok(Linear {
            file: BufReader::with_capacity(256 * 1024, file),
            reader: record_reader(limit),
            pos: mcap::MAGIC.len() as u64,
            total_bytes,
            limit,
            data_ended: false,
            end: None,
            finished: false,
        })
    }

    /// The next step; `None` after [`Step::End`]. Only IO errors are errors.
    pub fn next_step(&mut self) -> std::io::Result<Option<Step>> {
        loop {
            if self.finished {
                return Ok(self.end.take());
            }
            let Some(event) = self.reader.next_event() else {
                return Ok(Some(self.finish(Step::End { complete: true, stopped_by: None })));
            };
            let (opcode, data) = match event {
                Ok(LinearReadEvent::ReadRequest(need)) => {
                    let buf = self.reader.insert(need);
                    let n = read_some(&mut self.file, buf)?;
                    self.reader.notify_read(n);
                    continue;
                }
                Ok(LinearReadEvent::Record { opcode, data }) => (opcode, data),
                Err(e) => return self.resync(self.pos, e).map(Some),
            };
            let offset = self.pos;
            self.pos += (RECORD_PREFIX_BYTES + data.len()) as u64;
            if self.data_ended {
                continue;
            }
            let step = match opcode {
                op::CHUNK => {
                    let mut record = Vec::with_capacity(RECORD_PREFIX_BYTES + data.len());
                    record.push(opcode);
                    record.extend_from_slice(&(data.len() as u64).to_le_bytes());
                    record.extend_from_slice(data);
                    Step::Chunk { offset, record }
                }
                op::DATA_END => {
                    self.data_ended = true;
                    continue;
                }
                op::MESSAGE_INDEX | op::SCHEMA | op::CHANNEL | op::MESSAGE => match mcap::parse_record(opcode, data) {
                    Ok(Record::MessageIndex(index)) => Step::MessageIndex { channel_id: index.channel_id },
                    Ok(Record::Schema { header, .. }) => Step::Loose {
                        offset,
                        length: self.pos - offset,
                        record: Inner::Schema { id: header.id, name: header.name, encoding: header.encoding },
                    },
                    Ok(Record::Channel(c)) => Step::Loose {
                        offset,
                        length: self.pos - offset,
                        record: Inner::Channel {
                            id: c.id,
                            schema_id: c.schema_id,
                            topic: c.topic,
                            message_encoding: c.message_encoding,
                        },
                    },
                    Ok(Record::Message { header, data }) => Step::Loose {
                        offset,
                        length: self.pos - offset,
                        record: Inner::Message {
                            channel_id: header.channel_id,
                            log_time: header.log_time,
                            data: data.into_owned(),
                        },
                    },
                    Ok(_) => continue,
                    Err(e) => Step::Damaged {
                        offset,
                        length: self.pos - offset,
                        error: ChunkError::Mcap { what: format!("record does not parse: {e}") },
                    },
                },
                0 => return self.resync_after(offset, "opcode 0x00".to_string()).map(Some),
                o if o > LAST_OPCODE => return self.resync_after(offset, format!("unknown opcode {o:#04x}")).map(Some),
                // Header, attachments, metadata, ...: nothing forgemon reads.
                _ => continue,
            };
            return Ok(Some(step));
        }
    }

    fn finish(&mut self, end: Step) -> Step {
        self.finished = true;
        end
    }

    /// The record at `offset` cannot be read (`e`): carry on at the next intact chunk, or
    /// end (cut off, or damaged to the end).
    fn resync(&mut self, offset: u64, e: mcap::McapError) -> std::io::Result<Step> {
        if self.data_ended {
            // The data were all read; the summary after them is not needed.
            let stopped_by = Some(format!("{e} in the summary, after the data (near byte {offset})"));
            return Ok(self.finish(Step::End { complete: false, stopped_by }));
        }
        if matches!(e, mcap::McapError::UnexpectedEof) {
            if let Some(at) = self.find_chunk(offset + 1)? {
                return self.jump(offset, at, e.to_string());
            }
            let stopped_by =
                Some(format!("the file ends inside the record at byte {offset} (of {} bytes)", self.total_bytes));
            return Ok(self.finish(Step::End { complete: false, stopped_by }));
        }
        self.resync_after(offset, e.to_string())
    }

    fn resync_after(&mut self, offset: u64, reason: String) -> std::io::Result<Step> {
        match self.find_chunk(offset + 1)? {
            Some(at) => self.jump(offset, at, reason),
            None => {
                let stopped_by = Some(format!("unreadable records from byte {offset} to the end ({reason})"));
                self.end = Some(Step::End { complete: false, stopped_by });
                self.finished = true;
                Ok(Step::Damaged { offset, length: self.total_bytes - offset, error: ChunkError::Tail { reason } })
            }
        }
    }

    /// Go on reading at `at`, the bytes from `offset` skipped.
    fn jump(&mut self, offset: u64, at: u64, reason: String) -> std::io::Result<Step> {
        self.file.seek(SeekFrom::Start(at))?;
        self.reader = record_reader(self.limit);
        self.pos = at;
        Ok(Step::Damaged { offset, length: at - offset, error: ChunkError::Framing { reason } })
    }

    /// The offset of the first intact chunk (one whose CRC checks) at or after `from`.
    fn find_chunk(&mut self, from: u64) -> std::io::Result<Option<u64>> {
        find_next_chunk(self.file.get_mut(), from, self.total_bytes, self.limit)
    }
}

/// The crate's reader over top-level records, chunks handed over whole.
fn record_reader(limit: usize) -> LinearReader {
    LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_start_magic(true)
            .with_emit_chunks(true)
            .with_record_length_limit(limit),
    )
}

/// Read what is there (0 at the end of the file), retrying on interruption.
fn read_some(file: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    loop {
        match file.read(buf) {
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            other => return other,
        }
    }
}

/// Scan `file` from `from` for the start of a chunk record that passes its CRC.
fn find_next_chunk<F: Read + Seek>(file: &mut F, from: u64, total: u64, limit: usize) -> std::io::Result<Option<u64>> {
    const WINDOW: usize = 1 << 20;
    // Enough to hold a chunk header with a short compression name.
    const PROBE: usize = 64;
    let mut buf = vec![0u8; WINDOW + PROBE];
    let mut start = from;
    while start < total {
        let have = usize::try_from(total - start).unwrap_or(usize::MAX).min(buf.len());
        file.seek(SeekFrom::Start(start))?;
        file.read_exact(&mut buf[..have])?;
        let scan = have.min(WINDOW);
        for i in 0..scan {
            let at = start + i as u64;
            if buf[i] != op::CHUNK || !chunk::plausible_chunk_start(&buf[i..have], total - at, limit) {
                continue;
            }
            let mut len = [0u8; 8];
            len.copy_from_slice(&buf[i + 1..i + RECORD_PREFIX_BYTES]);
            // plausible_chunk_start checked the length against the limit and the file.
            let mut record = vec![0u8; RECORD_PREFIX_BYTES + u64::from_le_bytes(len) as usize];
            file.seek(SeekFrom::Start(at))?;
            file.read_exact(&mut record)?;
            if matches!(chunk::unpack(&record, limit), Ok(u) if u.verified) {
                return Ok(Some(at));
            }
        }
        start += scan as u64;
    }
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scan_finds_an_intact_chunk_behind_garbage_and_nothing_in_garbage() {
        let mut out = std::io::Cursor::new(Vec::new());
        let mut w = mcap::WriteOptions::new().create(&mut out).expect("writer");
        let schema = w.add_schema("forgemon.Gap", "protobuf", b"descriptor").expect("schema");
        let channel = w.add_channel(schema, "/gaps", "protobuf", &Default::default()).expect("channel");
        let header = mcap::records::MessageHeader { channel_id: channel, sequence: 0, log_time: 5, publish_time: 5 };
        w.write_to_known_channel(&header, &[1, 2, 3]).expect("message");
        w.finish().expect("finish");
        drop(w);
        let file = out.into_inner();
        let chunk_at = file.iter().position(|&b| b == op::CHUNK).expect("a chunk");
        // Garbage full of would-be chunk opcodes, then the file's chunk and the rest.
        let mut bytes = vec![op::CHUNK; 3000];
        bytes.extend_from_slice(&[op::CHUNK, 40, 0, 0, 0, 0, 0, 0, 0]);
        bytes.extend_from_slice(&file[chunk_at..]);
        let total = bytes.len() as u64;
        let found = find_next_chunk(&mut std::io::Cursor::new(&bytes), 0, total, 1 << 20).expect("in memory");
        assert_eq!(found, Some(3009));
        let garbage = vec![op::CHUNK; 5000];
        let none = find_next_chunk(&mut std::io::Cursor::new(&garbage), 0, 5000, 1 << 20).expect("in memory");
        assert_eq!(none, None);
    }
}
