//! What reading a recording found: how much was read, whether the file was finished or
//! cut off, and every corrupt chunk it skipped, as data. The reader never prints; `replay`
//! and `inspect` print [`ReadReport::problems`] and decide the exit status.

use std::path::PathBuf;

use super::error::ChunkError;

/// A chunk (or a stretch of records) that could not be used and was skipped.
#[derive(Debug, Clone, PartialEq)]
pub struct CorruptChunk {
    /// Byte offset of the chunk record (or of the first unreadable record) in the file.
    pub offset: u64,
    /// Bytes skipped from `offset`.
    pub length: u64,
    /// The topics whose messages it held, sorted, from the chunk index (or, reading front to
    /// back, from the message index records after it); empty when nothing says.
    pub topics: Vec<String>,
    pub error: ChunkError,
}

/// How much of a file was read, and whether it was whole.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadReport {
    pub path: PathBuf,
    /// The file has its summary and footer: it was finished properly.
    pub complete: bool,
    /// Read through the summary's chunk index (else front to back).
    pub indexed: bool,
    /// Messages yielded.
    pub messages: u64,
    /// Messages on channels that are not forgemon's (other schemas), passed over.
    pub skipped: u64,
    /// Bytes from the start of the file through the last chunk recovered (reading front to
    /// back; the whole file when read through its index).
    pub bytes_recovered: u64,
    pub total_bytes: u64,
    /// Why reading stopped before the end, for a cut-off file.
    pub stopped_by: Option<String>,
    /// Chunks read whose content matched their CRC.
    pub chunks_verified: u64,
    /// Chunks read that were written without a CRC (stored as 0): their content could not
    /// be checked, and a flipped bit in them would go unnoticed.
    pub chunks_unverified: u64,
    /// Chunks that failed their checks and were skipped, in file order.
    pub corrupt_chunks: Vec<CorruptChunk>,
    /// Messages skipped because their channel's definition was never read (it was in a
    /// corrupt chunk of a file read front to back).
    pub unknown_channel_messages: u64,
    /// The file ends like a finished one but its summary could not be used (and why): it
    /// was read front to back instead.
    pub summary_error: Option<String>,
}

impl ReadReport {
    pub(crate) fn new(path: PathBuf, total_bytes: u64) -> ReadReport {
        ReadReport {
            path,
            complete: false,
            indexed: false,
            messages: 0,
            skipped: 0,
            bytes_recovered: 0,
            total_bytes,
            stopped_by: None,
            chunks_verified: 0,
            chunks_unverified: 0,
            corrupt_chunks: Vec::new(),
            unknown_channel_messages: 0,
            summary_error: None,
        }
    }

    /// Some of the file was corrupt (not merely cut off): what was read is only part of it.
    pub fn is_corrupt(&self) -> bool {
        !self.corrupt_chunks.is_empty() || self.summary_error.is_some() || self.unknown_channel_messages > 0
    }

    /// One line per problem, each naming the file: corrupt chunks (byte offset, why, the
    /// topics lost), an unusable summary, messages on lost channels, unverifiable chunks.
    pub fn problems(&self) -> Vec<String> {
        let file = self.path.display();
        let mut out: Vec<String> = self
            .corrupt_chunks
            .iter()
            .map(|c| {
                let topics = if c.topics.is_empty() { "topics unknown".to_string() } else { c.topics.join(", ") };
                format!("{file}: chunk at byte {} is corrupt ({}), skipped: {topics}", c.offset, c.error)
            })
            .collect();
        if let Some(why) = &self.summary_error {
            out.push(format!("{file}: the summary is unusable ({why}); read front to back instead"));
        }
        if self.unknown_channel_messages > 0 {
            out.push(format!(
                "{file}: {} messages skipped: their channel was defined in a corrupt chunk",
                self.unknown_channel_messages
            ));
        }
        if self.chunks_unverified > 0 {
            out.push(format!("{file}: {} chunks carry no CRC and could not be verified", self.chunks_unverified));
        }
        out
    }
}

impl std::fmt::Display for ReadReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: {} messages, {} of {} bytes{}",
            self.path.display(),
            self.messages,
            self.bytes_recovered,
            self.total_bytes,
            if self.complete { String::new() } else { ", file was cut off".to_string() }
        )?;
        if let Some(why) = &self.stopped_by {
            write!(f, " ({why})")?;
        }
        if !self.corrupt_chunks.is_empty() {
            write!(f, ", {} corrupt chunks skipped", self.corrupt_chunks.len())?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn problems_name_the_file_offset_error_and_topics() {
        let mut r = ReadReport::new("rec.mcap".into(), 1000);
        assert!(!r.is_corrupt() && r.problems().is_empty());
        r.corrupt_chunks.push(CorruptChunk {
            offset: 123,
            length: 50,
            topics: vec!["/results".into(), "/samples/daq0".into()],
            error: ChunkError::Crc { saved: 1, calculated: 2 },
        });
        r.chunks_unverified = 2;
        assert!(r.is_corrupt());
        let p = r.problems();
        assert_eq!(
            p[0],
            "rec.mcap: chunk at byte 123 is corrupt (crc mismatch: stored 0x00000001, computed 0x00000002), \
             skipped: /results, /samples/daq0"
        );
        assert_eq!(p[1], "rec.mcap: 2 chunks carry no CRC and could not be verified");
        assert!(r.to_string().contains("1 corrupt chunks skipped"), "{r}");
    }

    #[test]
    fn unverified_chunks_alone_are_not_corruption() {
        let mut r = ReadReport::new("rec.mcap".into(), 1000);
        r.chunks_unverified = 1;
        assert!(!r.is_corrupt());
        assert_eq!(r.problems().len(), 1);
    }
}
