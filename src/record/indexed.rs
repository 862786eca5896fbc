//! Reading the chunks a recording's summary indexes: one at a time on the caller's thread
//! (`chunk_bounds`, `read_at`), or ahead on a thread of their own (`read_ahead`), which
//! decompresses and checks them in parallel on rayon's threads and hands them over in file
//! order (`reader::ReadMode`).

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::sync::mpsc::{Receiver, channel, sync_channel};

use mcap::records::ChunkIndex;

use super::chunk::{self, Unpacked};
use super::error::ChunkError;

/// The largest record (chunk, compressed or not) the reader accepts. forgemon's chunks are
/// about 1 MiB; the limit keeps a damaged length field from allocating gigabytes.
pub const MAX_RECORD_BYTES: usize = 64 * 1024 * 1024;

/// Chunks read ahead of the caller in `ReadMode::Parallel`: handed over or being unpacked
/// (forgemon's chunks are about 1 MiB each, 3 MiB unpacked).
pub const READ_AHEAD_CHUNKS: usize = 16;

/// One step of the read-ahead thread, in file order.
pub(super) enum Ahead {
    /// A chunk the index points at: its records, or why not, once unpacked.
    Chunk { index: ChunkIndex, unpacked: Receiver<Result<Unpacked, ChunkError>> },
    /// Reading failed; nothing follows.
    Io(std::io::Error),
    /// Every indexed chunk was handed over.
    End,
}

/// The indexed chunks of `file` (`total` bytes) read on a thread of their own and each
/// unpacked (decompressed, CRC-checked) as a task on rayon's threads as soon as it is read,
/// handed over in file order, at most `READ_AHEAD_CHUNKS` ahead of the caller. `None` when
/// the file cannot be shared with a thread or the thread cannot start: the caller reads in
/// turn.
pub(super) fn read_ahead(file: &File, chunks: Vec<ChunkIndex>, total: u64) -> Option<Receiver<Ahead>> {
    let (tx, rx) = sync_channel(READ_AHEAD_CHUNKS);
    let mut own = file.try_clone().ok()?;
    let spawned = std::thread::Builder::new().name("forgemon-read".into()).spawn(move || {
        // The buffers the chunks are read into come back once unpacked, to be used again.
        let (spare_tx, spare) = channel::<Vec<u8>>();
        for index in chunks {
            let (start, length) = (index.chunk_start_offset, index.chunk_length);
            let (done, unpacked) = sync_channel(1);
            match chunk_bounds(start, length, total) {
                Ok(()) => {
                    let mut record = spare.try_recv().unwrap_or_default();
                    if let Err(e) = read_at(&mut own, start, length as usize, &mut record) {
                        let _ = tx.send(Ahead::Io(e));
                        return;
                    }
                    let spare_tx = spare_tx.clone();
                    rayon::spawn(move || {
                        let _ = done.send(chunk::unpack(&record, MAX_RECORD_BYTES));
                        let _ = spare_tx.send(record);
                    });
                }
                Err(error) => {
                    let _ = done.send(Err(error));
                }
            }
            if tx.send(Ahead::Chunk { index, unpacked }).is_err() {
                return;
            }
        }
        let _ = tx.send(Ahead::End);
    });
    spawned.ok().map(|_| rx)
}

/// A chunk the index places at `start`, `length` bytes long, must lie inside the file of
/// `total` bytes and within [`MAX_RECORD_BYTES`].
pub(super) fn chunk_bounds(start: u64, length: u64, total: u64) -> Result<(), ChunkError> {
    let end = start.saturating_add(length);
    if end > total {
        return Err(ChunkError::OutsideFile { start, end, total });
    }
    if length > MAX_RECORD_BYTES as u64 {
        return Err(ChunkError::TooLarge { bytes: length, limit: MAX_RECORD_BYTES as u64 });
    }
    Ok(())
}

/// `length` bytes of `file` from `start`, into `record` (what it held replaced; its
/// capacity used again, nothing zeroed first).
pub(super) fn read_at(file: &mut File, start: u64, length: usize, record: &mut Vec<u8>) -> std::io::Result<()> {
    record.clear();
    record.reserve(length);
    file.seek(SeekFrom::Start(start))?;
    let got = file.by_ref().take(length as u64).read_to_end(record)?;
    if got < length {
        let why = format!("the file ends {got} bytes into a chunk of {length}");
        return Err(std::io::Error::new(std::io::ErrorKind::UnexpectedEof, why));
    }
    Ok(())
}
