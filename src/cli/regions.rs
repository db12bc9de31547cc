//! `rangeseg regions`: multi-seed region growing and its borders C1.

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
    /// Configuration file (see `configs/`; this command uses `seed`, `[features]` and `[regiongrow]`).
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
    let cfg = rangeseg::Config::load_or_default(args.config.as_deref())?;
    let seed = args.seed.unwrap_or(cfg.seed);
    super::prepare_out_dir(&args.out)?;
    let frame = rangeio::read(&args.file, &args.read.options())?;
    let (range, units) = rangeseg::units::in_working_units(&frame.range, &frame.camera, &cfg);
    let feats = features::compute(&range, &cfg.features);
    let (mut seg, info) = regiongrow::grow(&range, &feats, &units.camera, &cfg.regiongrow, seed);
    // The normals the .ms-nor holds, in the input's geometry.
    units.input_normals(&mut seg.regions);

    let name =
        args.file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
    let path = |ext: &str| args.out.join(format!("{name}.{ext}"));
    let mapping =
        rangeseg::output::write_segmentation(&path("ms-seg"), &path("ms-nor"), &seg.labels, &seg.regions)?
            .mapping;
    rangeio::png::write_edge_png(&path("c1.png"), &seg.c1)?;
    rangeio::png::write_label_png(&path("regions.png"), &seg.labels)?;

    let kept = mapping.iter().filter(|&&(_, new)| new != 0).count();
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
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
