//! `rangeseg render`: a viewable 8-bit PNG of a range file.

use super::info::ReadArgs;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `rangeseg render`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// Range file: ABW Sun rasterfile, PGM, PNG, TIFF or organized PCD.
    #[arg(value_name = "FILE")]
    file: PathBuf,
    /// Output PNG: valid range (0.5–99.5th percentile) as gray 1..255, near = bright, no data black.
    #[arg(short, long, value_name = "OUT.png")]
    output: PathBuf,
    /// Write a Lambertian shading of the surface (light from the upper left) instead of the depth.
    #[arg(long)]
    shade: bool,
    #[command(flatten)]
    read: ReadArgs,
}

/// Runs `rangeseg render`.
pub(crate) fn run(args: Args) -> anyhow::Result<ExitCode> {
    super::prepare_out_file(&args.output)?;
    let frame = rangeio::read(&args.file, &args.read.options())?;
    if args.shade {
        rangeio::png::write_gray_png(&args.output, &features::shade(&frame.range))?;
    } else {
        rangeio::png::write_depth_png(&args.output, &frame.range)?;
    }
    let (w, h) = frame.range.dimensions();
    writeln!(
        std::io::stdout().lock(),
        "wrote {} ({w}x{h}, {:.1}% valid)",
        args.output.display(),
        100.0 * frame.valid_fraction()
    )?;
    Ok(ExitCode::SUCCESS)
}
