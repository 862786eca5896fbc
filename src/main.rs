//! The `forgemon` binary: parse the command line, run the verb, decide the exit code.

use std::process::ExitCode;

use clap::Parser;
use forgemon::cli::Cli;

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.run() {
        Ok(code) => code,
        Err(err) => {
            eprintln!("forgemon: error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
