//! `rangeseg edges`: Canny on plane parameters (or raw depth), written as a binary edge PNG.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `rangeseg edges`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// Range file: ABW Sun rasterfile, PGM, PNG, TIFF or organized PCD.
    #[arg(value_name = "FILE")]
    file: PathBuf,
    /// Output PNG: edge pixels white, the rest black.
    #[arg(short, long, value_name = "EDGES.png")]
    output: PathBuf,
    /// Run Canny on the raw depth instead of the plane parameters (the paper's baseline).
    #[arg(long)]
    raw: bool,
    /// Configuration file (see `configs/`). The plane-parameter edges are the C2 that `segment` finds with it: on the
    /// depth as `[pipeline]` prepares it (dequantised, in working units, decimated), from `[features]` and
    /// `[vcanny]`. With --raw: `[raw_canny]` on the depth as read.
    #[arg(long, value_name = "C.toml")]
    config: Option<PathBuf>,
    #[command(flatten)]
    read: super::info::ReadArgs,
}

/// Runs `rangeseg edges`.
pub(crate) fn run(args: Args) -> anyhow::Result<ExitCode> {
    let cfg = rangeseg::Config::load_or_default(args.config.as_deref())?;
    super::prepare_out_file(&args.output)?;
    let frame = rangeio::read(&args.file, &args.read.options())?;
    let edges = if args.raw {
        vcanny::detect_raw(&frame.range, &cfg.raw_canny.detector()).edges
    } else {
        // The whole method, for the C2 `segment` finds: the same depth preparation, so the same edges.
        rangeseg::pipeline::segment(&frame.range, &frame.camera, &cfg).canny.edges
    };
    rangeio::png::write_edge_png(&args.output, &edges)?;
    let n = edges.as_slice().iter().filter(|&&e| e).count();
    writeln!(
        std::io::stdout().lock(),
        "wrote {} ({} edge pixels, {})",
        args.output.display(),
        n,
        if args.raw { "raw depth" } else { "plane parameters" }
    )?;
    Ok(ExitCode::SUCCESS)
}
