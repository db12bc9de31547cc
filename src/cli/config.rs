//! `rangeseg config`: print a complete configuration file to start from.

use std::process::ExitCode;

/// Arguments of `rangeseg config`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// Print the paper-faithful configuration instead of the defaults.
    #[arg(long)]
    paper: bool,
}

/// Runs `rangeseg config`.
pub(crate) fn run(args: Args) -> anyhow::Result<ExitCode> {
    let config = if args.paper { rangeseg::Config::paper() } else { rangeseg::Config::default() };
    std::io::Write::write_all(&mut std::io::stdout().lock(), config.to_commented_toml().as_bytes())?;
    Ok(ExitCode::SUCCESS)
}
