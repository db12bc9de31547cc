//! `rangeseg render`.

use std::process::ExitCode;

/// Arguments of `rangeseg render`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {}

/// Runs `rangeseg render`.
pub(crate) fn run(_args: Args) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`rangeseg render` is not implemented yet")
}
