//! The `forgemon` binary: parse the command line, run the verb, decide the exit code: 0
//! success, 1 an error (named on stderr), 3 a corrupt input recording whose readable part
//! was processed (`cli::inspect::EXIT_CORRUPT_INPUT`; the verb returns it), 141 standard
//! output closed by its reader (`cli::out::EXIT_STDOUT_CLOSED`, no message).

use std::process::ExitCode;

use clap::Parser;
use forgemon::cli::{Cli, error_message, out};

fn main() -> ExitCode {
    quiet_on_closed_stdout();
    let cli = Cli::parse();
    let result = cli.run();
    if out::closed() || result.as_ref().is_err_and(broken_pipe) {
        // The reader went away: the verb stopped where it was (a demo's recording closed),
        // and the error, if any, is the write that found it gone. Nothing to say, nobody
        // to say it to on stdout.
        return ExitCode::from(out::EXIT_STDOUT_CLOSED);
    }
    match result {
        Ok(code) => code,
        Err(err) => {
            eprintln!("forgemon: error: {}", error_message(&err));
            ExitCode::FAILURE
        }
    }
}

/// An error that ends in EPIPE, from a verb that writes its stdout with `writeln!` and `?`
/// rather than through `cli::out` (simulate, identify, ...). The verbs' other peers
/// (sockets of the service's faces) log their errors and do not return them, so EPIPE here
/// is the reader of stdout gone.
fn broken_pipe(err: &anyhow::Error) -> bool {
    err.chain().any(|e| e.downcast_ref::<std::io::Error>().is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe))
}

/// The verbs not yet printing through `cli::out` use `println!`, which panics when the
/// reader of stdout is gone ("failed printing to stdout: Broken pipe"): that panic ends the
/// process quietly with `EXIT_STDOUT_CLOSED`, as `cli::out` does. Such a verb holds no
/// recording open while it prints; any other panic is reported as before.
fn quiet_on_closed_stdout() {
    let report = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let msg =
            payload.downcast_ref::<String>().map(String::as_str).or_else(|| payload.downcast_ref::<&str>().copied());
        if msg.is_some_and(|m| m.starts_with("failed printing to stdout") && m.contains("Broken pipe")) {
            std::process::exit(out::EXIT_STDOUT_CLOSED.into());
        }
        report(info);
    }));
}
