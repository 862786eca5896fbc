//! Reading the chunks a recording's summary indexes: one at a time on the caller's thread
//! (`chunk_bounds`, `read_at`), or ahead on a thread of their own (`read_ahead`), which
//! decompresses and checks them in parallel on rayon's threads and hands them over in file
//! order (`reader::ReadMode`).

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};

use mcap::records::ChunkIndex;

use super::chunk::{self, Unpacked};
use super::error::ChunkError;

/// The largest record (chunk, compressed or not) the reader accepts. forgemon's chunks are
/// about 1 MiB; the limit keeps a damaged length field from allocating gigabytes.
pub const MAX_RECORD_BYTES: usize = 64 * 1024 * 1024;

/// Chunks read and unpacked together in `ReadMode::Parallel`, and the most the read-ahead
/// thread holds waiting (forgemon's chunks are about 1 MiB each).
pub const READ_AHEAD_CHUNKS: usize = 8;

/// One step of the read-ahead thread, in file order.
pub(super) enum Ahead {
    /// A chunk the index points at: its records, or why not.
    Chunk { index: ChunkIndex, unpacked: Result<Unpacked, ChunkError> },
    /// Reading failed; nothing follows.
    Io(std::io::Error),
    /// Every indexed chunk was handed over.
    End,
}

/// The indexed chunks of `file` (`total` bytes) read and unpacked on a thread of their
/// own, in batches of `READ_AHEAD_CHUNKS` unpacked in parallel, handed over in file order.
/// `None` when the file cannot be shared with a thread or the thread cannot start: the
/// caller reads in turn.
pub(super) fn read_ahead(file: &File, chunks: Vec<ChunkIndex>, total: u64) -> Option<Receiver<Ahead>> {
    let (tx, rx) = sync_channel(READ_AHEAD_CHUNKS);
    let mut own = file.try_clone().ok()?;
    let spawned = std::thread::Builder::new().name("forgemon-read".into()).spawn(move || {
        for batch in chunks.chunks(READ_AHEAD_CHUNKS) {
            let mut read = Vec::with_capacity(batch.len());
            for index in batch {
                let (start, length) = (index.chunk_start_offset, index.chunk_length);
                match chunk_bounds(start, length, total).map(|()| read_at(&mut own, start, length as usize)) {
                    Ok(Err(e)) => {
                        // The chunks before the failed read are handed over first.
                        send_unpacked(&tx, read);
                        let _ = tx.send(Ahead::Io(e));
                        return;
                    }
                    Ok(Ok(record)) => read.push((index.clone(), Ok(record))),
                    Err(error) => read.push((index.clone(), Err(error))),
                }
            }
            if !send_unpacked(&tx, read) {
                return;
            }
        }
        let _ = tx.send(Ahead::End);
    });
    spawned.ok().map(|_| rx)
}

/// Unpack `read` in parallel and send it in order; `false` once the reader is gone.
fn send_unpacked(tx: &SyncSender<Ahead>, read: Vec<(ChunkIndex, Result<Vec<u8>, ChunkError>)>) -> bool {
    use rayon::prelude::*;
    let unpacked: Vec<Ahead> = read
        .into_par_iter()
        .map(|(index, record)| Ahead::Chunk {
            index,
            unpacked: record.and_then(|r| chunk::unpack(&r, MAX_RECORD_BYTES)),
        })
        .collect();
    unpacked.into_iter().all(|a| tx.send(a).is_ok())
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

/// `length` bytes of `file` from `start`.
pub(super) fn read_at(file: &mut File, start: u64, length: usize) -> std::io::Result<Vec<u8>> {
    let mut record = vec![0u8; length];
    file.seek(SeekFrom::Start(start))?;
    file.read_exact(&mut record)?;
    Ok(record)
}
