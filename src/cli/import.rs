//! `forgemon import`: capture CSV files or capture directories (docs/interfaces.md §1–2) into an
//! MCAP recording that `replay` and `inspect` read, with the process sheet (and, if given,
//! the machine model) stored in it.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::Args;

use super::{parse_process_warn, read_text};
use crate::config::parse_machine;
use crate::record::{RecordWriter, Rotation};

#[derive(Debug, Args)]
pub struct ImportArgs {
    /// A capture CSV or a capture directory (blow_01.csv, ..., process.toml).
    pub input: PathBuf,
    /// The recording to write.
    #[arg(short, long)]
    pub out: PathBuf,
    /// A machine model to store in the recording too.
    #[arg(long)]
    pub machine: Option<PathBuf>,
    /// A process sheet to store (defaults to the directory's process.toml).
    #[arg(long)]
    pub process: Option<PathBuf>,
}

pub fn run(args: ImportArgs) -> anyhow::Result<ExitCode> {
    let files: Vec<PathBuf> =
        if args.input.is_dir() { super::capture_dir_files(&args.input)? } else { vec![args.input.clone()] };
    let process = args
        .process
        .clone()
        .or_else(|| Some(args.input.join("process.toml")).filter(|p| args.input.is_dir() && p.exists()));
    // Check the files before anything is written.
    let machine_text = args.machine.as_ref().map(|m| read_text(m).map(|t| (m, t))).transpose()?;
    if let Some((m, t)) = &machine_text {
        parse_machine(&m.display().to_string(), t)?;
    }
    let process_text = process.as_ref().map(|p| read_text(p).map(|t| (p, t))).transpose()?;
    if let Some((p, t)) = &process_text {
        parse_process_warn(&p.display().to_string(), t)?;
    }
    let mut w = RecordWriter::create(&args.out, Rotation::default())
        .with_context(|| format!("{}: cannot record", args.out.display()))?;
    if let Some((_, t)) = &machine_text {
        w.write_config(0, "machine.toml", t)?;
    }
    if let Some((_, t)) = &process_text {
        w.write_config(0, "process.toml", t)?;
    }
    let mut samples = 0u64;
    for path in &files {
        super::for_each_capture_batch(path, |batch| {
            samples += batch.len() as u64;
            Ok(w.write_samples(&batch)?)
        })?;
    }
    for f in w.finish()? {
        eprintln!("forgemon: imported {samples} samples from {} file(s) into {}", files.len(), f.display());
    }
    Ok(ExitCode::SUCCESS)
}
