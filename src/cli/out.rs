//! Standard output for the verbs' results, where a reader that goes away
//! (`forgemon demo | head -1`) is a quiet stop, not a panic. Rust ignores SIGPIPE, so a
//! closed pipe shows as EPIPE on the next write, and `println!` panics on it (exit 101,
//! and a demo's recording left as `.mcap.part`). Writes through here fail instead, and note
//! that the reader is gone; the verb stops as it would on Ctrl-C, and `main` ends the
//! process with `EXIT_STDOUT_CLOSED` and no message.

use std::io::{self, Write};
use std::sync::atomic::{AtomicBool, Ordering};

/// The exit status once standard output was closed: 141 = 128 + SIGPIPE (13), what `cat`
/// or `grep` end with when the reader goes away (killed by the signal). A script under
/// `set -o pipefail` so sees that the output was cut short, as it would from them; a plain
/// pipeline takes the status of its last command (`head`), unchanged.
pub const EXIT_STDOUT_CLOSED: u8 = 141;

/// Set by the first write that found the reader gone.
static CLOSED: AtomicBool = AtomicBool::new(false);

/// Whether a write to standard output found its reader gone.
pub fn closed() -> bool {
    CLOSED.load(Ordering::Relaxed)
}

/// Standard output as a writer that notes a closed reader (`closed`).
pub struct Stdout(io::Stdout);

/// Standard output, noting a closed reader.
pub fn stdout() -> Stdout {
    Stdout(io::stdout())
}

fn note<T>(r: io::Result<T>) -> io::Result<T> {
    if let Err(e) = &r
        && e.kind() == io::ErrorKind::BrokenPipe
    {
        CLOSED.store(true, Ordering::Relaxed);
    }
    r
}

impl Write for Stdout {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        note(self.0.write(buf))
    }
    fn flush(&mut self) -> io::Result<()> {
        note(self.0.flush())
    }
}

/// One line to standard output (`outln!`), flushed: an error when the reader is gone.
pub fn line(args: std::fmt::Arguments<'_>) -> io::Result<()> {
    let mut lock = io::stdout().lock();
    note(writeln!(lock, "{args}").and_then(|()| lock.flush()))
}

/// `println!` that returns `io::Result<()>` instead of panicking (`out::line`).
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::cli::out::line(format_args!($($arg)*))
    };
}
pub(crate) use outln;
