//! Project automation behind `cargo xtask` (gen-data, tune, eval, tidy), as a library so that
//! subcommands and tests can share helpers such as [`gen_data::ensure_synthetic_data`].

pub mod data;
pub mod eval;
pub mod gen_data;
mod report;
mod seeds;
pub mod tidy;
pub mod tune;

use std::path::{Path, PathBuf};

/// The `cargo xtask` usage text.
pub const USAGE: &str = "usage: cargo xtask <command>

commands:
  eval [--config C.toml] [--data DIR|synthetic|synthetic:FAMILY[@S] [--camera CAM] [--depth-scale M]] [--out DIR]
      Run one data set (default: the synthetic benchmark's test split, generated on first use;
      synthetic:FAMILY the 20 test images of an artefact family (abw, stripes, staircase, kinect, disparity) at strength S
      (default 1), generated into target/synthetic/FAMILY-sS/ on every use; a folder of
      ABW files gives its test split; any other folder every STEM.range with a STEM.gt-seg, which needs
      --camera unless the names are ABW names) and write target/eval/report.{md,html}, results.{csv,json}
      and figures
  tune [--grid configs/tune.toml] [--objective NAME] [--data DIR|synthetic [--camera CAM]]... [--write]
      Sweep the grid over one or more data sets (default: the synthetic training split; a folder without a
      training split gives every labelled image); one objective, the mean over the sets; write
      target/tune/{results.csv,best.toml,report.md}; --write also updates configs/default.toml
  gen-data [--out DIR] [--check] [--figures] [--family NAME [--strength S]]
      Generate the synthetic ABW-like benchmark (10 train + 30 test) into data/synthetic-abw/
      and its MANIFEST.sha256; --check regenerates and compares with the committed manifest;
      --figures also renders docs/img/synthetic-example-{range,gt}.png; --family writes an artefact
      family set (10 train + 20 test) into target/synthetic/NAME-sS/ (or --out)
  tidy
      Check the source tree: `//!` doc lines, workspace lints, stage crate dependencies";

/// `path` relative to the workspace `root` when it lies inside it, for reports (they name no machine's directories).
pub fn shown(root: &Path, path: &Path) -> String {
    path.strip_prefix(root).unwrap_or(path).display().to_string()
}

/// The workspace root (the parent of xtask/).
pub fn project_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("xtask lives in the workspace root").to_path_buf()
}
