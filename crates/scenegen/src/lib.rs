//! Deterministic ABW-like synthetic range scenes with ground truth (docs/method.md §2.2).
//!
//! [`generate`] lays out random polyhedra (boxes, wedges and ramps, roof prisms, pyramids and
//! frustums, L-blocks, stairs, polygonal prisms, houses) on a table in front of a wall, some
//! stacked, some flush against each other, a few tilted; ray-casts them through the ABW camera
//! (the USF model of docs/method.md §2.1, which is a pinhole with depth `d = v/SCAL + OFFSET` along the
//! optical axis, so each planar face is intersected analytically per pixel); removes what a
//! structured-light projector offset by a horizontal baseline cannot see (shadows); adds
//! Gaussian depth noise, mixed pixels at jump edges and dropout blobs; and quantises to 8 bits.
//! Optional artefact families ([`Family`]: scanner stripes, quantisation staircases, Kinect-like
//! depth-dependent noise and holes) model other sensors; the benchmark uses none of them.
//! [`generate_room`] renders another kind of scene: rooms seen by a Kinect-like depth camera, in metres on a pinhole
//! camera (the `rooms` module).
//!
//! Ground truth follows the ABW rules: one label per connected visible piece of a plane,
//! numbered from 10 in raster order of first appearance; 0 on no-data pixels and pieces under
//! `min_region_px`. A mixed pixel keeps the label of the face its ray hit (docs/method.md §2.2: 0 only for
//! no data and small faces), so depth jumps are scored as boundaries wherever no shadow hides them. Coplanar faces that touch (an L-block's side, two boxes of the
//! same height side by side) form one region, since no sensor can tell them apart.
//!
//! Everything is computed with IEEE `+ − × ÷ √` on one thread from one
//! `Xoshiro256PlusPlus` stream, so a seed gives bit-identical scenes on every platform.

mod family;
mod layout;
mod math;
mod render;
mod rooms;

pub use family::{FAMILY_TEST_IMAGES, FAMILY_TRAIN_IMAGES, Family, Kinect, Staircase, Stripes, family_image};
pub use rooms::{ROOM_METRES_PER_UNIT, ROOM_TEST_IMAGES, RoomParams, RoomScene, generate_room, room_image};

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rangeimage::ParamError;
use rangeimage::{AbwCalibration, Camera, Grid, LabelImage};

/// The `[scenegen]` parameters of a synthetic scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Image width in pixels (ABW: 512). The principal point is at `(width/2 − 1, height/2 − 1)`,
    /// which is the USF model's 255 for 512 × 512.
    pub width_px: u32,
    /// Image height in pixels (ABW: 512).
    pub height_px: u32,
    /// The scanner calibration used to cast rays and quantise range (ABW calibration 0).
    pub calibration: AbwCalibration,
    /// Fewest objects placed (attempts that do not fit are dropped, so fewer may appear).
    pub min_objects: u32,
    /// Most objects placed.
    pub max_objects: u32,
    /// Probability that an object is stacked on a free flat top of an earlier one.
    pub stack_prob: f64,
    /// Probability that an object is placed flush against the side of an earlier one.
    pub touch_prob: f64,
    /// Probability that a free-standing object is tilted (8°–25° about a horizontal axis).
    pub tilt_prob: f64,
    /// Whether a wall stands behind the table.
    pub wall: bool,
    /// Standard deviation of the Gaussian depth noise, in 8-bit range steps.
    pub noise_sigma_v: f64,
    /// Expected fraction of pixels lost in small dropout blobs (v = 0).
    pub dropout_rate: f64,
    /// Probability that a pixel on a depth jump becomes a mixed pixel.
    pub mixed_pixel_prob: f64,
    /// A 4-neighbour on another face whose range differs by more than this many steps, both from
    /// this pixel and from the extension of this pixel's plane, marks a jump edge (not a crease).
    pub jump_v: f64,
    /// Whether the projector casts shadows (no data where it cannot see).
    pub shadows: bool,
    /// Horizontal offset of the projector from the camera centre, in mm (positive = to the right).
    pub projector_baseline_mm: f64,
    /// Ground-truth regions smaller than this get label 0.
    pub min_region_px: u32,
    /// Scanner stripes along the scan direction, on top of the noise (none in the benchmark).
    pub stripes: Option<Stripes>,
    /// Range rounded to a coarser step than 8 bits (none in the benchmark).
    pub staircase: Option<Staircase>,
    /// Kinect-like depth-dependent noise, disparity quantisation and holes (none in the benchmark).
    pub kinect: Option<Kinect>,
    /// Store inverse depth, as stereo disparity, instead of range (false in the benchmark; see
    /// [`Family::Disparity`]).
    pub disparity: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            width_px: 512,
            height_px: 512,
            calibration: AbwCalibration::CAL0,
            min_objects: 3,
            max_objects: 6,
            stack_prob: 0.25,
            touch_prob: 0.35,
            tilt_prob: 0.15,
            wall: true,
            noise_sigma_v: 0.6,
            dropout_rate: 0.001,
            mixed_pixel_prob: 0.35,
            jump_v: 4.0,
            shadows: true,
            projector_baseline_mm: 200.0,
            min_region_px: 100,
            stripes: None,
            staircase: None,
            kinect: None,
            disparity: false,
        }
    }
}

impl Params {
    /// Checks that every value is usable.
    pub fn validate(&self) -> Result<(), ParamError> {
        let prob = |name: &'static str, p: f64| {
            if (0.0..=1.0).contains(&p) {
                Ok(())
            } else {
                Err(ParamError::new(name, format!("= {p} is not in 0..=1")))
            }
        };
        if !(16..=4096).contains(&self.width_px) || !(16..=4096).contains(&self.height_px) {
            return Err(ParamError::new(
                "scenegen.width_px",
                format!("and height_px must be in 16..=4096, got {}×{}", self.width_px, self.height_px),
            ));
        }
        if self.min_objects > self.max_objects || self.max_objects > 40 {
            return Err(ParamError::new(
                "scenegen.min_objects",
                format!(
                    "..=max_objects must be a non-empty range up to 40, got {}..={}",
                    self.min_objects, self.max_objects
                ),
            ));
        }
        prob("scenegen.stack_prob", self.stack_prob)?;
        prob("scenegen.touch_prob", self.touch_prob)?;
        prob("scenegen.tilt_prob", self.tilt_prob)?;
        prob("scenegen.dropout_rate", self.dropout_rate)?;
        prob("scenegen.mixed_pixel_prob", self.mixed_pixel_prob)?;
        if self.stack_prob + self.touch_prob > 1.0 {
            return Err(ParamError::new("scenegen.stack_prob", "+ touch_prob must not exceed 1"));
        }
        if !(0.0..=20.0).contains(&self.noise_sigma_v) {
            return Err(ParamError::new(
                "scenegen.noise_sigma_v",
                format!("= {} is not in 0..=20", self.noise_sigma_v),
            ));
        }
        if self.jump_v.is_nan() || self.jump_v <= 0.0 {
            return Err(ParamError::new("scenegen.jump_v", format!("= {} must be positive", self.jump_v)));
        }
        if !self.projector_baseline_mm.is_finite() {
            return Err(ParamError::new("scenegen.projector_baseline_mm", "must be finite"));
        }
        let cal = self.calibration;
        if !(cal.scal > 0.0 && cal.offset > 0.0 && cal.f != 0.0 && cal.c > 0.0) {
            return Err(ParamError::new(
                "scenegen.calibration",
                format!("{cal:?} needs scal, offset, c > 0 and f ≠ 0"),
            ));
        }
        family::validate(self)
    }
}

/// One synthetic range image with its ground truth, in ABW conventions.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Raw 8-bit range values; 0 = no data, larger = farther.
    pub range: Grid<u8>,
    /// Ground truth: 0 = unlabelled, regions consecutive from 10.
    pub labels: LabelImage,
    /// For every pair of 4-adjacent GT regions `(a, b)` with `a < b`, the angle in degrees between
    /// their plane normals (both pointing toward the sensor), sorted by `(a, b)`.
    pub angles: Vec<(u32, u32, f64)>,
}

/// Generates the scene of `seed`: the same params and seed always give a bit-identical scene.
///
/// # Panics
/// In debug builds, if `params` fails [`Params::validate`] (callers validate once, at the edge).
#[must_use]
pub fn generate(params: &Params, seed: u64) -> Scene {
    let _s = tracing::info_span!("scenegen", seed).entered();
    debug_assert_eq!(params.validate(), Ok(()), "scenegen::generate");
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let layout = layout::random_layout(params, &mut rng);
    tracing::debug!(pieces = layout.pieces.len(), "layout");
    let scene = render::render(params, &layout, &mut rng, seed);
    tracing::debug!(regions = scene.angles.len(), "rendered");
    scene
}

/// Number of training images in the synthetic ABW-like benchmark (as in ABW).
pub const TRAIN_IMAGES: u32 = 10;
/// Number of test images in the synthetic ABW-like benchmark (as in ABW).
pub const TEST_IMAGES: u32 = 30;

/// Parameters and seed of benchmark image `abw.{train,test}.index`.
///
/// Seeds are fixed per split and index. The calibration is the one ABW uses for that name
/// ([`Camera::abw_for`]: calibration 1 for test images 0, 19, 21, 25, 27, 28, 29, otherwise 0), so
/// a reader that picks the camera from the file name back-projects the scene exactly.
#[must_use]
pub fn benchmark_image(test_split: bool, index: u32) -> (Params, u64) {
    let calibration = match Camera::abw_for(test_split, index) {
        Camera::Abw(cal) => cal,
        other => unreachable!("abw_for returned a non-ABW camera {other:?}"),
    };
    let seed = if test_split { 0x5EED_0002_0000 } else { 0x5EED_0001_0000 } + u64::from(index);
    (Params { calibration, ..Params::default() }, seed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    fn train(index: u32) -> Scene {
        let (p, seed) = benchmark_image(false, index);
        generate(&p, seed)
    }

    /// Mean squared distance of points to their least-squares plane (smallest covariance eigenvalue).
    fn plane_fit_ms(pts: &[[f64; 3]]) -> f64 {
        let n = pts.len() as f64;
        let mut c = [0.0; 3];
        for p in pts {
            for k in 0..3 {
                c[k] += p[k] / n;
            }
        }
        let mut m = [[0.0; 3]; 3];
        for p in pts {
            for i in 0..3 {
                for j in 0..3 {
                    m[i][j] += (p[i] - c[i]) * (p[j] - c[j]) / n;
                }
            }
        }
        // Smallest eigenvalue of a symmetric 3×3 matrix (trigonometric method).
        let q = (m[0][0] + m[1][1] + m[2][2]) / 3.0;
        let p1 = m[0][1].powi(2) + m[0][2].powi(2) + m[1][2].powi(2);
        let p2 = (0..3).map(|i| (m[i][i] - q).powi(2)).sum::<f64>() + 2.0 * p1;
        let p = (p2 / 6.0).sqrt();
        let b: Vec<Vec<f64>> =
            (0..3).map(|i| (0..3).map(|j| (m[i][j] - if i == j { q } else { 0.0 }) / p).collect()).collect();
        let det = b[0][0] * (b[1][1] * b[2][2] - b[1][2] * b[2][1])
            - b[0][1] * (b[1][0] * b[2][2] - b[1][2] * b[2][0])
            + b[0][2] * (b[1][0] * b[2][1] - b[1][1] * b[2][0]);
        let phi = (det / 2.0).clamp(-1.0, 1.0).acos() / 3.0;
        q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos()
    }

    #[test]
    fn same_seed_same_scene_other_seed_differs() {
        let p = Params::default();
        let a = generate(&p, 7);
        assert_eq!(a, generate(&p, 7));
        let b = generate(&p, 8);
        assert_ne!(a.range, b.range);
        assert_ne!(a.labels, b.labels);
    }

    #[test]
    fn labels_follow_abw_rules() {
        for i in 0..TRAIN_IMAGES {
            let s = train(i);
            assert_eq!(s.range.dimensions(), (512, 512));
            assert!(s.labels.same_size(&s.range));
            let used: BTreeSet<u32> = s.labels.as_slice().iter().copied().filter(|&l| l != 0).collect();
            let k = used.len() as u32;
            assert_eq!(used, (10..10 + k).collect(), "train {i}: labels not consecutive from 10");
            for (&v, &l) in s.range.as_slice().iter().zip(s.labels.as_slice()) {
                assert!(v != 0 || l == 0, "train {i}: labelled no-data pixel");
            }
            // Every region is at least min_region_px.
            for l in &used {
                let n = s.labels.as_slice().iter().filter(|&&x| x == *l).count();
                assert!(n >= 100, "train {i}: region {l} has {n} px");
            }
        }
    }

    #[test]
    fn region_counts_are_abw_like() {
        let counts: Vec<u32> = (0..TRAIN_IMAGES)
            .map(|i| train(i).labels.as_slice().iter().copied().max().unwrap_or(0).saturating_sub(9))
            .collect();
        let mean = f64::from(counts.iter().sum::<u32>()) / counts.len() as f64;
        assert!(counts.iter().all(|&c| (6..=35).contains(&c)), "region counts {counts:?}");
        assert!((11.0..=22.0).contains(&mean), "mean region count {mean} ({counts:?})");
    }

    #[test]
    fn regions_are_planar_in_3d() {
        for (p, seed) in [benchmark_image(false, 0), benchmark_image(false, 3), benchmark_image(true, 19)] {
            // Mixed pixels keep their face's label but lie between two surfaces by construction.
            let p = Params { mixed_pixel_prob: 0.0, ..p };
            let s = generate(&p, seed);
            let cam = Camera::Abw(p.calibration);
            let k = s.labels.as_slice().iter().copied().max().unwrap_or(0);
            assert!(k >= 12);
            let mut pts: Vec<Vec<[f64; 3]>> = vec![Vec::new(); k as usize + 1];
            for (x, y, &l) in s.labels.enumerate() {
                if l >= 10 {
                    let v = f64::from(s.range[(x, y)]);
                    pts[l as usize].push(cam.point(f64::from(x), f64::from(y), v).expect("finite"));
                }
            }
            for l in 10..=k as usize {
                // Noise σ = 0.6 steps plus quantisation is about 0.85 mm along Z (1 step = 1.26 mm).
                let rms = plane_fit_ms(&pts[l]).sqrt();
                assert!(rms < 1.3, "seed {seed}: region {l} off its plane by {rms} mm rms");
            }
        }
    }

    #[test]
    fn mixed_pixels_change_depth_not_ground_truth() {
        // Not 0: with 0 the mixed-pixel pass and its random draws are skipped, which moves the dropouts.
        let none = Params { mixed_pixel_prob: 1e-12, ..Params::default() };
        let all = Params { mixed_pixel_prob: 1.0, ..Params::default() };
        let (a, b) = (generate(&none, 5), generate(&all, 5));
        let changed = a.range.as_slice().iter().zip(b.range.as_slice()).filter(|(p, q)| p != q).count();
        assert!(changed > 100, "only {changed} mixed pixels on the jumps");
        let relabelled = a.labels.as_slice().iter().zip(b.labels.as_slice()).filter(|(p, q)| p != q).count();
        assert_eq!(relabelled, 0, "mixed pixels must keep their face's label");
    }

    #[test]
    fn noise_free_regions_are_planar_to_quantisation() {
        let p = Params { noise_sigma_v: 0.0, mixed_pixel_prob: 0.0, dropout_rate: 0.0, ..Params::default() };
        let s = generate(&p, 11);
        let cam = Camera::Abw(p.calibration);
        let k = s.labels.as_slice().iter().copied().max().unwrap_or(0);
        for l in 10..=k {
            let pts: Vec<[f64; 3]> = s
                .labels
                .enumerate()
                .filter(|&(_, _, &x)| x == l)
                .map(|(x, y, _)| {
                    cam.point(f64::from(x), f64::from(y), f64::from(s.range[(x, y)])).expect("finite")
                })
                .collect();
            let rms = plane_fit_ms(&pts).sqrt();
            // Rounding to a step is uniform: 1.26 mm / √12 ≈ 0.36 mm rms along Z.
            assert!(rms < 0.45, "region {l} off its plane by {rms} mm rms");
        }
    }

    #[test]
    fn angles_cover_every_adjacent_pair() {
        for i in [0, 5, 9] {
            let s = train(i);
            let mut adjacent = BTreeSet::new();
            let (w, h) = s.labels.dimensions();
            for y in 0..h {
                for x in 0..w {
                    let a = s.labels[(x, y)];
                    for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                        if let Some(&b) = s.labels.get(nx, ny)
                            && a >= 10
                            && b >= 10
                            && a != b
                        {
                            adjacent.insert((a.min(b), a.max(b)));
                        }
                    }
                }
            }
            let listed: BTreeSet<(u32, u32)> = s.angles.iter().map(|&(a, b, _)| (a, b)).collect();
            assert_eq!(listed, adjacent, "train {i}");
            assert_eq!(listed.len(), s.angles.len(), "train {i}: duplicate pairs");
            assert!(s.angles.iter().all(|&(_, _, t)| (0.0..=180.0).contains(&t)));
            // Box-like scenes: many neighbours meet at right angles (table and box sides).
            assert!(s.angles.iter().any(|&(_, _, t)| (t - 90.0).abs() < 0.5), "train {i}: no right angle");
        }
    }

    #[test]
    fn parameters_change_the_artefacts() {
        let base = Params::default();
        let valid = |p: &Params| generate(p, 4).range.as_slice().iter().filter(|&&v| v > 0).count();
        let no_shadow = Params { shadows: false, dropout_rate: 0.0, mixed_pixel_prob: 0.0, ..base.clone() };
        assert!(valid(&no_shadow) > valid(&base));
        let small = Params { width_px: 128, height_px: 96, ..base.clone() };
        assert_eq!(generate(&small, 4).range.dimensions(), (128, 96));
        assert!(Params { noise_sigma_v: -1.0, ..base.clone() }.validate().is_err());
        assert!(Params { min_objects: 5, max_objects: 2, ..base.clone() }.validate().is_err());
        assert!(base.validate().is_ok());
    }

    #[test]
    fn benchmark_uses_the_abw_calibration_by_name() {
        assert_eq!(benchmark_image(true, 19).0.calibration, AbwCalibration::CAL1);
        assert_eq!(benchmark_image(true, 18).0.calibration, AbwCalibration::CAL0);
        assert_ne!(benchmark_image(true, 3).1, benchmark_image(false, 3).1);
    }
}
