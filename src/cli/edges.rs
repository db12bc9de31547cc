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
    /// Configuration file (see `configs/`; this command uses `[features]`, `[vcanny]` and, with --raw, `[raw_canny]`).
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
        vcanny::detect_raw(&frame.range, &cfg.raw_canny.detector())
    } else {
        let (range, _) = rangeseg::units::in_working_units(&frame.range, &frame.camera, &cfg);
        let plane = features::fit_planes(&range, cfg.features.window_px);
        let valid = rangeimage::valid_mask(&frame.range);
        vcanny::detect_planes(&plane, &valid, &cfg.vcanny)
    };
    rangeio::png::write_edge_png(&args.output, &edges.edges)?;
    let n = edges.edges.as_slice().iter().filter(|&&e| e).count();
    writeln!(
        std::io::stdout().lock(),
        "wrote {} ({} edge pixels, {})",
        args.output.display(),
        n,
        if args.raw { "raw depth" } else { "plane parameters" }
    )?;
    Ok(ExitCode::SUCCESS)
}
