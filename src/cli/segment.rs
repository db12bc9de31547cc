//! `rangeseg segment`.

use std::process::ExitCode;

/// Arguments of `rangeseg segment`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {}

/// Runs `rangeseg segment`.
pub(crate) fn run(_args: Args) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`rangeseg segment` is not implemented yet")
}
