//! `rangeseg edges`.

use std::process::ExitCode;

/// Arguments of `rangeseg edges`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {}

/// Runs `rangeseg edges`.
pub(crate) fn run(_args: Args) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`rangeseg edges` is not implemented yet")
}
