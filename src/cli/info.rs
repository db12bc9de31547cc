//! `rangeseg info`.

use std::process::ExitCode;

/// Arguments of `rangeseg info`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {}

/// Runs `rangeseg info`.
pub(crate) fn run(_args: Args) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`rangeseg info` is not implemented yet")
}
