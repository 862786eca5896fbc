//! The `forgemon` binary: parse the command line, run the verb, decide the exit code: 0
//! success, 1 an error (named on stderr), 3 a corrupt input recording whose readable part
//! was processed (`cli::inspect::EXIT_CORRUPT_INPUT`; the verb returns it).

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
