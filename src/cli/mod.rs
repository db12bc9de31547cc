//! Subcommands of the `rangeseg` tool, one module each.

mod config;
mod edges;
mod info;
mod regions;
mod render;
mod score;
mod segment;

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
use std::path::Path;
use std::process::ExitCode;

/// Segment range images (depth images) into surfaces and edges.
#[derive(Debug, Parser)]
#[command(name = "rangeseg", version, about)]
pub(crate) struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Print format, size, camera, valid fraction and value range of range files.
    Info(info::Args),
    /// Write a viewable PNG of a range file.
    Render(render::Args),
    /// Score a segmentation (and optionally an edge map) against ground truth.
    Score(score::Args),
    /// Detect edges with Canny on plane parameters, as `segment` does (C2), or on raw depth.
    Edges(edges::Args),
    /// Segment by multi-seed region growing, as `segment` does, and write the regions and their borders C1.
    Regions(regions::Args),
    /// Run the whole pipeline: regions, edges, relaxation, final segmentation.
    Segment(segment::Args),
    /// Print a complete configuration (the defaults, or the paper's with --paper) as TOML.
    Config(config::Args),
}

/// Runs the parsed command line.
pub(crate) fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Info(a) => info::run(a),
        Command::Render(a) => render::run(a),
        Command::Score(a) => score::run(a),
        Command::Edges(a) => edges::run(a),
        Command::Regions(a) => regions::run(a),
        Command::Segment(a) => segment::run(a),
        Command::Config(a) => config::run(a),
    }
}

/// Makes sure `dir` is a folder we can write into (created if missing), before any work is done.
pub(crate) fn prepare_out_dir(dir: &Path) -> anyhow::Result<()> {
    if dir.exists() && !dir.is_dir() {
        bail!("{}: not a directory (the output of this command is a folder)", dir.display());
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create the output folder", dir.display()))?;
    let probe = dir.join(format!(".rangeseg-probe.{}", std::process::id()));
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
        .with_context(|| format!("{}: cannot write into the output folder", dir.display()))?;
    std::fs::remove_file(&probe).with_context(|| format!("{}: cannot remove", probe.display()))?;
    Ok(())
}

/// Makes sure the output file `path` can be written: its folder is created if missing and must be writable.
pub(crate) fn prepare_out_file(path: &Path) -> anyhow::Result<()> {
    if path.is_dir() {
        bail!("{}: is a directory (expected an output file name)", path.display());
    }
    match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => prepare_out_dir(parent),
        _ => prepare_out_dir(Path::new(".")),
    }
}
