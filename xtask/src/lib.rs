//! Project automation behind `cargo xtask` (gen-data, tune, eval, tidy), as a library so that
//! subcommands and tests can share helpers such as [`gen_data::ensure_synthetic_data`].

pub mod gen_data;

use std::path::{Path, PathBuf};

/// The `cargo xtask` usage text.
pub const USAGE: &str = "usage: cargo xtask <command>

commands:
  gen-data [--out DIR] [--check] [--figures]
      Generate the synthetic ABW-like benchmark (10 train + 30 test) into data/synthetic-abw/
      and its MANIFEST.sha256; --check regenerates and compares with the committed manifest;
      --figures also renders docs/img/synthetic-example-{range,gt}.png";

/// The workspace root (the parent of xtask/).
pub fn project_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("xtask lives in the workspace root").to_path_buf()
}
