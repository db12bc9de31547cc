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
    /// The borders between the final segmentation's regions ([`rangeimage::boundary::label_boundaries`], every
    /// non-zero label a region, after the gaps of [`PipelineParams::edge_gap_px`] are split): one boundary per
    /// pair of final regions, shaped by both edge sets through the segmentation.
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
    /// With `final_edges = segmentation`: valid unlabelled pixels within this many pixels of a region are given to the
    /// nearest one, or to the one whose plane clearly fits them, before the borders are drawn
    /// ([`finalseg::edge_labels_into`]; 0 = off).
    pub edge_gap_px: u32,
    /// Run pinhole images (and grid images of unusual noise) in working units of a fixed noise level ([`crate::units`]).
    pub normalize_units: bool,
    /// Dequantise depth rounded to steps coarser than its noise before the stages run ([`crate::dequantise`]).
    pub dequantise: bool,
    /// Run the stages on the frame averaged over blocks of this many pixels a side, and carry the labels back to
    /// every pixel by their planes ([`crate::decimate`]; pinhole cameras only; 1 = off).
    pub decimate: u32,
}

impl Default for PipelineParams {
    fn default() -> Self {
        Self {
            c1_strength: C1Strength::default(),
            relax: true,
            final_edges: FinalEdges::default(),
            edge_gap_px: 2,
            normalize_units: true,
            dequantise: true,
            decimate: 1,
        }
    }
}

/// The largest `pipeline.decimate`.
pub const MAX_DECIMATE: u32 = 4;

/// The whole configuration: one table per stage, as in `configs/default.toml`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
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
    pub raw_canny: RawCannyParams,
    /// Multi-seed region growing (regions and C1).
    pub regiongrow: regiongrow::Params,
    /// Simulated-annealing relaxation of C1 and C2.
    pub relax: relax::Params,
    /// Final segmentation from the relaxed edge map.
    pub segment: finalseg::Params,
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
    #[error("{}: [{table}] {error}", path.display())]
    Invalid {
        /// The configuration file.
        path: PathBuf,
        /// The table holding the bad value.
        table: &'static str,
        /// The field and what is wrong with it.
        error: rangeimage::ParamError,
    },
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
        c.pipeline.dequantise = false;
        c.relax.support_px = 0.0;
        c.regiongrow = regiongrow::Params::paper();
        c.segment.mode = finalseg::Mode::Components;
        // Plain components have no region-growing borders to close their contours.
        c.segment.gap_close_px = 2.0;
        c.segment.min_region_px = 50;
        // The specification fills every left-over pixel.
        c.segment.fill_max_residual = 0.0;
        c.segment.refine_passes = 0;
        c.segment.refine_steep_cos = 0.0;
        c.segment.crease_passes = 0;
        c.segment.band_max_angle_deg = 0.0;
        c.segment.outlier_scales = 0.0;
        c.segment.curved_merge_ratio = 0.0;
        c.segment.small_face_min_px = 0;
        c.segment.bend_max_angle_deg = 0.0;
        c.segment.terrace_gap_steps = 0.0;
        c.segment.within_joint_rms_ratio = 0.0;
        c.segment.within_close_px = 0;
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
        if config.raw_canny.weights.is_some() {
            tracing::warn!(
                "{}: [raw_canny] weights is deprecated and ignored (the raw-depth detector has one channel)",
                path.display()
            );
        }
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
            move |error: rangeimage::ParamError| ConfigError::Invalid { path: path.into(), table, error }
        };
        rangeimage::ParamError::in_range("pipeline.decimate", self.pipeline.decimate, 1, MAX_DECIMATE)
            .map_err(bad("pipeline"))?;
        self.features.validate().map_err(bad("features"))?;
        self.vcanny.validate().map_err(bad("vcanny"))?;
        self.raw_canny.detector().validate().map_err(bad("raw_canny"))?;
        self.regiongrow.validate().map_err(bad("regiongrow"))?;
        self.relax.validate().map_err(bad("relax"))?;
        self.segment.validate().map_err(bad("segment"))?;
        Ok(())
    }

    /// The configuration as TOML text.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("a Config always serialises")
    }

    /// [`to_toml`](Self::to_toml) with a one-line comment above every table and key (`KEY_DOCS`):
    /// what `configs/default.toml` holds and `rangeseg config` prints.
    pub fn to_commented_toml(&self) -> String {
        let mut out = String::new();
        let mut table = String::new();
        for line in self.to_toml().lines() {
            let t = line.trim();
            let key = if let Some(name) = t.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
                table = name.to_owned();
                Some(table.clone())
            } else {
                t.split_once(" = ")
                    .map(|(k, _)| if table.is_empty() { k.to_owned() } else { format!("{table}.{k}") })
            };
            if let Some(doc) = key.as_deref().and_then(key_doc) {
                out.push_str("# ");
                out.push_str(doc);
                out.push('\n');
            }
            out.push_str(line);
            out.push('\n');
        }
        out
    }
}

/// The raw-depth Canny baseline's thresholds (2 and 4 times the noise level of the magnitude), the best found on
/// the training split by `cargo run --release --example table1 -- --tune`.
/// The `[raw_canny]` table: the raw-depth Canny baseline of Table I. It runs the detector of `[vcanny]` on one
/// channel (the depth), so it has no channel weights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RawCannyParams {
    /// Gaussian σ in pixels.
    pub sigma_px: f32,
    /// Gaussian kernel width in pixels (odd).
    pub kernel_px: u32,
    /// Hysteresis thresholds.
    pub thresholds: vcanny::Thresholds,
    /// Deprecated and ignored (the one depth channel has weight 1); read so that older files still load,
    /// with a warning, and never written.
    #[serde(skip_serializing)]
    pub weights: Option<[f32; 3]>,
}

impl Default for RawCannyParams {
    fn default() -> Self {
        let v = vcanny::Params::default();
        Self {
            sigma_px: v.sigma_px,
            kernel_px: v.kernel_px,
            thresholds: vcanny::Thresholds {
                mode: vcanny::ThresholdMode::NoiseRelative,
                low: 2.0,
                high: 4.0,
                ..Default::default()
            },
            weights: None,
        }
    }
}

impl RawCannyParams {
    /// The detector's parameters for `vcanny::detect_raw` (the channel weights of `vcanny::Params` are
    /// not read by it).
    pub fn detector(&self) -> vcanny::Params {
        vcanny::Params {
            sigma_px: self.sigma_px,
            kernel_px: self.kernel_px,
            thresholds: self.thresholds.clone(),
            ..vcanny::Params::default()
        }
    }
}

/// One-line comments of every key of the configuration file, by `table.key` (`key` for the top
/// level), written above each key by [`Config::to_commented_toml`]. The tables hold the stage
/// parameters; the Rust docs of each `Params` field say more.
const KEY_DOCS: &[(&str, &str)] = &[
    ("seed", "Seed of every random choice (region seeds, annealing moves)."),
    ("pipeline", "Options of the pipeline itself."),
    (
        "pipeline.c1_strength",
        "Strength s1 of C1 points in the relaxation energy: \"curvedness\" or \"abs_k\" (|K|, the paper).",
    ),
    ("pipeline.relax", "Run the relaxation (false: the relaxed edge sets are C1 and C2 as detected)."),
    (
        "pipeline.final_edges",
        "Final edge map C: \"segmentation\" (the final regions' borders) or \"relaxed\" (C1 ∪ supported C2, the paper).",
    ),
    (
        "pipeline.edge_gap_px",
        "Final edge map \"segmentation\": unlabelled pixels within this many pixels of a region go to the nearest one, or to the one whose plane clearly fits them, before the borders are drawn (0 = off).",
    ),
    (
        "pipeline.normalize_units",
        "Scale pinhole depth to a noise σ of 0.25 (and grid depth outside σ 0.25–1) so distances mean the same in any unit.",
    ),
    (
        "pipeline.dequantise",
        "Dequantise depth rounded to steps above its noise (a staircase on every slope) before the stages run.",
    ),
    (
        "pipeline.decimate",
        "Run the stages on the frame averaged over blocks of this many pixels a side (1 = off; 2: a Kinect frame about 2.7 times faster, loses faces of a few hundred pixels; pinhole cameras only).",
    ),
    ("features", "Local planes, derivatives and curvatures (window sides in pixels, odd)."),
    ("features.window_px", "Window of the local plane fit (odd, ≥ 3)."),
    ("features.deriv_window_px", "Window of the quadratic (derivative) fit (odd, ≥ 3)."),
    ("features.k_std_window_px", "Window of the standard deviation of K (odd, ≥ 1)."),
    ("vcanny", "Canny on the plane parameters (C2)."),
    ("vcanny.sigma_px", "Standard deviation of the Gaussian smoothing, in pixels."),
    ("vcanny.kernel_px", "Side of the Gaussian mask (odd)."),
    (
        "vcanny.weights",
        "Weights of the plane channels [a, b, c] in the structure tensor (c, the intercept, is noisy).",
    ),
    ("vcanny.thresholds", "Hysteresis thresholds."),
    (
        "vcanny.thresholds.mode",
        "How low and high are read: \"noise_relative\" (multiples of the noise estimate), \"absolute\" or \"quantile\".",
    ),
    ("vcanny.thresholds.low", "Weak threshold: edge pixels connected to a strong one need at least this."),
    ("vcanny.thresholds.high", "Strong threshold: edges start at pixels with at least this."),
    (
        "vcanny.thresholds.noise_floor",
        "Lower bound of the noise estimate in noise_relative mode (noise-free images).",
    ),
    ("raw_canny", "The raw-depth Canny baseline of Table I: the same detector on the depth alone."),
    ("raw_canny.sigma_px", "Standard deviation of the Gaussian smoothing, in pixels."),
    ("raw_canny.kernel_px", "Side of the Gaussian mask (odd)."),
    ("raw_canny.thresholds", "Hysteresis thresholds."),
    (
        "raw_canny.thresholds.mode",
        "How low and high are read: \"noise_relative\", \"absolute\" or \"quantile\".",
    ),
    ("raw_canny.thresholds.low", "Weak threshold."),
    ("raw_canny.thresholds.high", "Strong threshold."),
    ("raw_canny.thresholds.noise_floor", "Lower bound of the noise estimate in noise_relative mode."),
    ("regiongrow", "Multi-seed region growing (regions and their borders C1); distances in camera units."),
    (
        "regiongrow.mode",
        "Homogeneity criterion: \"default\" (curvedness and plane consistency) or \"paper\" (Gaussian curvature).",
    ),
    ("regiongrow.t_sigma", "T_σ: a seed is accepted only where the std of K over its window is ≤ this."),
    (
        "regiongrow.t_m",
        "T_m (paper mode): adjacent regions merge only if their mean K differ by less than this.",
    ),
    ("regiongrow.min_seeds", "Minimum number of seeds (t_sigma is relaxed to reach it)."),
    ("regiongrow.max_seeds", "Maximum number of seeds (regions grown)."),
    ("regiongrow.max_k_diff", "Paper mode: a pixel joins if |K − the region's mean K| ≤ this."),
    ("regiongrow.max_curvedness", "Default mode: a pixel grows (or seeds) only if its curvedness is ≤ this."),
    (
        "regiongrow.max_angle_deg",
        "Default mode: largest angle between a pixel's normal and the region's normal.",
    ),
    (
        "regiongrow.max_residual",
        "Default mode: largest distance of a pixel's 3D point to the region's plane.",
    ),
    (
        "regiongrow.step_tilt",
        "Default mode, depth in uniform steps: angle limit ≥ this many steps of tilt per pixel, residual limit ≥ one step (0 = off).",
    ),
    (
        "regiongrow.residual_rms_ratio",
        "Default mode: the residual limit is max(max_residual, this × the region's own RMS); 0 = max_residual alone.",
    ),
    (
        "regiongrow.max_slant_deg",
        "Default mode: a pixel's normal must be within this angle of the direction to the sensor.",
    ),
    (
        "regiongrow.refit_every_px",
        "Default mode: the region plane is refitted after max(this, n / 4) additions.",
    ),
    (
        "regiongrow.release_max_px",
        "Default mode: a region that stops growing with at most this many pixels releases those that fail the growth test against its own fit (0 = never).",
    ),
    (
        "regiongrow.merge_max_angle_deg",
        "Default mode: adjacent regions merge only if their normals are within this angle.",
    ),
    (
        "regiongrow.merge_max_residual",
        "Default mode: adjacent regions merge only if each one's RMS distance to the other's plane is ≤ this.",
    ),
    (
        "regiongrow.merge_joint_rms_ratio",
        "Default mode: adjacent regions also merge when one plane fitted to both has RMS ≤ merge_max_residual and ≤ this × their own (0 = off).",
    ),
    ("regiongrow.min_region_px", "Regions with fewer pixels become unlabelled (0)."),
    ("regiongrow.connectivity", "Neighbourhood of growth and of the region adjacency graph: 4 or 8."),
    (
        "regiongrow.fill_unlabelled",
        "Give left-over valid pixels to the adjacent region whose plane fits them.",
    ),
    ("regiongrow.fill_max_residual", "Largest plane distance for fill_unlabelled."),
    (
        "regiongrow.merge_after_fill",
        "After the fill step, merge again (regions a band of non-growable pixels kept apart now touch).",
    ),
    ("regiongrow.c1_one_sided", "C1 one pixel thick (one side of each border) instead of both sides."),
    ("regiongrow.seed_stride_px", "Seed candidates on every n-th pixel in x and y (1 = all pixels)."),
    (
        "regiongrow.seed_radius_px",
        "A seed needs its (2r+1)² window growable and passing the growth test (r = this; 0 = no test).",
    ),
    ("relax", "Simulated-annealing relaxation of C1 and C2 (docs/method.md §3.4)."),
    ("relax.t_d_px", "T_d: points of one set farther than this from the other set are removed (pixels)."),
    ("relax.lambda", "λ, the weight of the external (edge strength) energy against the distance energy."),
    ("relax.t0", "Initial temperature; 0 = automatic (see auto_t0_acceptance)."),
    (
        "relax.auto_t0_acceptance",
        "With t0 = 0: probability of accepting a mean uphill move at the start, in (0, 1).",
    ),
    ("relax.cooling_delta", "δ of the geometric cooling T ← (1 − δ)·T per sweep, in (0, 1)."),
    ("relax.min_acceptance", "Stop after a sweep whose fraction of accepted moves is below this."),
    ("relax.max_sweeps", "Upper bound on the number of sweeps (0 = prune only)."),
    ("relax.normalize", "Divide s1 and |∇| by their means over the initial sets (λ becomes unitless)."),
    (
        "relax.support_px",
        "Relaxed C2 points farther than this from the pruned C1 leave the relaxed edge map C1 ∪ C2, the final one only with final_edges = \"relaxed\" (pixels; 0 = keep all).",
    ),
    ("segment", "The final segmentation from the relaxed edges (crate finalseg); distances in camera units."),
    (
        "segment.mode",
        "\"regions\" (guided by the region-growing labels, then merged) or \"components\" (connected components, the paper).",
    ),
    (
        "segment.min_region_px",
        "Components of core pixels smaller than this are dropped (their pixels are filled like edge pixels).",
    ),
    (
        "segment.gap_close_px",
        "Core pixels are farther than this from every edge pixel (0 = every non-edge pixel).",
    ),
    (
        "segment.unlabelled_core",
        "Regions mode: pixels region growing left unlabelled may be core pixels too.",
    ),
    (
        "segment.min_border_support",
        "Regions mode: adjacent regions may merge if less than this fraction of their border lies at edges.",
    ),
    (
        "segment.merge_within_region",
        "Regions mode: pieces of one region-growing region merge when their planes agree, whatever the edges.",
    ),
    (
        "segment.within_max_rms_ratio",
        "Regions mode: such pieces merge only if each one's RMS to the other's plane ≤ this × its own RMS (≥ 1).",
    ),
    (
        "segment.within_joint_rms_ratio",
        "Regions mode: or if each one's RMS to the plane fitted to both ≤ this × its own RMS and their planes meet between them (0 = off).",
    ),
    (
        "segment.within_close_px",
        "Regions mode: such pieces within this many pixels across unlabelled valid pixels count as adjacent (0 = off).",
    ),
    (
        "segment.merge_max_angle_deg",
        "Regions mode: largest angle between the two regions' plane normals for a merge.",
    ),
    (
        "segment.merge_max_residual",
        "Regions mode: largest RMS distance of each region's points to the other's plane for a merge.",
    ),
    ("segment.fill_max_residual", "Largest distance of a filled pixel to its region's plane (0 = no limit)."),
    (
        "segment.fill_rms_ratio",
        "The fill limit of a region is at least this × its RMS distance to its own plane (0 = fill_max_residual alone).",
    ),
    (
        "segment.refine_passes",
        "Passes moving border pixels to the adjacent region whose plane fits them better (0 = off).",
    ),
    (
        "segment.refine_steep_cos",
        "Refinement: a plane seen from a border pixel at a cosine under this has its distances scaled up toward their length along the line of sight (0 = off).",
    ),
    (
        "segment.bend_max_angle_deg",
        "Regions mode: adjacent regions meeting along their border (a bend, not a step) merge if their normals differ ≤ this (0 = off).",
    ),
    (
        "segment.bend_max_gap",
        "Regions mode: a bend needs the border pixels' mean distance to the other region's plane < this × the larger region RMS.",
    ),
    (
        "segment.bend_fit_ratio",
        "Regions mode: a sharper bend still merges if the joint plane fits each region within this × the larger region RMS (0 = off).",
    ),
    (
        "segment.terrace_gap_steps",
        "Regions mode, stepped depth: a bend next to a single terrace (depths spread under half a step's rounding error) allows this many steps more border gap (0 = off).",
    ),
    (
        "segment.crease_passes",
        "Passes giving each pixel beside a crease to the region whose plane its line of sight sees (0 = off).",
    ),
    (
        "segment.crease_min_angle_deg",
        "Smallest angle between two regions' normals for crease_passes to place the border between them.",
    ),
    (
        "segment.band_max_angle_deg",
        "After refinement, a connected band of a region lying on an adjacent region's plane moves to it whole if their normals differ ≤ this (0 = off).",
    ),
    (
        "segment.outlier_scales",
        "A region's pixels beyond this many noise scales (its RMS, at least 0.25) of its plane, in groups, are left unlabelled (0 = off).",
    ),
    (
        "segment.outlier_min_px",
        "Smallest 4-connected group of such outliers that outlier_scales leaves unlabelled.",
    ),
    (
        "segment.curved_merge_ratio",
        "Last, adjacent regions merge if one quadric fits their union within this multiple of their pooled plane RMS (0 = off): a surface the depth encoding bends.",
    ),
    ("segment.curved_max_angle_deg", "Largest angle between two regions' normals for curved_merge_ratio."),
    (
        "segment.small_face_min_px",
        "After the merges, a group of unlabelled pixels, this many up to under min_region_px, on a plane of its own between two or more regions becomes a region (0 = off).",
    ),
    (
        "segment.small_face_scales",
        "Three quarters of a small face's pixels lie within this many noise scales (its neighbours' largest RMS) of its plane.",
    ),
    (
        "segment.small_face_min_gap",
        "Smallest RMS distance of a small face's points to each neighbour's plane, in noise scales.",
    ),
    (
        "segment.small_face_max_slant_deg",
        "Largest angle between a small face's normal and the line of sight.",
    ),
    (
        "segment.small_face_grow_px",
        "A small face then takes, out to this many pixels from it, its neighbours' pixels that its plane explains better than their own (0 = off).",
    ),
    (
        "segment.small_face_grow_margin",
        "How much nearer such a pixel lies to the face's plane than to its own region's, in noise scales.",
    ),
];

/// The comment of `key` (`table.key`) in [`KEY_DOCS`].
fn key_doc(key: &str) -> Option<&'static str> {
    KEY_DOCS.iter().find(|(k, _)| *k == key).map(|(_, d)| *d)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tables and keys of a configuration's TOML text, as `table.key`.
    fn keys(text: &str) -> Vec<String> {
        let mut table = String::new();
        let mut keys = Vec::new();
        for t in text.lines().map(str::trim) {
            if let Some(name) = t.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
                table = name.to_owned();
                keys.push(table.clone());
            } else if let Some((k, _)) = t.split_once(" = ") {
                keys.push(if table.is_empty() { k.to_owned() } else { format!("{table}.{k}") });
            }
        }
        keys
    }

    #[test]
    fn every_key_has_one_comment_and_every_comment_a_key() {
        let keys = keys(&Config::default().to_toml());
        for k in &keys {
            assert!(key_doc(k).is_some(), "no comment for `{k}` in KEY_DOCS");
        }
        for (k, _) in KEY_DOCS {
            assert!(keys.iter().any(|x| x == k), "KEY_DOCS has `{k}`, which the configuration has not");
        }
        let commented = Config::default().to_commented_toml();
        assert_eq!(commented.lines().filter(|l| l.starts_with("# ")).count(), keys.len());
        assert_eq!(Config::from_toml(&commented, Path::new("x.toml")).unwrap(), Config::default());
    }

    #[test]
    fn old_raw_canny_weights_load_and_are_not_written() {
        let c = Config::from_toml("[raw_canny]\nweights = [1.0, 1.0, 0.0]\n", Path::new("old.toml")).unwrap();
        assert_eq!(c.raw_canny.weights, Some([1.0, 1.0, 0.0]));
        assert_eq!(c.raw_canny.detector(), Config::default().raw_canny.detector());
        assert!(!c.to_toml().contains("weights = [1.0, 1.0, 0.0]\n\n[raw_canny.thresholds]"));
        assert!(!keys(&c.to_toml()).contains(&"raw_canny.weights".to_owned()));
    }
}
