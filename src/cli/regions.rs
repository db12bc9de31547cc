//! `rangeseg regions`: multi-seed region growing and its borders C1.

use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Arguments of `rangeseg regions`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// Range file: ABW Sun rasterfile, PGM, PNG, TIFF or organized PCD.
    #[arg(value_name = "FILE")]
    file: PathBuf,
    /// Output directory (created if missing); writes NAME.ms-seg, NAME.ms-nor, NAME.c1.png and
    /// NAME.regions.png, NAME being the file name without its last extension.
    #[arg(short, long, value_name = "OUTDIR")]
    out: PathBuf,
    /// TOML file with optional `seed`, `[features]` and `[regiongrow]` tables (other tables are ignored).
    #[arg(long, value_name = "C.toml")]
    config: Option<PathBuf>,
    /// Seed of the random seed draws [default: the config's `seed`, else 0].
    #[arg(long, value_name = "N")]
    seed: Option<u64>,
    #[command(flatten)]
    read: super::info::ReadArgs,
}

/// The parts of a config file this subcommand reads.
#[derive(Debug, Default, serde::Deserialize)]
#[serde(default)]
struct RegionsConfig {
    seed: u64,
    features: features::Params,
    regiongrow: regiongrow::Params,
}

fn load_config(path: Option<&Path>) -> anyhow::Result<RegionsConfig> {
    let Some(path) = path else { return Ok(RegionsConfig::default()) };
    let text = std::fs::read_to_string(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let cfg: RegionsConfig =
        toml::from_str(&text).with_context(|| format!("{}: bad config", path.display()))?;
    cfg.features.validate().map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    cfg.regiongrow.validate().map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(cfg)
}

/// Runs `rangeseg regions`.
pub(crate) fn run(args: Args) -> anyhow::Result<ExitCode> {
    let cfg = load_config(args.config.as_deref())?;
    let seed = args.seed.unwrap_or(cfg.seed);
    let frame = rangeio::read(&args.file, &args.read.options())?;
    let feats = features::compute(&frame.range, &cfg.features);
    let (seg, info) = regiongrow::grow(&frame.range, &feats, &frame.camera, &cfg.regiongrow, seed);

    std::fs::create_dir_all(&args.out).with_context(|| format!("{}: cannot create", args.out.display()))?;
    let name =
        args.file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
    let path = |ext: &str| args.out.join(format!("{name}.{ext}"));
    let mapping = rangeio::abw::write_labels(&path("ms-seg"), &seg.labels)?;
    let normals: Vec<(u32, [f32; 3])> = mapping
        .iter()
        .filter(|&&(_, new)| new != 0)
        .filter_map(|&(old, new)| {
            let r = seg.regions.get(old.checked_sub(1)? as usize)?;
            Some((u32::from(new), r.normal))
        })
        .collect();
    rangeio::abw::write_normals(&path("ms-nor"), &normals)?;
    rangeio::png::write_edge_png(&path("c1.png"), &seg.c1)?;
    rangeio::png::write_label_png(&path("regions.png"), &seg.labels)?;

    let kept = normals.len();
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
