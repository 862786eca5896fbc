//! The progress of reading recordings (`replay` of a file or of a rotated run's directory):
//! bytes read of all the files' bytes, the rate, the time left and the file being read.
//!
//! Drawn on stderr when stderr is a terminal and stdout is not: `forgemon replay DIR >
//! day.jsonl` shows it, while a table printed on the terminal is its own progress and a
//! pipe or a log file gets nothing. Hidden, it costs nothing.

use std::io::IsTerminal;
use std::path::Path;

use indicatif::{ProgressBar, ProgressStyle};

pub(crate) struct Progress {
    bar: Option<ProgressBar>,
    /// Bytes of the files already read.
    done: u64,
    /// The size of the file being read.
    current: u64,
}

impl Progress {
    /// A bar over `files`, if there is a terminal to draw it on.
    pub fn over<'a>(files: impl IntoIterator<Item = &'a Path>) -> Progress {
        let drawn = std::io::stderr().is_terminal() && !std::io::stdout().is_terminal();
        let bar = drawn.then(|| {
            let total = files.into_iter().map(|p| std::fs::metadata(p).map_or(0, |m| m.len())).sum();
            let bar = ProgressBar::new(total);
            bar.set_style(
                ProgressStyle::with_template(
                    "replay {msg} {bar:20} {binary_bytes}/{binary_total_bytes} {binary_bytes_per_sec} eta {eta}",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            bar
        });
        Progress { bar, done: 0, current: 0 }
    }

    /// Nothing drawn.
    pub fn hidden() -> Progress {
        Progress { bar: None, done: 0, current: 0 }
    }

    /// Reading `path` begins.
    pub fn file(&mut self, path: &Path) {
        if let Some(bar) = &self.bar {
            self.current = std::fs::metadata(path).map_or(0, |m| m.len());
            bar.set_message(path.file_name().map_or(String::new(), |n| n.to_string_lossy().into_owned()));
            bar.set_position(self.done);
        }
    }

    /// `bytes` of the file being read are read.
    pub fn at(&self, bytes: u64) {
        if let Some(bar) = &self.bar {
            bar.set_position(self.done + bytes.min(self.current));
        }
    }

    /// The file being read is read to its end (or given up).
    pub fn file_done(&mut self) {
        self.done += std::mem::take(&mut self.current);
        self.at(0);
    }

    /// Print a line on stderr without tearing the bar.
    pub fn say(&self, line: std::fmt::Arguments<'_>) {
        match &self.bar {
            Some(bar) => bar.suspend(|| eprintln!("{line}")),
            None => eprintln!("{line}"),
        }
    }

    /// The bar goes; what is printed after stays.
    pub fn clear(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
