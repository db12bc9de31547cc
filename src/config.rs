//! The configuration that ties the stages together: `configs/*.toml` into one struct.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Which per-pixel quantity gives a C1 point its strength s1 in the relaxation energy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum C1Strength {
    /// |K|, the magnitude of Gaussian curvature (the paper).
    AbsK,
    /// Curvedness `sqrt((k1² + k2²)/2)`: non-zero on creases, where K vanishes.
    #[default]
    Curvedness,
}

/// What the final edge map C is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum FinalEdges {
    /// The relaxed edge sets: C1 ∪ the supported relaxed C2 (the paper; C1 and C2 often run as two
    /// parallel lines along one boundary).
    Relaxed,
    /// The borders between the final segmentation's regions ([`eval::boundary::label_boundaries`], every
    /// non-zero label a region): one boundary per pair of final regions, shaped by both edge sets through
    /// the segmentation.
    #[default]
    Segmentation,
}

/// Pipeline-level options that belong to no single stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PipelineParams {
    /// Strength of C1 points in the relaxation energy.
    pub c1_strength: C1Strength,
    /// Run the relaxation (false: the relaxed edge sets are C1 and C2 as detected).
    pub relax: bool,
    /// What the final edge map C is.
    pub final_edges: FinalEdges,
}

impl Default for PipelineParams {
    fn default() -> Self {
        Self { c1_strength: C1Strength::default(), relax: true, final_edges: FinalEdges::default() }
    }
}

/// The whole configuration: one table per stage, as in `configs/default.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// Seed of every random choice (region seeds, annealing moves).
    pub seed: u64,
    /// Options of the pipeline itself.
    pub pipeline: PipelineParams,
    /// Local planes, derivatives and curvatures.
    pub features: features::Params,
    /// Canny on plane parameters (C2).
    pub vcanny: vcanny::Params,
    /// The raw-depth Canny baseline of Table I (same detector, one channel, its own thresholds).
    pub raw_canny: vcanny::Params,
    /// Multi-seed region growing (regions and C1).
    pub regiongrow: regiongrow::Params,
    /// Simulated-annealing relaxation of C1 and C2.
    pub relax: relax::Params,
    /// Final segmentation from the relaxed edge map.
    pub segment: relax::SegmentParams,
}

/// A configuration file that could not be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{}: {error}", path.display())]
    Io {
        /// The configuration file.
        path: PathBuf,
        /// The underlying error (its text is part of the message, so it is not chained as a source:
        /// `{:#}` would print it twice).
        error: std::io::Error,
    },
    /// The file is not valid TOML or has unknown keys or wrong types.
    #[error("{}: {message}", path.display())]
    Parse {
        /// The configuration file.
        path: PathBuf,
        /// What the parser said, with the key and line.
        message: String,
    },
    /// A value is out of its allowed range.
    #[error("{}: [{table}] {message}", path.display())]
    Invalid {
        /// The configuration file.
        path: PathBuf,
        /// The table holding the bad value.
        table: &'static str,
        /// What is wrong.
        message: String,
    },
}

impl Default for Config {
    fn default() -> Self {
        Self {
            seed: 0,
            pipeline: PipelineParams::default(),
            features: features::Params::default(),
            vcanny: vcanny::Params::default(),
            raw_canny: vcanny_raw_preset(),
            regiongrow: regiongrow::Params::default(),
            relax: relax::Params::default(),
            segment: relax::SegmentParams::default(),
        }
    }
}

impl Config {
    /// The configuration faithful to the paper (`configs/paper.toml`): Gaussian-curvature growth, |K| as the
    /// strength of C1 points, no final support test of C2, the final segmentation as plain connected
    /// components of the non-edge pixels, the relaxed edge sets as the final edge map, and Canny thresholds chosen
    /// as the paper chose its parameters (the highest precision of C2 against C1, on the real ABW images that stand
    /// in for its training set).
    pub fn paper() -> Self {
        let mut c = Self::default();
        c.vcanny.thresholds.low = 32.0;
        c.vcanny.thresholds.high = 64.0;
        c.pipeline.c1_strength = C1Strength::AbsK;
        c.pipeline.final_edges = FinalEdges::Relaxed;
        c.relax.support_px = 0.0;
        c.regiongrow = regiongrow::Params::paper();
        c.segment.mode = relax::SegmentMode::Components;
        // Plain components have no region-growing borders to close their contours.
        c.segment.gap_close_px = 2.0;
        c.segment.min_region_px = 50;
        // The specification fills every left-over pixel.
        c.segment.fill_max_residual = 0.0;
        c
    }

    /// Reads and validates a TOML configuration file.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let text =
            std::fs::read_to_string(path).map_err(|error| ConfigError::Io { path: path.into(), error })?;
        Self::from_toml(&text, path)
    }

    /// Reads `path` when given ([`Config::load`]), otherwise returns the defaults.
    pub fn load_or_default(path: Option<&Path>) -> Result<Config, ConfigError> {
        path.map_or_else(|| Ok(Config::default()), Self::load)
    }

    /// Parses and validates TOML text; `path` only names the source in errors.
    pub fn from_toml(text: &str, path: &Path) -> Result<Config, ConfigError> {
        let config: Config = toml::from_str(text)
            .map_err(|e| ConfigError::Parse { path: path.into(), message: e.to_string() })?;
        config.validate(path)?;
        Ok(config)
    }

    /// Builds a configuration from a TOML table (used by the tuning grid), validated.
    pub fn from_table(table: toml::Table, path: &Path) -> Result<Config, ConfigError> {
        let config: Config = toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| ConfigError::Parse { path: path.into(), message: e.to_string() })?;
        config.validate(path)?;
        Ok(config)
    }

    /// Checks every stage's values; the error names the table and the problem.
    pub fn validate(&self, path: &Path) -> Result<(), ConfigError> {
        let bad = |table: &'static str| {
            move |message: String| ConfigError::Invalid { path: path.into(), table, message }
        };
        self.features.validate().map_err(bad("features"))?;
        self.vcanny.validate().map_err(bad("vcanny"))?;
        self.raw_canny.validate().map_err(bad("raw_canny"))?;
        self.regiongrow.validate().map_err(bad("regiongrow"))?;
        self.relax.validate().map_err(bad("relax"))?;
        self.segment.validate().map_err(bad("segment"))?;
        Ok(())
    }

    /// The configuration as TOML text (what `configs/default.toml` holds).
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("a Config always serialises")
    }
}

/// The raw-depth Canny baseline's thresholds (2 and 4 times the noise level of the magnitude), the best found on
/// the training split by `cargo run --release --example table1 -- --tune`.
fn vcanny_raw_preset() -> vcanny::Params {
    vcanny::Params {
        thresholds: vcanny::Thresholds {
            mode: vcanny::ThresholdMode::NoiseRelative,
            low: 2.0,
            high: 4.0,
            ..Default::default()
        },
        ..Default::default()
    }
}
