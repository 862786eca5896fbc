//! The disk under a recording: the space left on it, the retention that deletes the oldest
//! whole files, and the outage that follows a failed write (DESIGN.md §3).
//!
//! A write that fails (a full disk, a quota, a file size limit, an I/O error) suspends the
//! recording instead of ending it: the file is given up (`OpenFile::abandon`), messages
//! are dropped and counted, and a new file is tried after a backoff in log time (the
//! writer reads no clock) once the directory has room for it again.

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

/// The first retry after a failed write, in log time.
pub const RETRY_FIRST_NS: u64 = 500_000_000;
/// The longest wait between retries: a disk that is freed is written again within this.
pub const RETRY_MAX_NS: u64 = 2_000_000_000;

/// What a retention policy keeps of a recording directory. The current file is never
/// deleted; older files go oldest first, whole.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Retention {
    /// Delete the oldest files while the recording's files hold more than this.
    pub keep_bytes: Option<u64>,
    /// Delete files last written more than this many days ago.
    pub keep_days: Option<f64>,
}

impl Retention {
    pub fn is_none(&self) -> bool {
        self.keep_bytes.is_none() && self.keep_days.is_none()
    }
}

/// The recording's state, as `/status` shows it.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize)]
pub struct RecordingHealth {
    /// `"recording"`, or `"suspended"` after a failed write until a new file is open.
    pub state: &'static str,
    /// The file being written (`None` while suspended).
    pub path: Option<PathBuf>,
    /// Why the recording is suspended (the failed write, or the room a retry found).
    pub reason: Option<String>,
    /// Bytes free for this service in the recording's directory (`None` when unknown).
    pub bytes_free: Option<u64>,
    /// Messages not recorded because the recording was suspended or the write failed.
    pub dropped_messages: u64,
    /// Of those, blow results.
    pub dropped_blows: u64,
    /// Times the recording was suspended.
    pub suspensions: u64,
    /// Files the retention policy deleted.
    pub deleted_files: u64,
}

/// Bytes an unprivileged writer may still use in the file system holding `dir`.
pub fn bytes_free(dir: &Path) -> Option<u64> {
    let st = rustix::fs::statvfs(dir).ok()?;
    Some(st.f_bavail.saturating_mul(st.f_frsize))
}

/// Whether `e` says the disk (or a quota or file size limit) has no room: a recording
/// that meets it at its start waits for room rather than refusing to start.
pub fn is_out_of_room(e: &super::RecordError) -> bool {
    use std::error::Error as _;
    let mut source: Option<&(dyn std::error::Error + 'static)> = e.source();
    while let Some(s) = source {
        if let Some(io) = s.downcast_ref::<std::io::Error>() {
            use rustix::io::Errno;
            return Errno::from_io_error(io).is_some_and(|e| [Errno::NOSPC, Errno::DQUOT, Errno::FBIG].contains(&e));
        }
        source = s.source();
    }
    false
}

/// A suspended recording: since when, why, and when to try again.
#[derive(Debug, Clone)]
pub(super) struct Outage {
    pub(super) reason: String,
    retry_at_ns: u64,
    backoff_ns: u64,
}

impl Outage {
    pub(super) fn new(log_time: u64, reason: String) -> Outage {
        Outage { reason, retry_at_ns: log_time.saturating_add(RETRY_FIRST_NS), backoff_ns: RETRY_FIRST_NS }
    }

    pub(super) fn retry_due(&self, log_time: u64) -> bool {
        log_time >= self.retry_at_ns
    }

    /// A retry failed: wait twice as long (up to [`RETRY_MAX_NS`]) for the next.
    pub(super) fn retry_failed(&mut self, log_time: u64, reason: String) {
        self.backoff_ns = (self.backoff_ns * 2).min(RETRY_MAX_NS);
        self.retry_at_ns = log_time.saturating_add(self.backoff_ns);
        self.reason = reason;
    }
}

/// One finished (or crash-left) file of the recording, as retention sees it.
struct Kept {
    path: PathBuf,
    index: u32,
    bytes: u64,
    modified: SystemTime,
}

/// The recording's numbered files in `dir` (`STEM-NNNNN.mcap[.part]`), oldest first.
fn numbered_files(dir: &Path, stem: &str) -> Vec<Kept> {
    let prefix = format!("{stem}-");
    let Ok(entries) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut files: Vec<Kept> = entries
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let rest = name.strip_prefix(&prefix)?;
            let number = rest.strip_suffix(".mcap.part").or_else(|| rest.strip_suffix(".mcap"))?;
            let index = number.parse::<u32>().ok()?;
            let meta = e.metadata().ok().filter(|m| m.is_file())?;
            Some(Kept { path: e.path(), index, bytes: meta.len(), modified: meta.modified().ok()? })
        })
        .collect();
    files.sort_by_key(|f| f.index);
    files
}

/// Apply `retention` to the recording's files in `dir`, never deleting `current`: files
/// older than `keep_days` go, then the oldest while the files hold more than `keep_bytes`.
/// Each deletion is logged; the number deleted comes back.
pub(super) fn enforce(dir: &Path, stem: &str, current: Option<&Path>, retention: Retention, now: SystemTime) -> u64 {
    if retention.is_none() {
        return 0;
    }
    let files = numbered_files(dir, stem);
    let mut total: u64 = files.iter().map(|f| f.bytes).sum();
    let max_age = retention.keep_days.map(|d| Duration::from_secs_f64((d * 86_400.0).max(0.0)));
    let mut deleted = 0;
    for f in files.iter().filter(|f| Some(f.path.as_path()) != current) {
        let age = now.duration_since(f.modified).unwrap_or_default();
        let reason = if max_age.is_some_and(|max| age > max) {
            "older than [recording] keep_days"
        } else if retention.keep_bytes.is_some_and(|keep| total > keep) {
            "over [recording] keep_bytes"
        } else {
            continue;
        };
        match std::fs::remove_file(&f.path) {
            Ok(()) => {
                total -= f.bytes;
                deleted += 1;
                tracing::info!(file = %f.path.display(), bytes = f.bytes, "retention: deleted a recording, {reason}");
            }
            Err(e) => tracing::warn!(file = %f.path.display(), "retention: cannot delete: {e}"),
        }
    }
    deleted
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, bytes: usize) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, vec![0u8; bytes]).expect("write");
        p
    }

    #[test]
    fn retention_deletes_the_oldest_whole_files_and_never_the_current_one() {
        let dir = tempfile::tempdir().expect("temp dir");
        let d = dir.path();
        let old = write(d, "forgemon-00002.mcap", 400);
        let part = write(d, "forgemon-00003.mcap.part", 300);
        let newer = write(d, "forgemon-00010.mcap", 200);
        let current = write(d, "forgemon-00011.mcap.part", 500);
        let other = write(d, "notes-00001.mcap", 900);
        let keep = Retention { keep_bytes: Some(900), keep_days: None };
        // 1400 bytes: the two oldest go (1400 → 1000 → 700), in number order, not the name's.
        assert_eq!(enforce(d, "forgemon", Some(&current), keep, SystemTime::now()), 2);
        assert!(!old.exists() && !part.exists());
        assert!(newer.exists() && current.exists() && other.exists());
        // Only the current file would be left over the limit: it stays.
        let tight = Retention { keep_bytes: Some(10), keep_days: None };
        assert_eq!(enforce(d, "forgemon", Some(&current), tight, SystemTime::now()), 1);
        assert!(!newer.exists() && current.exists());
    }

    #[test]
    fn retention_by_age_uses_the_files_last_write() {
        let dir = tempfile::tempdir().expect("temp dir");
        let d = dir.path();
        let a = write(d, "forgemon-00001.mcap", 10);
        let b = write(d, "forgemon-00002.mcap", 10);
        let two_days = SystemTime::now() + Duration::from_secs(2 * 86_400);
        let keep = Retention { keep_bytes: None, keep_days: Some(1.5) };
        assert_eq!(enforce(d, "forgemon", Some(&b), keep, SystemTime::now()), 0);
        assert_eq!(enforce(d, "forgemon", Some(&b), keep, two_days), 1);
        assert!(!a.exists() && b.exists());
    }

    #[test]
    fn retries_back_off_to_the_maximum() {
        let mut o = Outage::new(0, "full".into());
        assert!(!o.retry_due(RETRY_FIRST_NS - 1) && o.retry_due(RETRY_FIRST_NS));
        let mut t = RETRY_FIRST_NS;
        for _ in 0..10 {
            o.retry_failed(t, "still full".into());
            t += o.backoff_ns;
        }
        assert_eq!(o.backoff_ns, RETRY_MAX_NS);
        assert!(o.retry_due(t) && !o.retry_due(t - 1));
    }

    #[test]
    fn free_bytes_of_a_real_directory_are_known() {
        let dir = tempfile::tempdir().expect("temp dir");
        assert!(bytes_free(dir.path()).is_some_and(|b| b > 0));
        assert_eq!(bytes_free(&dir.path().join("missing")), None);
    }
}
