//! Command-line interface: one `Command` enum, one file per verb. Each verb's `run` returns
//! the process exit code; only `main` turns errors into one.

use std::path::Path;

use anyhow::Context;
use clap::{Parser, Subcommand};

pub mod advise;
pub mod demo;
pub mod diagnose;
pub mod export;
pub mod history;
pub mod identify;
pub mod import;
pub mod inspect;
pub mod out;
mod progress;
pub mod replay;
pub mod run;
pub mod simulate;
pub mod simulate_device;
pub mod teach;

/// forgemon: blow-by-blow monitoring of gravity drop hammers and screw presses.
#[derive(Debug, Parser)]
#[command(name = "forgemon", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Simulate consecutive blows on a billet (or bare strikes) with the machine model.
    Simulate(simulate::SimulateArgs),
    /// Fit the machine model to reference blows (or bare strikes), with uncertainty.
    Identify(identify::IdentifyArgs),
    /// Find where the model and the measurement part, and which unmodelled effect explains it.
    Diagnose(diagnose::DiagnoseArgs),
    /// Run a recording, capture CSV or capture directory through the live pipeline.
    Replay(replay::ReplayArgs),
    /// Turn capture CSV files or a capture directory into an MCAP recording.
    Import(import::ImportArgs),
    /// Write the blow results of recordings as one table (CSV or Parquet), a row per blow.
    Export(export::ExportArgs),
    /// The quality record: query the history database, or rebuild it from recordings.
    History(history::HistoryArgs),
    /// Say what a recording holds: sources, rates, duration, blows, gaps, drops, alerts.
    Inspect(inspect::InspectArgs),
    /// The always-on service: acquire, segment, estimate, alert, record.
    Run(run::RunArgs),
    /// The service against a simulated hammer over a pty: no hardware needed.
    Demo(demo::DemoArgs),
    /// A simulated hammer or press driving a real transport (a pty), like a DAQ.
    SimulateDevice(simulate_device::SimulateDeviceArgs),
    /// Plan the next blows from the billet's height to a target with the machine model.
    Advise(advise::AdviseArgs),
    /// Learn a part's recipe (windows and an envelope per blow) from good billets.
    Teach(teach::TeachArgs),
}

impl Cli {
    pub fn run(self) -> anyhow::Result<std::process::ExitCode> {
        match self.command {
            Command::Simulate(args) => simulate::run(args),
            Command::Identify(args) => identify::run(args),
            Command::Diagnose(args) => diagnose::run(args),
            Command::Replay(args) => replay::run(args),
            Command::Import(args) => import::run(args),
            Command::Export(args) => export::run(args),
            Command::History(args) => history::run(args),
            Command::Inspect(args) => inspect::run(args),
            Command::Run(args) => run::run(args),
            Command::Demo(args) => demo::run(args),
            Command::SimulateDevice(args) => simulate_device::run(args),
            Command::Advise(args) => advise::run(args),
            Command::Teach(args) => teach::run(args),
        }
    }
}

/// An error and its causes joined by ": ", as `{:#}` joins them, but without a cause the
/// message before it already ends with: errors that print their source in their own
/// message (`RecordError::Io`: "x.mcap: cannot open: No such file or directory (os error
/// 2)") would otherwise say it twice.
pub fn error_message(err: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in err.chain().map(ToString::to_string) {
        if text.ends_with(&cause) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&cause);
    }
    text
}

/// A length option in metres, checked against its physical range (`config::limits`). A
/// value above the range that fits it in millimetres is a unit slip (`--h-now 112` for
/// 112 mm) and the error says so, with the value in metres.
pub(crate) fn length_m(flag: &str, value_m: f64, limits: crate::config::limits::Limits) -> anyhow::Result<f64> {
    if value_m > limits.max && limits.check(value_m / 1e3).is_ok() {
        anyhow::bail!("{flag} {value_m} looks like millimetres; the option takes metres: {}", value_m / 1e3);
    }
    limits.check(value_m).map_err(|why| anyhow::anyhow!("{flag} {value_m}: {why}"))
}

/// Read a text file, naming it in the error.
pub(crate) fn read_text(path: &Path) -> anyhow::Result<String> {
    std::fs::read_to_string(path).with_context(|| format!("{}: cannot read", path.display()))
}

/// Parse a process sheet (docs/interfaces.md §2) and print its warnings (a measured height that
/// rises, kept as measured) to stderr as `forgemon: warning: ...`.
pub(crate) fn parse_process_warn(
    origin: &str,
    text: &str,
) -> Result<crate::physics::process::Process, crate::config::ConfigError> {
    let sheet = crate::config::parse_process_sheet(origin, text)?;
    for w in &sheet.warnings {
        eprintln!("forgemon: warning: {w}");
    }
    Ok(sheet.value)
}

/// Source name of samples read from capture files, before the file's name: each file is a
/// capture of its own (`capture/blow_02.csv`), with its own clock origin and encoder offset
/// (docs/interfaces.md §1), so a new file ends the stream (`pipeline::Feeder`: another source) in a
/// replay of the directory and of its import alike. The path before the name is left out,
/// so a directory replays the same wherever it lies.
pub(crate) const CAPTURE_SOURCE: &str = "capture";

/// The blow files of a capture directory (docs/interfaces.md §1), in blow order.
pub fn capture_dir_files(dir: &Path) -> anyhow::Result<Vec<std::path::PathBuf>> {
    let names = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot list", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()));
    let files: Vec<_> = crate::signal::capture::blow_files(names).into_iter().map(|n| dir.join(n)).collect();
    if files.is_empty() {
        anyhow::bail!("{}: no blow_NN.csv files: not a capture directory", dir.display());
    }
    Ok(files)
}

/// Each batch of a capture file, as the source `CAPTURE_SOURCE/<file name>`.
pub fn for_each_capture_batch(
    path: &Path,
    mut f: impl FnMut(crate::signal::sample::SampleBatch) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    use crate::signal::capture::{CaptureReader, DEFAULT_BATCH_S};
    let file = std::fs::File::open(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let mut reader = CaptureReader::new(path.display().to_string(), std::io::BufReader::new(file), DEFAULT_BATCH_S)?;
    let name = path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned());
    let source = format!("{CAPTURE_SOURCE}/{name}");
    while let Some(mut batch) = reader.next_batch()? {
        batch.source.clone_from(&source);
        f(batch)?;
    }
    Ok(())
}
