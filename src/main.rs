//! The `rangeseg` command-line tool.

mod cli;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    init_tracing();
    if let Err(e) = rangeseg::isa::limit_from_env() {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    let args = cli::Cli::parse();
    exit_cleanly_on_signals();
    match cli::run(args) {
        Ok(code) => code,
        // A closed pipe (`rangeseg score --json … | head`) ends the output; nothing is wrong.
        Err(err) if is_broken_pipe(&err) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

/// Whether the error comes from writing to a closed standard output.
fn is_broken_pipe(err: &anyhow::Error) -> bool {
    err.chain().any(|e| {
        e.downcast_ref::<std::io::Error>().is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// Logs to stderr at level `warn` (so warnings such as regions lost to the `.ms-seg` cap are seen);
/// `RUST_LOG` overrides (e.g. `RUST_LOG=info`, `RUST_LOG=off`).
fn init_tracing() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_target(false).init();
}

/// On SIGINT or SIGTERM (or SIGHUP): remove the temporary files of the writes in flight, block new
/// writes, and exit with 128 + the signal's number. Each image's `NAME.json` is written last, so an
/// image without one is incomplete.
fn exit_cleanly_on_signals() {
    #[cfg(unix)]
    {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        let mut signals = match signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!(
                    "cannot install the signal handler ({e}): an interrupt may leave temporary files"
                );
                return;
            }
        };
        std::thread::spawn(move || {
            if let Some(sig) = signals.forever().next() {
                let removed = rangeio::abort_writes();
                eprintln!(
                    "\ninterrupted: removed {removed} temporary file(s) being written; \
                     an image whose NAME.json is missing has incomplete outputs"
                );
                std::process::exit(128 + sig);
            }
        });
    }
}
