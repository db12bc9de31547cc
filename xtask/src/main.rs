//! `cargo xtask`: project automation (gen-data, tune, eval, tidy).

use xtask::{USAGE, eval, gen_data, project_root, tidy, tune};

fn main() -> std::process::ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_span_events(tracing_subscriber::fmt::format::FmtSpan::CLOSE)
        .with_writer(std::io::stderr)
        .init();
    if let Err(e) = rangeseg::isa::limit_from_env() {
        eprintln!("error: {e}");
        return std::process::ExitCode::FAILURE;
    }
    let args: Vec<String> = std::env::args().skip(1).collect();
    let root = project_root();
    let result = match args.first().map(String::as_str) {
        Some("gen-data") => gen_data::run(&args[1..]),
        Some("eval") => eval::run(&root, &args[1..]),
        Some("tune") => tune::run(&root, &args[1..]),
        Some("tidy") => tidy::run(&root),
        _ => Err(anyhow::anyhow!("{USAGE}")),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
