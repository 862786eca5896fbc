//! When a recording starts a new file, and how its files are named (DESIGN.md §3): a
//! `.mcap` target is one file (numbered when it rotates), a directory target holds
//! numbered files, and a restarted recorder continues after the highest number there.

use std::path::{Path, PathBuf};

use super::error::RecordError;

/// File-name stem of the numbered files when the target is a directory.
pub const DEFAULT_FILE_STEM: &str = "forgemon";
/// Extension of a finished recording.
pub const FINISHED_EXTENSION: &str = "mcap";
/// Extension of a recording being written (or left by a crash).
pub const PART_EXTENSION: &str = "mcap.part";

/// When to start a new file. Both limits may be set; the first one reached rotates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Rotation {
    /// Start a new file once the current one holds this many bytes (it may exceed it by
    /// up to one chunk).
    pub max_bytes: Option<u64>,
    /// Start a new file once its messages span this much log time, ns.
    pub max_duration_ns: Option<u64>,
}

impl Rotation {
    /// One file, never rotated.
    pub const NEVER: Rotation = Rotation { max_bytes: None, max_duration_ns: None };

    pub fn by_size(max_bytes: u64) -> Rotation {
        Rotation { max_bytes: Some(max_bytes), max_duration_ns: None }
    }

    pub fn by_duration_ns(max_duration_ns: u64) -> Rotation {
        Rotation { max_bytes: None, max_duration_ns: Some(max_duration_ns) }
    }

    pub fn is_never(&self) -> bool {
        self.max_bytes.is_none() && self.max_duration_ns.is_none()
    }
}

/// How the files of a recording are named.
pub(super) struct Naming {
    pub(super) dir: PathBuf,
    stem: String,
    /// `STEM-NNNNN.mcap` (rotating or a directory target) or exactly `STEM.mcap`.
    numbered: bool,
    next_index: u32,
}

impl Naming {
    pub(super) fn new(path: &Path, rotation: Rotation) -> Result<Naming, RecordError> {
        let is_file_target = path.extension().is_some_and(|e| e == FINISHED_EXTENSION);
        let (dir, stem, numbered) = if is_file_target {
            let stem = path
                .file_stem()
                .and_then(|s| s.to_str())
                .ok_or_else(|| RecordError::BadTarget { path: path.to_path_buf() })?
                .to_string();
            let dir = match path.parent() {
                Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
                _ => PathBuf::from("."),
            };
            (dir, stem, !rotation.is_never())
        } else {
            std::fs::create_dir_all(path).map_err(|source| RecordError::Io {
                path: path.to_path_buf(),
                action: "create directory",
                source,
            })?;
            (path.to_path_buf(), DEFAULT_FILE_STEM.to_string(), true)
        };
        let mut naming = Naming { dir, stem, numbered, next_index: 1 };
        if numbered {
            naming.next_index = naming.first_free_index()?;
        }
        Ok(naming)
    }

    /// One past the highest `STEM-NNNNN.mcap[.part]` already in the directory, so a
    /// restarted recorder never overwrites an earlier file.
    fn first_free_index(&self) -> Result<u32, RecordError> {
        let entries = std::fs::read_dir(&self.dir).map_err(|source| RecordError::Io {
            path: self.dir.clone(),
            action: "list",
            source,
        })?;
        let prefix = format!("{}-", self.stem);
        let mut highest = 0u32;
        for entry in entries.flatten() {
            let name = entry.file_name();
            let Some(name) = name.to_str() else { continue };
            let Some(rest) = name.strip_prefix(&prefix) else { continue };
            let number = rest
                .strip_suffix(&format!(".{PART_EXTENSION}"))
                .or_else(|| rest.strip_suffix(&format!(".{FINISHED_EXTENSION}")));
            if let Some(n) = number.and_then(|n| n.parse::<u32>().ok()) {
                highest = highest.max(n);
            }
        }
        Ok(highest.saturating_add(1))
    }

    pub(super) fn stem(&self) -> &str {
        &self.stem
    }

    pub(super) fn next_path(&mut self) -> Result<PathBuf, RecordError> {
        if !self.numbered {
            return Ok(self.dir.join(format!("{}.{FINISHED_EXTENSION}", self.stem)));
        }
        let path = self.dir.join(format!("{}-{:05}.{FINISHED_EXTENSION}", self.stem, self.next_index));
        self.next_index = self.next_index.saturating_add(1);
        Ok(path)
    }
}

/// Where a file is written until it is finished.
pub(super) fn part_path_of(final_path: &Path) -> PathBuf {
    let mut name = final_path.as_os_str().to_owned();
    name.push(".part");
    PathBuf::from(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_restarted_recorder_continues_after_the_highest_number() -> Result<(), Box<dyn std::error::Error>> {
        let dir = std::env::temp_dir().join(format!("forgemon-naming-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir)?;
        for name in ["forgemon-00003.mcap", "forgemon-00007.mcap.part", "forgemon-x.mcap", "other-00009.mcap"] {
            std::fs::write(dir.join(name), b"")?;
        }
        let mut naming = Naming::new(&dir, Rotation::NEVER)?;
        assert_eq!(naming.next_path()?, dir.join("forgemon-00008.mcap"));
        assert_eq!(naming.next_path()?, dir.join("forgemon-00009.mcap"));
        assert_eq!(part_path_of(&dir.join("a.mcap")), dir.join("a.mcap.part"));
        // A file target that never rotates is exactly that file.
        let mut one = Naming::new(&dir.join("run.mcap"), Rotation::NEVER)?;
        assert_eq!(one.next_path()?, dir.join("run.mcap"));
        let _ = std::fs::remove_dir_all(&dir);
        Ok(())
    }
}
