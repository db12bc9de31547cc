//! `rangeseg score`.

use std::process::ExitCode;

/// Arguments of `rangeseg score`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {}

/// Runs `rangeseg score`.
pub(crate) fn run(_args: Args) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`rangeseg score` is not implemented yet")
}
