//! `rangeseg regions`: multi-seed region growing and its borders C1, as `segment` runs them.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `rangeseg regions`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// Range file: ABW Sun rasterfile, PGM, PNG, TIFF or organized PCD.
    #[arg(value_name = "FILE")]
    file: PathBuf,
    /// Output directory (created if missing); writes NAME.ms-seg, NAME.ms-nor, NAME.labels.png (16-bit,
    /// every region), NAME.c1.png and NAME.regions.png, NAME being the file name without its last extension.
    #[arg(short, long, value_name = "OUTDIR")]
    out: PathBuf,
    /// Configuration file (see `configs/`). The regions are those `segment` grows with it: on the depth as
    /// `[pipeline]` prepares it (dequantised, in working units, decimated), from `[features]` and `[regiongrow]`.
    #[arg(long, value_name = "C.toml")]
    config: Option<PathBuf>,
    /// Seed of the random seed draws [default: the config's `seed`, else 0].
    #[arg(long, value_name = "N")]
    seed: Option<u64>,
    #[command(flatten)]
    read: super::info::ReadArgs,
}

/// Runs `rangeseg regions`.
pub(crate) fn run(args: Args) -> anyhow::Result<ExitCode> {
    let mut cfg = rangeseg::Config::load_or_default(args.config.as_deref())?;
    cfg.seed = args.seed.unwrap_or(cfg.seed);
    super::prepare_out_dir(&args.out)?;
    let frame = rangeio::read(&args.file, &args.read.options())?;
    // The whole method, for the region growing `segment` runs: the same depth preparation, so the same regions
    // (their normals, for the .ms-nor, are already in the input's geometry).
    let out = rangeseg::pipeline::segment(&frame.range, &frame.camera, &cfg);
    let (seg, info) = (&out.regions, &out.regions_info);

    let name =
        args.file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
    let path = |ext: &str| args.out.join(format!("{name}.{ext}"));
    let mapping =
        rangeseg::output::write_segmentation(&path("ms-seg"), &path("ms-nor"), &seg.labels, &seg.regions)?
            .mapping;
    rangeio::png::write_edge_png(&path("c1.png"), &seg.c1)?;
    rangeio::png::write_label_png(&path("regions.png"), &seg.labels)?;

    let kept = mapping.iter().filter(|&&(_, new)| new != 0).count();
    let mut stdout = std::io::stdout().lock();
    writeln!(
        stdout,
        "{}: {} regions ({} written to .ms-seg), {} seeds, {} merged, {} dropped, {} filled px, {} valid px unlabelled",
        args.file.display(),
        info.n_regions,
        kept,
        info.n_seeds,
        info.n_merged,
        info.n_dropped,
        info.n_filled_px,
        info.n_unlabelled_valid_px,
    )?;
    Ok(ExitCode::SUCCESS)
}
