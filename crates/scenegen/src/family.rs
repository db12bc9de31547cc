//! Sensor artefact families beyond the benchmark's white noise (docs/benchmark.md, "Artefact families"):
//! scanner stripes along the scan direction, depth quantisation staircases and Kinect-like
//! depth-dependent noise with disparity quantisation and holes; and [`Family`], the named presets
//! `cargo xtask eval --data synthetic:FAMILY` generates.
//!
//! Every artefact draws from its own random stream, seeded from the scene's seed, so a scene's
//! layout, noise draws and dropouts are the same with and without it, and the benchmark (no
//! artefact) is what it was bit for bit.

use crate::Params;
use rangeimage::{Camera, ParamError};

/// Scanner stripes: the range of every column carries an offset that drifts down the column
/// (the scan direction of the ABW scanner), as the short vertical streaks of the real ABW images.
///
/// Down a column the offset is a first-order autoregressive process of standard deviation
/// `amplitude_v` and correlation length `length_px`; across columns neighbouring offsets are
/// mixed by a `[1 2 1] / 4` kernel (rescaled to keep the amplitude), which gives the correlation
/// of about 0.5 between adjacent columns that real ABW residuals show.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Stripes {
    /// Standard deviation of the stripe offsets, in 8-bit range steps.
    pub amplitude_v: f64,
    /// Correlation length down a column, in pixels (the offset's correlation at lag k is e^(−k/length)).
    pub length_px: f64,
}

/// Depth quantisation: range rounded to a multiple of `step_v` before the 8-bit rounding, which
/// turns slanted planes into staircases of that step.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Staircase {
    /// The step, in 8-bit range steps (1 = the 8-bit quantisation alone).
    pub step_v: f64,
}

/// Kinect-like depth: noise growing with the square of depth, quantised disparity (so the depth
/// step grows with depth too) and holes on grazing surfaces and at far range.
///
/// The scene keeps the ABW geometry and camera; the sensor model runs on a virtual depth axis that
/// maps range value 0 to `near_mm` and 255 to `far_mm` linearly, so the 8-bit image spans a
/// Kinect-like 1.5–4 m with a z² ratio of 7 from front to back.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Kinect {
    /// Virtual depth of range value 0, in mm.
    pub near_mm: f64,
    /// Virtual depth of range value 255, in mm.
    pub far_mm: f64,
    /// Depth noise at 1 m, in mm; σ(z) = this · (z / 1 m)² (Khoshelham and Elberink 2012: about 1.4 mm).
    pub sigma_1m_mm: f64,
    /// Disparity quantisation step, in pixels (Kinect v1: 1/8).
    pub disparity_step_px: f64,
    /// Focal length times baseline, in pixel·mm (Kinect v1: about 580 px × 75 mm).
    pub focal_baseline_px_mm: f64,
    /// Incidence angle (between the ray and the surface normal) from which holes appear, in degrees;
    /// their probability rises linearly to 1 over the next 10°.
    pub grazing_deg: f64,
    /// Virtual depth from which holes appear, in mm; their probability rises linearly to 0.5 at `far_mm`.
    pub far_holes_mm: f64,
}

impl Default for Kinect {
    fn default() -> Self {
        Self {
            near_mm: 1500.0,
            far_mm: 4000.0,
            sigma_1m_mm: 1.4,
            disparity_step_px: 0.125,
            focal_baseline_px_mm: 580.0 * 75.0,
            grazing_deg: 70.0,
            far_holes_mm: 3500.0,
        }
    }
}

impl Kinect {
    /// Virtual depth (mm) of a range value.
    pub(crate) fn depth_mm(&self, v: f64) -> f64 {
        self.near_mm + v * (self.far_mm - self.near_mm) / 255.0
    }

    /// Range value of a virtual depth (mm).
    fn value(&self, z_mm: f64) -> f64 {
        (z_mm - self.near_mm) * 255.0 / (self.far_mm - self.near_mm)
    }

    /// The sensor's range value for the clean value `v` and a unit Gaussian draw `g`: noise in depth,
    /// then disparity rounded to its step.
    pub(crate) fn measure(&self, v: f64, g: f64) -> f64 {
        let z = self.depth_mm(v);
        let z = z + self.sigma_1m_mm * (z / 1000.0) * (z / 1000.0) * g;
        let d = self.focal_baseline_px_mm / z;
        let d = (d / self.disparity_step_px).round() * self.disparity_step_px;
        self.value(self.focal_baseline_px_mm / d)
    }

    /// Probability that a pixel of virtual depth `z_mm` seen at incidence `cos_incidence` is a hole.
    pub(crate) fn hole_probability(&self, z_mm: f64, cos_incidence: f64) -> f64 {
        let angle = cos_incidence.clamp(0.0, 1.0).acos().to_degrees();
        let grazing = ((angle - self.grazing_deg) / 10.0).clamp(0.0, 1.0);
        let far = if self.far_mm > self.far_holes_mm {
            0.5 * ((z_mm - self.far_holes_mm) / (self.far_mm - self.far_holes_mm)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        grazing.max(far)
    }
}

/// Checks the artefact parameters of `p`.
pub(crate) fn validate(p: &Params) -> Result<(), ParamError> {
    let positive = |name: &'static str, v: f64, max: f64| {
        if v > 0.0 && v <= max {
            Ok(())
        } else {
            Err(ParamError::new(name, format!("= {v} must be in (0, {max}]")))
        }
    };
    if let Some(s) = p.stripes {
        if !(0.0..=20.0).contains(&s.amplitude_v) {
            return Err(ParamError::new(
                "scenegen.stripes.amplitude_v",
                format!("= {} is not in 0..=20", s.amplitude_v),
            ));
        }
        positive("scenegen.stripes.length_px", s.length_px, 4096.0)?;
    }
    if let Some(s) = p.staircase
        && !(1.0..=64.0).contains(&s.step_v)
    {
        return Err(ParamError::new("scenegen.staircase.step_v", format!("= {} is not in 1..=64", s.step_v)));
    }
    if let Some(k) = p.kinect {
        positive("scenegen.kinect.near_mm", k.near_mm, 1e5)?;
        if k.far_mm.is_nan() || k.far_mm <= k.near_mm || k.far_mm > 1e5 {
            return Err(ParamError::new(
                "scenegen.kinect.far_mm",
                format!("= {} must exceed near_mm", k.far_mm),
            ));
        }
        if !(0.0..=100.0).contains(&k.sigma_1m_mm) {
            return Err(ParamError::new(
                "scenegen.kinect.sigma_1m_mm",
                format!("= {} is not in 0..=100", k.sigma_1m_mm),
            ));
        }
        positive("scenegen.kinect.disparity_step_px", k.disparity_step_px, 16.0)?;
        positive("scenegen.kinect.focal_baseline_px_mm", k.focal_baseline_px_mm, 1e7)?;
        if !(0.0..=90.0).contains(&k.grazing_deg) {
            return Err(ParamError::new(
                "scenegen.kinect.grazing_deg",
                format!("= {} is not in 0..=90", k.grazing_deg),
            ));
        }
        if k.far_holes_mm.is_nan() {
            return Err(ParamError::new("scenegen.kinect.far_holes_mm", "must not be NaN"));
        }
    }
    Ok(())
}

/// The stripe offsets of every pixel (row-major), from the stripes' own random stream.
pub(crate) fn stripe_field(
    s: &Stripes,
    w: u32,
    h: u32,
    rng: &mut rand::rngs::Xoshiro256PlusPlus,
) -> Vec<f64> {
    let (w, h) = (w as usize, h as usize);
    let rho = (-1.0 / s.length_px).exp();
    let innovation = (1.0 - rho * rho).sqrt();
    // Column processes, then the [1 2 1] / 4 mix across columns (clamped at the sides), rescaled
    // by 1 / √(6/16) so the mixed offsets keep the amplitude.
    let mut raw = vec![0.0; w * h];
    for x in 0..w {
        let mut o = crate::render::gauss(rng);
        for y in 0..h {
            if y > 0 {
                o = rho * o + innovation * crate::render::gauss(rng);
            }
            raw[y * w + x] = o;
        }
    }
    let gain = s.amplitude_v / (6.0f64 / 16.0).sqrt();
    let mut field = vec![0.0; w * h];
    for y in 0..h {
        let row = &raw[y * w..(y + 1) * w];
        for x in 0..w {
            let (l, r) = (row[x.saturating_sub(1)], row[(x + 1).min(w - 1)]);
            field[y * w + x] = gain * (0.25 * l + 0.5 * row[x] + 0.25 * r);
        }
    }
    field
}

/// A named artefact family: the benchmark's scenes and sensor model with one kind of artefact,
/// at a strength that scales it (1 = the family's default).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Family {
    /// The benchmark's model: white Gaussian noise (0.6 × strength steps) and 8-bit quantisation.
    Abw,
    /// White noise 0.2 steps plus scanner stripes of 0.5 × strength steps, correlation length 8 px
    /// down the columns (together about the 0.6-step plane residual and its correlations down and
    /// across the columns in real ABW images).
    Stripes,
    /// White noise 0.25 steps, range rounded to 3 × strength steps (at least 1): staircases.
    Staircase,
    /// Kinect-like: σ ∝ z² (1.4 mm × strength at 1 m), disparity step 1/8 px × strength, holes on
    /// grazing surfaces and beyond 3.5 m, on a virtual 1.5–4 m depth axis; no white noise.
    Kinect,
    /// Stereo ground truth: noise-free inverse depth (disparity), rounded to steps of strength (at least
    /// 1). A plane is a plane in pixel coordinates and stored value, so read it with `--camera grid`.
    Disparity,
}

impl Family {
    /// Every family, in the order reports list them.
    pub const ALL: [Family; 5] =
        [Family::Abw, Family::Stripes, Family::Staircase, Family::Kinect, Family::Disparity];

    /// The family's name on the command line (`synthetic:NAME`).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Family::Abw => "abw",
            Family::Stripes => "stripes",
            Family::Staircase => "staircase",
            Family::Kinect => "kinect",
            Family::Disparity => "disparity",
        }
    }

    /// The family of a name, if any.
    #[must_use]
    pub fn from_name(name: &str) -> Option<Family> {
        Family::ALL.into_iter().find(|f| f.name() == name)
    }

    /// `base` with this family's sensor model at `strength` (0 = no artefact of the family's kind).
    #[must_use]
    pub fn apply(self, base: Params, strength: f64) -> Params {
        match self {
            Family::Abw => Params { noise_sigma_v: 0.6 * strength, ..base },
            Family::Stripes => Params {
                noise_sigma_v: 0.2,
                stripes: Some(Stripes { amplitude_v: 0.5 * strength, length_px: 8.0 }),
                ..base
            },
            Family::Staircase => Params {
                noise_sigma_v: 0.25,
                staircase: Some(Staircase { step_v: (3.0 * strength).max(1.0) }),
                ..base
            },
            Family::Kinect => {
                let k = Kinect::default();
                Params {
                    noise_sigma_v: 0.0,
                    kinect: Some(Kinect {
                        sigma_1m_mm: k.sigma_1m_mm * strength,
                        disparity_step_px: k.disparity_step_px * strength.max(1e-3),
                        ..k
                    }),
                    ..base
                }
            }
            Family::Disparity => Params {
                noise_sigma_v: 0.0,
                disparity: true,
                staircase: Some(Staircase { step_v: strength.max(1.0) }),
                ..base
            },
        }
    }
}

/// Number of training images of a family set (`abw.train.N`).
pub const FAMILY_TRAIN_IMAGES: u32 = 10;
/// Number of test images of a family set (`abw.test.N`).
pub const FAMILY_TEST_IMAGES: u32 = 20;

/// Parameters and seed of image `abw.{train,test}.index` of a family set.
///
/// Every family uses the same scenes (seeds differ from the benchmark's, so tuning on a family
/// set never sees the benchmark's test scenes), with the ABW calibration of the image's name.
#[must_use]
pub fn family_image(family: Family, strength: f64, test_split: bool, index: u32) -> (Params, u64) {
    let calibration = match Camera::abw_for(test_split, index) {
        Camera::Abw(cal) => cal,
        other => unreachable!("abw_for returned a non-ABW camera {other:?}"),
    };
    let seed = if test_split { 0x5EED_0004_0000 } else { 0x5EED_0003_0000 } + u64::from(index);
    (family.apply(Params { calibration, ..Params::default() }, strength), seed)
}
