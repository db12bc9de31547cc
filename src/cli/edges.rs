//! `rangeseg edges`: Canny on plane parameters (or raw depth), written as a binary edge PNG.

use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};
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
    /// TOML file with optional `[features]` and `[vcanny]` tables (other tables are ignored).
    #[arg(long, value_name = "C.toml")]
    config: Option<PathBuf>,
}

/// The parts of a config file this command uses.
#[derive(Debug, Default, serde::Deserialize)]
struct EdgeConfig {
    #[serde(default)]
    features: features::Params,
    #[serde(default)]
    vcanny: vcanny::Params,
}

fn load_config(path: &Path) -> anyhow::Result<EdgeConfig> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("{}: cannot read config", path.display()))?;
    let cfg: EdgeConfig =
        toml::from_str(&text).with_context(|| format!("{}: invalid config", path.display()))?;
    cfg.features.validate().map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    cfg.vcanny.validate().map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(cfg)
}

/// Runs `rangeseg edges`.
pub(crate) fn run(args: Args) -> anyhow::Result<ExitCode> {
    let cfg = match &args.config {
        Some(p) => load_config(p)?,
        None => EdgeConfig::default(),
    };
    let frame = rangeio::read(&args.file, &Default::default())?;
    let edges = if args.raw {
        vcanny::detect_raw(&frame.range, &cfg.vcanny)
    } else {
        let plane = features::fit_planes(&frame.range, cfg.features.window_px);
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
