//! `rangeseg regions`.

use std::process::ExitCode;

/// Arguments of `rangeseg regions`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {}

/// Runs `rangeseg regions`.
pub(crate) fn run(_args: Args) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`rangeseg regions` is not implemented yet")
}
