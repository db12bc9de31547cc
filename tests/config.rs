//! The configuration files: defaults, the paper's config, unknown keys.

use rangeseg::Config;
use std::path::Path;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn default_toml_is_default() {
    let path = root().join("configs/default.toml");
    let config = Config::load(&path).unwrap();
    assert_eq!(config, Config::default(), "configs/default.toml and Config::default() differ");
}

#[test]
fn paper_toml_loads_and_differs_from_default() {
    let config = Config::load(&root().join("configs/paper.toml")).unwrap();
    assert_eq!(config, Config::paper(), "configs/paper.toml and Config::paper() differ");
    assert_ne!(config, Config::default());
    assert_eq!(config.regiongrow.mode, regiongrow::Mode::Paper);
}

#[test]
fn load_or_default_reads_the_file_or_gives_the_defaults() {
    assert_eq!(Config::load_or_default(None).unwrap(), Config::default());
    let paper = root().join("configs/paper.toml");
    assert_eq!(Config::load_or_default(Some(&paper)).unwrap(), Config::paper());
    let missing = root().join("configs/no-such-file.toml");
    let err = Config::load_or_default(Some(&missing)).unwrap_err().to_string();
    assert!(err.contains("no-such-file.toml"), "{err}");
}

#[test]
fn unknown_key_is_an_error_naming_it() {
    let err = Config::from_toml("[regiongrow]\nt_mm = 1.0\n", Path::new("x.toml")).unwrap_err().to_string();
    assert!(err.starts_with("x.toml: "), "{err}");
    assert!(err.contains("t_mm"), "{err}");
}

#[test]
fn round_trips_through_toml() {
    let config = Config::default();
    let back = Config::from_toml(&config.to_toml(), Path::new("x.toml")).unwrap();
    assert_eq!(back, config);
}
