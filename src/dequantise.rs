//! Dequantisation: depth rounded to steps coarser than its noise, turned back into slopes before the stages run.
//!
//! A depth rounded to steps well above its noise (rendered depth, a stereo disparity or a quantiser with no noise
//! to dither it) turns every slanted plane into a staircase of flat terraces and risers of one step. The stages
//! see the terraces, not the plane: local planes are flat on a terrace and steep on a riser, the Canny detector
//! fires on the risers, and region growing can join a staircase only with limits raised to one step
//! (`regiongrow::Params::for_steps`), which then let it run across creases too. Such an image carries the slope in
//! the terraces' shape: a terrace of a plane lies between a riser one step down and a riser one step up, and the
//! plane crosses the terrace's stored value halfway between them. So each pixel of a terrace gets the value that
//! a straight ramp from half a step below (at the riser down) to half a step above (at the riser up) has there,
//! by the pixel's distances to the two risers within its terrace:
//!
//! `value = stored − q/2 + q · d_down / (d_down + d_up)`
//!
//! A terrace with a riser on one side only (cut by the image border, no data or a jump; a ridge or a valley)
//! ramps from that riser at the slope of the terrace beyond it (one step over that terrace's width), up to half
//! a step; a terrace with no riser (a level surface) keeps its value. The result always rounds back to the
//! stored value (it stays within half a step of it). A difference of more than one step is a jump, not a riser,
//! and distances do not cross it.
//!
//! It runs only on a staircase: an image whose depth has a step, uniform or nearly (`planefit::noise::step_from_smallest`),
//! and a noise σ (`planefit::noise::sigma_sampled`) below that step's rounding error `q / √12`, the test
//! [`crate::units`] already makes to take the rounding as the image's noise floor. Noise at least as large as
//! the rounding dithers the risers into noise, which the stages handle as noise; the real ABW images and the NYU
//! frames have it (docs/method.md §2.6).
//!
//! A pinhole frame that is no staircase of its depth may be one of its inverse depth: a structured-light or stereo
//! camera's disparity in uniform steps (a Kinect's 1/8 px), turned into depth and rounded to the frame's units. Its
//! inverse depth is then rounded to its steps, dequantised and turned back into depth (`disparity_step`,
//! `disparity_staircase`; a plane's inverse depth is affine in the pixel coordinates, so its terraces are straight).

use rangeimage::{Camera, RangeImage};

/// Stride of the rows and 5 × 5 windows the test reads (as [`crate::units`], which can reuse its σ).
use crate::units::SAMPLE_STRIDE;

/// The working memory of [`dequantise`], kept from one frame to the next.
#[derive(Debug, Default)]
pub struct Scratch {
    /// Per pixel: its distance to the nearest pixel of its terrace beside a riser down, then up.
    down: Vec<f32>,
    up: Vec<f32>,
    /// Per pixel of a terrace with one riser: its distance to that riser, and the width of the terrace beyond.
    ramp: Vec<f32>,
    ramp_width: Vec<f32>,
    /// Per pixel: which of its 8 neighbours lie in its terrace ([`terrace_neighbours`]).
    same: Vec<u8>,
    /// The pixels of terraces with one riser, as [`dequantise`] ramps them from it.
    members: Vec<u32>,
    /// The memory of the last dequantised image, given back by [`Scratch::recycle`].
    values: Vec<f32>,
    /// A disparity staircase's inverse depth in steps ([`disparity_step`]), and the risers it sampled.
    inverse: Vec<f32>,
    risers: Vec<f64>,
}

impl Scratch {
    /// Reserves room for frames of `px` pixels (untouched memory: later frames of that size allocate nothing,
    /// whether or not they are staircases).
    pub fn reserve(&mut self, px: usize) {
        for v in [
            &mut self.down,
            &mut self.up,
            &mut self.ramp,
            &mut self.ramp_width,
            &mut self.values,
            &mut self.inverse,
        ] {
            v.clear();
            v.reserve(px);
        }
        // Two neighbour pairs per pixel of every SAMPLE_STRIDE-th row (at most one value per pixel).
        self.risers.clear();
        self.risers.reserve(px);
        self.same.clear();
        self.same.reserve(px);
        self.members.clear();
        self.members.reserve(px);
    }

    /// Takes back the memory of an image [`dequantise`] returned.
    pub fn recycle(&mut self, image: RangeImage) {
        self.values = image.into_vec();
    }
}

/// What [`staircase`] read from an image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Staircase {
    /// The step `q` of the depth if the depth is a staircase (module docs): a step exists and the noise σ lies
    /// below the rounding error of the smallest difference between neighbours, `d / √12` (`d = q` for a uniform
    /// step; for a nearly uniform one, the lower riser).
    pub step: Option<f64>,
    /// The σ it read (`planefit::noise::sigma_sampled` at [`crate::units`]'s stride), if it needed it: depth
    /// with no step is no staircase whatever its noise.
    pub sigma: Option<f64>,
}

/// A screen reads σ from one window in [`SCREEN_STRIDE`]² (a sixteenth of the test's windows) and ends the test
/// when that σ is at least this many times the rounding error. On quantised depth both σ take few distinct
/// values (medians of window residuals that are mostly 0 on a terrace): over the 220 images of the three data
/// sets and eight artefact families, the screen read up to 1.26 times the rounding error where the test read
/// under it (two `staircase@1.33` images).
const SCREEN_MARGIN: f64 = 1.5;
/// The stride of the screen's windows.
const SCREEN_STRIDE: usize = 4 * SAMPLE_STRIDE;

/// Whether `range`'s depth is a staircase (module docs). `noise` is the σ estimate's scratch memory. A caller
/// that will not use the σ (no working units: `pipeline.normalize_units` off) asks for a `screen`: a coarse σ first,
/// which rules out a noisy image at a sixteenth of the cost (then [`Staircase::sigma`] is `None`).
#[must_use]
pub fn staircase(range: &RangeImage, noise: &mut Vec<f64>, screen: bool) -> Staircase {
    let none = Staircase { step: None, sigma: None };
    let Some(smallest) = planefit::noise::smallest_difference(range, SAMPLE_STRIDE) else { return none };
    let rounding = smallest / 12f64.sqrt();
    if screen && planefit::noise::sigma_sampled_with(range, SCREEN_STRIDE, noise) >= SCREEN_MARGIN * rounding
    {
        return none;
    }
    let sigma = planefit::noise::sigma_sampled_with(range, SAMPLE_STRIDE, noise);
    // NaN (too few windows) is no staircase.
    let step = if sigma < rounding {
        planefit::noise::step_from_smallest(range, SAMPLE_STRIDE, smallest)
    } else {
        None
    };
    if let Some(step) = step {
        tracing::debug!(step, sigma, "staircase depth: dequantised");
    }
    Staircase { step, sigma: Some(sigma) }
}

/// What the pipeline runs `range` (seen through `camera`) on under `config` ([`Prepared`]). `noise` is the σ
/// estimate's scratch memory. [`crate::pipeline::Segmenter`] and [`crate::units::in_working_units`] both call it.
/// With `pipeline.dequantise` on, `noise` and `scratch` first get room for a frame of this size, whether or not
/// it is a staircase, so that a stream of frames allocates nothing image-sized after its first.
pub fn for_config(
    range: &RangeImage,
    camera: &Camera,
    config: &crate::Config,
    noise: &mut Vec<f64>,
    scratch: &mut Scratch,
) -> Prepared {
    if !config.pipeline.dequantise {
        return Prepared::default();
    }
    scratch.reserve(range.len());
    // Room for the σ of every sampled window, whether or not this frame's test reads them all.
    let windows =
        (range.width() as usize / SAMPLE_STRIDE + 1) * (range.height() as usize / SAMPLE_STRIDE + 1);
    noise.clear();
    noise.reserve(windows);
    // Without working units nothing else reads the σ: screen first. (With them, every camera's read it, an ABW
    // image's for its stretch across, and reuse the σ the test read.)
    let screen = !config.pipeline.normalize_units;
    let stairs = staircase(range, noise, screen);
    match stairs.step {
        Some(q) => Prepared { dequantised: Some((q, dequantise(range, q, scratch))), ..Prepared::default() },
        // A pinhole frame may be a staircase of its inverse depth instead.
        None if matches!(camera, Camera::Pinhole { .. }) => disparity_staircase(range, noise, scratch)
            .unwrap_or(Prepared { sigma: stairs.sigma, ..Prepared::default() }),
        None => Prepared { sigma: stairs.sigma, ..Prepared::default() },
    }
}

/// A depth difference between neighbours beyond this share of the nearer depth is a jump, not a riser of
/// [`disparity_step`]'s staircase (a Kinect's riser is 0.3 % of the depth at 1 m, 1.3 % at 4 m).
const DISPARITY_JUMP: f64 = 0.05;
/// Fewest risers [`disparity_step`] reads a step from.
const DISPARITY_MIN_RISERS: usize = 1000;
/// Least share of equal neighbours (terraces) of a disparity staircase, as [`planefit::noise`]'s nearly uniform
/// steps ask.
const DISPARITY_MIN_TERRACES: f64 = 0.25;
/// Least share of the risers within 0.2 steps of a whole number of steps (noisy depth has about 40 %).
const DISPARITY_MIN_WHOLE: f64 = 0.9;
/// The largest σ, in steps, of the inverse depth of a disparity staircase that is dequantised: `√(2 / 12)`, noise
/// below the rounding error `1 / √12` with the rounding error added. Its terraces are narrow (a floor's are 2–10 px
/// wide), so most 5 × 5 windows straddle a riser and σ reads the whole rounding error even without noise, where a
/// staircase of wide terraces ([`staircase`]) reads next to none of it.
const DISPARITY_MAX_SIGMA: f64 = 0.408_248_290_463_863;

/// The step of the inverse depth of a pinhole frame whose depth was computed from a disparity quantised in uniform
/// steps and then rounded to the frame's units (a Kinect v1 or another structured-light camera, OpenNI's millimetres,
/// TUM's fifths of a millimetre): the depth steps grow with the square of depth, so no uniform step of the depth
/// shows, but the inverse depth steps evenly. `None` unless, on every [`SAMPLE_STRIDE`]-th row, at least
/// [`DISPARITY_MIN_TERRACES`] of the neighbour pairs are equal, and of the others (jumps of more than
/// [`DISPARITY_JUMP`] left out, at least [`DISPARITY_MIN_RISERS`] of them), [`DISPARITY_MIN_WHOLE`] differ in inverse
/// depth by a whole number of steps, within 0.2 steps: the step is the median of the smallest risers (those within
/// half to one and a half times the lower quartile). `risers` is working memory.
fn disparity_step(range: &RangeImage, risers: &mut Vec<f64>) -> Option<f64> {
    let (w, h) = (range.width() as usize, range.height() as usize);
    let v = range.as_slice();
    risers.clear();
    let (mut pairs, mut equal) = (0usize, 0usize);
    for y in (0..h).step_by(SAMPLE_STRIDE) {
        for x in 0..w {
            let a = v[y * w + x];
            if !(a.is_finite() && a > 0.0) {
                continue;
            }
            for j in [(x + 1 < w).then(|| y * w + x + 1), (y + 1 < h).then(|| (y + 1) * w + x)]
                .into_iter()
                .flatten()
            {
                let b = v[j];
                if !(b.is_finite() && b > 0.0) {
                    continue;
                }
                pairs += 1;
                if a == b {
                    equal += 1;
                    continue;
                }
                let (a, b) = (f64::from(a), f64::from(b));
                if (a - b).abs() <= DISPARITY_JUMP * a.min(b) {
                    risers.push((1.0 / a - 1.0 / b).abs());
                }
            }
        }
    }
    if risers.len() < DISPARITY_MIN_RISERS || (equal as f64) < DISPARITY_MIN_TERRACES * pairs as f64 {
        return None;
    }
    // Ranks in the risers' order, by selection rather than sorting (the risers are positive and finite).
    let n = risers.len();
    let quartile = *risers.select_nth_unstable_by(n / 4, f64::total_cmp).1;
    let below = |share: f64| risers.iter().filter(|&&d| d < share * quartile).count();
    let (lo, hi) = (below(0.5), below(1.5));
    let q = *risers.select_nth_unstable_by((lo + hi) / 2, f64::total_cmp).1;
    if !(q > 0.0 && q.is_finite()) {
        return None;
    }
    let whole = risers
        .iter()
        .filter(|&&d| {
            let m = d / q;
            m.round() >= 1.0 && (m - m.round()).abs() < 0.2
        })
        .count();
    (whole as f64 >= DISPARITY_MIN_WHOLE * risers.len() as f64).then_some(q)
}

/// A pinhole frame whose inverse depth is a staircase ([`disparity_step`]) and whose σ, read on the inverse depth in
/// steps, is under [`DISPARITY_MAX_SIGMA`]: the inverse depth is rounded to its steps, dequantised
/// ([`dequantise`], step 1) and turned back into depth. The step reported, and the noise floor it sets, is the depth
/// step at the frame's median sampled depth. `None` for any other frame.
fn disparity_staircase(range: &RangeImage, noise: &mut Vec<f64>, scratch: &mut Scratch) -> Option<Prepared> {
    let q = disparity_step(range, &mut scratch.risers)?;
    let mut inverse = std::mem::take(&mut scratch.inverse);
    inverse.clear();
    inverse.extend(
        range
            .as_slice()
            .iter()
            .map(|&r| if r.is_finite() && r > 0.0 { (1.0 / f64::from(r) / q) as f32 } else { f32::NAN }),
    );
    let steps = RangeImage::from_vec(range.width(), range.height(), inverse).expect("one value per pixel");
    let sigma = planefit::noise::sigma_sampled_with(&steps, SAMPLE_STRIDE, noise);
    let mut inverse = steps.into_vec();
    // NaN (too few windows) is no staircase.
    if sigma.is_nan() || sigma >= DISPARITY_MAX_SIGMA {
        scratch.inverse = inverse;
        return None;
    }
    // The depth step at the median depth of the sampled pixels: q · z².
    let Some(z) = median_depth(range, &mut scratch.risers) else {
        scratch.inverse = inverse;
        return None;
    };
    inverse.iter_mut().for_each(|u| *u = u.round());
    let steps = RangeImage::from_vec(range.width(), range.height(), inverse).expect("one value per pixel");
    let mut depth = dequantise(&steps, 1.0, scratch);
    scratch.inverse = steps.into_vec();
    depth.as_mut_slice().iter_mut().for_each(|u| {
        *u = if u.is_finite() && *u > 0.0 { (1.0 / (f64::from(*u) * q)) as f32 } else { f32::NAN }
    });
    let step = q * z * z;
    tracing::debug!(q, step, sigma, "disparity staircase: dequantised");
    Some(Prepared { dequantised: Some((step, depth)), sigma: None, inverse_depth: true })
}

/// The median of the valid depths of every [`SAMPLE_STRIDE`]-th pixel of every [`SAMPLE_STRIDE`]-th row; `z` is
/// working memory.
fn median_depth(range: &RangeImage, z: &mut Vec<f64>) -> Option<f64> {
    let w = range.width() as usize;
    z.clear();
    z.extend(
        range
            .as_slice()
            .chunks_exact(w.max(1))
            .step_by(SAMPLE_STRIDE)
            .flat_map(|row| row.iter().step_by(SAMPLE_STRIDE).copied())
            .filter(|v| v.is_finite() && *v > 0.0)
            .map(f64::from),
    );
    if z.is_empty() {
        return None;
    }
    let k = z.len() / 2;
    let (_, m, _) = z.select_nth_unstable_by(k, f64::total_cmp);
    Some(*m)
}

/// What [`for_config`] prepared an image as.
#[derive(Debug, Default)]
pub struct Prepared {
    /// The step and the image dequantised, if it is a staircase and `pipeline.dequantise` is on (`None`: the
    /// image as it is).
    pub dequantised: Option<(f64, RangeImage)>,
    /// The σ the test read when it did not dequantise (for the working units, which read the same σ; `None` if
    /// the test read none).
    pub sigma: Option<f64>,
    /// Whether the staircase dequantised was one of the inverse depth (a disparity's steps), not of the depth.
    pub inverse_depth: bool,
}

/// The noise σ the working units take a dequantised image to have at least, as a share of its step's rounding
/// error `q / √12`. Noise-free steps dequantise to planes that windows fit to ~1e-6 (σ read 2e-6 to 0.02 on
/// rendered disparity), and scaled to the working σ by that, the ramps' small misfits at terrace ends and
/// corners became jumps (a grid frame was scaled 10⁵ times: `disparity@2` scored 2.10 of 15.10 on the grid
/// camera). The dequantisation's own error on a plane is under 0.05 q RMS (0.17 of the rounding error); the share
/// was swept from 0.05 to 0.3 (docs/results.md, "Dequantised depth keeps a noise floor").
pub const SIGMA_FLOOR_SHARE: f64 = 0.1;

impl Prepared {
    /// The least noise σ the working units may take the image to have, in its own units: [`SIGMA_FLOOR_SHARE`]
    /// of the rounding error if it was dequantised, else 0 (the working units find the floor of a staircase
    /// they read themselves).
    #[must_use]
    pub fn sigma_floor(&self) -> f64 {
        self.dequantised.as_ref().map_or(0.0, |(q, _)| SIGMA_FLOOR_SHARE * q / 12f64.sqrt())
    }
}

/// `range`, depth rounded to steps of `q`, dequantised (module docs); NaN stays NaN. The image lives in the
/// memory of `scratch` (give it back with [`Scratch::recycle`]).
///
/// # Panics
/// If `q` is not positive and finite.
#[must_use]
pub fn dequantise(range: &RangeImage, q: f64, scratch: &mut Scratch) -> RangeImage {
    assert!(q > 0.0 && q.is_finite(), "the step must be positive, got {q}");
    let (w, h) = (range.width() as usize, range.height() as usize);
    let v = range.as_slice();
    let Scratch { down, up, ramp, ramp_width, same, values, members, .. } = scratch;
    terrace_neighbours(v, (w, h), q, same);
    // Distances to the risers down and up within each terrace.
    // Seeds: the pixels beside a riser down, and beside a riser up.
    riser_seeds(v, (w, h), q, down, up);
    chamfer_pair((w, h), same, down, up);
    let mut out = std::mem::take(values);
    out.clear();
    out.extend(v.iter().zip(down.iter().zip(up.iter())).map(|(&s, (&dd, &du))| {
        if dd.is_finite() && du.is_finite() {
            (f64::from(s) + q * (f64::from(dd) / f64::from(dd + du) - 0.5)) as f32
        } else {
            s
        }
    }));
    // A terrace with a riser on one side only (cut by the image border, no data or a jump; a ridge or a
    // valley): the ramp leaves its riser at the slope of the terrace beyond it, up to half a step away.
    for (dir, near, far) in [(-1.0, &*down, &*up), (1.0, &*up, &*down)] {
        // The pixels that can take part: reached from the near riser, in terraces without a far one (a few per cent
        // of a frame). No other pixel is reached from a seed below: the seeds are pixels beside the near riser, and
        // the passes are those that reached them from that riser.
        members.clear();
        members.extend((0..w * h).filter(|&i| near[i].is_finite() && far[i].is_infinite()).map(as_index));
        unreached([&mut *ramp, &mut *ramp_width], w * h);
        // Seeds: its pixels beside the riser, carrying the width of the terrace beyond where it has both risers
        // (the smallest of those beside it, in the order left, right, up, down).
        for i in members.iter().map(|&i| i as usize) {
            let (x, y) = (i % w, i / w);
            if near[i] != 0.5 || !v[i].is_finite() {
                continue;
            }
            let width = four_neighbours((x, y), (w, h))
                .into_iter()
                .filter(|n| n.0)
                .filter_map(|(_, j)| {
                    let width = down[j] + up[j];
                    (relation(v[i], v[j], q) == Some(dir) && width.is_finite()).then_some(width)
                })
                .reduce(f32::min);
            if let Some(width) = width {
                (ramp[i], ramp_width[i]) = (0.5, width);
            }
        }
        chamfer_carrying(w, same, members, ramp, ramp_width);
        for i in members.iter().map(|&i| i as usize) {
            if ramp[i].is_finite() {
                let rise = (f64::from(ramp[i]) / f64::from(ramp_width[i])).min(1.0);
                out[i] = (f64::from(v[i]) + dir * q * (0.5 - rise)) as f32;
            }
        }
    }
    RangeImage::from_vec(range.width(), range.height(), out).expect("one value per pixel")
}

/// How two stored values relate on a staircase of step `q`: the same terrace, a riser of one step (`±1`: the
/// second one step above or below the first), or neither (a jump, or no data).
#[inline]
fn relation(a: f32, b: f32, q: f64) -> Option<f64> {
    // Compared with multiples of q rather than divided by it: the same decisions on quantised depth, whose
    // differences are whole multiples of q (or, for nearly uniform steps, at least half of it), at a fraction of
    // the cost.
    let d = f64::from(b) - f64::from(a);
    if d.abs() < 0.5 * q {
        Some(0.0)
    } else if d.abs() < 1.5 * q {
        Some(d.signum())
    } else {
        None
    }
}

/// Sets `down` and `up` (per pixel of `v`, `w × h`) to 0.5 at the pixels with a 4-neighbour one step below, and
/// one step above, on a staircase of step `q` ([`relation`]: a riser lies between the two), +∞ elsewhere.
fn riser_seeds(v: &[f32], (w, h): (usize, usize), q: f64, down: &mut Vec<f32>, up: &mut Vec<f32>) {
    // The kernel writes every pixel of both maps: they only need the frame's length, not a fill of +∞ first.
    for m in [&mut *down, &mut *up] {
        m.resize(w * h, f32::INFINITY);
    }
    // Compiled for each instruction set (`isa::dispatch`): subtractions and comparisons only, the same bits on each.
    isa::dispatch(
        #[inline(always)]
        || riser_seeds_kernel(v, (w, h), q, down, up),
    );
}

/// [`riser_seeds`]' body, compiled for each instruction set ([`isa::dispatch`]).
#[inline(always)]
fn riser_seeds_kernel(v: &[f32], (w, h): (usize, usize), q: f64, down: &mut [f32], up: &mut [f32]) {
    let (half, one_half) = (0.5 * q, 1.5 * q);
    // [`relation`] without branches: whether `b` lies one step below `a`, and one step above (never for NaN).
    let riser = |a: f32, b: f32| {
        let d = f64::from(b) - f64::from(a);
        let step = (half..one_half).contains(&d.abs());
        (step & (d < 0.0), step & (d > 0.0))
    };
    let seed = |(below, above): (bool, bool)| {
        (if below { 0.5 } else { f32::INFINITY }, if above { 0.5 } else { f32::INFINITY })
    };
    let at = |i: usize, neighbours: [(bool, usize); 4]| {
        let (mut below, mut above) = (false, false);
        for (ok, j) in neighbours {
            let (b, a) = if ok { riser(v[i], v[j]) } else { (false, false) };
            (below, above) = (below | b, above | a);
        }
        seed((below, above))
    };
    for y in 0..h {
        if y == 0 || y + 1 == h || w < 3 {
            for x in 0..w {
                let i = y * w + x;
                (down[i], up[i]) = at(i, four_neighbours((x, y), (w, h)));
            }
            continue;
        }
        // Inside the image, each pixel has all four neighbours.
        let (above, row, below) =
            (&v[(y - 1) * w..y * w], &v[y * w..(y + 1) * w], &v[(y + 1) * w..(y + 2) * w]);
        let (row_d, row_u) = (&mut down[y * w..(y + 1) * w], &mut up[y * w..(y + 1) * w]);
        for x in 1..w - 1 {
            let a = row[x];
            let ((b0, a0), (b1, a1)) = (riser(a, row[x - 1]), riser(a, row[x + 1]));
            let ((b2, a2), (b3, a3)) = (riser(a, above[x]), riser(a, below[x]));
            (row_d[x], row_u[x]) = seed((b0 | b1 | b2 | b3, a0 | a1 | a2 | a3));
        }
        for x in [0, w - 1] {
            let i = y * w + x;
            (down[i], up[i]) = at(i, four_neighbours((x, y), (w, h)));
        }
    }
}

/// Makes each map `n` values of +∞ (no seed reached yet), reusing its memory.
fn unreached(maps: [&mut Vec<f32>; 2], n: usize) {
    for m in maps {
        m.clear();
        m.resize(n, f32::INFINITY);
    }
}

/// The 4-neighbours of pixel `(x, y)` of a `w × h` image, left, right, up, down: whether each lies inside, and
/// its index (meaningless where it does not).
#[inline(always)]
fn four_neighbours((x, y): (usize, usize), (w, h): (usize, usize)) -> [(bool, usize); 4] {
    let i = y * w + x;
    [(x > 0, i.wrapping_sub(1)), (x + 1 < w, i + 1), (y > 0, i.wrapping_sub(w)), (y + 1 < h, i + w)]
}

/// Sets `same[i]` to the neighbours of pixel `i` (of `v`, `w × h`) that lie inside the image and in its terrace of a
/// staircase of step `q` (values less than half a step apart; no data is in no terrace): bit 0 left, 1 up-left, 2
/// up, 3 up-right, 4 right, 5 down-right, 6 down, 7 down-left.
fn terrace_neighbours(v: &[f32], (w, h): (usize, usize), q: f64, same: &mut Vec<u8>) {
    same.clear();
    same.resize(w * h, 0);
    // Compiled for each instruction set (`isa::dispatch`): subtractions and comparisons only, the same bits on each.
    isa::dispatch(
        #[inline(always)]
        || terrace_neighbours_kernel(v, (w, h), q, same),
    );
}

/// [`terrace_neighbours`]' body, compiled for each instruction set ([`isa::dispatch`]).
#[inline(always)]
fn terrace_neighbours_kernel(v: &[f32], (w, h): (usize, usize), q: f64, same: &mut [u8]) {
    let half = 0.5 * q;
    // Each pixel tests its own eight neighbours, without branches: the relation is symmetric (`|b − a|` and
    // `|a − b|` round alike), so both pixels of a pair agree.
    let level = |a: f32, b: f32| u8::from((f64::from(b) - f64::from(a)).abs() < half);
    // Bit k's neighbour offset (dx, dy).
    const OFFSETS: [(isize, isize); 8] =
        [(-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0), (1, 1), (0, 1), (-1, 1)];
    let at_border = |x: usize, y: usize, same: &mut [u8]| {
        let a = v[y * w + x];
        let mut bits = 0;
        for (k, (dx, dy)) in OFFSETS.into_iter().enumerate() {
            let (nx, ny) = (x.wrapping_add_signed(dx), y.wrapping_add_signed(dy));
            if nx < w && ny < h {
                bits |= level(a, v[ny * w + nx]) << k;
            }
        }
        same[y * w + x] = bits;
    };
    for y in 0..h {
        if y == 0 || y + 1 == h || w < 3 {
            (0..w).for_each(|x| at_border(x, y, same));
            continue;
        }
        let (above, row, below) =
            (&v[(y - 1) * w..y * w], &v[y * w..(y + 1) * w], &v[(y + 1) * w..(y + 2) * w]);
        let out = &mut same[y * w..(y + 1) * w];
        for x in 1..w - 1 {
            let a = row[x];
            out[x] = level(a, row[x - 1])
                | level(a, above[x - 1]) << 1
                | level(a, above[x]) << 2
                | level(a, above[x + 1]) << 3
                | level(a, row[x + 1]) << 4
                | level(a, below[x + 1]) << 5
                | level(a, below[x]) << 6
                | level(a, below[x - 1]) << 7;
        }
        at_border(0, y, same);
        at_border(w - 1, y, same);
    }
}

/// Propagates the distance maps `down` and `up` (per pixel, `w × h`, 0.5 beside their risers) within each
/// terrace (`same`, from [`terrace_neighbours`]; 8-neighbour chamfer, 1 and √2): each pixel ends with the smallest
/// seed distance plus path length. Two forward and backward passes: exact on terraces convex enough, an upper bound
/// on the others.
fn chamfer_pair((w, h): (usize, usize), same: &[u8], down: &mut [f32], up: &mut [f32]) {
    // Compiled for each instruction set (`isa::dispatch`): additions and comparisons only, the same bits on each.
    isa::dispatch(
        #[inline(always)]
        || {
            for _ in 0..2 {
                chamfer_pair_pass::<true>((w, h), same, down, up);
                chamfer_pair_pass::<false>((w, h), same, down, up);
            }
        },
    );
}

/// One pass of [`chamfer_pair`]: forward (rows top down, left to right, from the left and the row above: bits 0–3 of
/// [`terrace_neighbours`]), or backward, the same on the image turned half a turn (bits 4–7).
#[inline(always)] // into `isa::dispatch` in `chamfer_pair`
fn chamfer_pair_pass<const FORWARD: bool>(
    (w, h): (usize, usize),
    same: &[u8],
    down: &mut [f32],
    up: &mut [f32],
) {
    // A step to a neighbour outside the pixel's terrace costs +∞; distances are never NaN (+∞ or at least 0.5), so
    // `min` without branches takes the shortest of the paths, whatever their order.
    let cost = |bits: u8, bit: u32, step: f32| if bits & (1 << bit) != 0 { step } else { f32::INFINITY };
    let min = |a: f32, b: f32| if b < a { b } else { a };
    let shift = if FORWARD { 0 } else { 4 };
    for n in 0..h {
        let y = if FORWARD { n } else { h - 1 - n };
        let ((row_d, prev_d), (row_u, prev_u)) =
            (split_rows::<FORWARD>(down, y, w), split_rows::<FORWARD>(up, y, w));
        let bits = &same[y * w..(y + 1) * w];
        // From the previous row first (bits 1–3: behind, level and ahead), a row at a time: the pass leaves those
        // values as they are. Forward, behind is x − 1 and ahead x + 1; backward the other way round. The pixels
        // at the row's ends have no neighbour beyond it (their bits say so).
        if !prev_d.is_empty() {
            let from_prev = |x: usize, behind: usize, ahead: usize, row: &mut [f32], prev: &[f32]| {
                let b = bits[x] >> shift;
                let (c1, c2, c3) = (cost(b, 1, STEPS[1]), cost(b, 2, STEPS[2]), cost(b, 3, STEPS[3]));
                row[x] = min(min(min(row[x], prev[behind] + c1), prev[x] + c2), prev[ahead] + c3);
            };
            // The row's ends, whose neighbours beyond it do not exist (their bits are 0: any index will do).
            for x in [0, w - 1] {
                let (left, right) = (x.saturating_sub(1), (x + 1).min(w - 1));
                let (behind, ahead) = if FORWARD { (left, right) } else { (right, left) };
                from_prev(x, behind, ahead, row_d, prev_d);
                from_prev(x, behind, ahead, row_u, prev_u);
            }
            if w > 2 {
                // Both maps in one loop: each pixel's bits and costs are read once.
                let (b, rd, ru) = (&bits[1..w - 1], &mut row_d[1..w - 1], &mut row_u[1..w - 1]);
                let ((db, dc, da), (ub, uc, ua)) =
                    (behind_level_ahead::<FORWARD>(prev_d), behind_level_ahead::<FORWARD>(prev_u));
                for k in 0..w - 2 {
                    let bk = b[k] >> shift;
                    let (c1, c2, c3) = (cost(bk, 1, STEPS[1]), cost(bk, 2, STEPS[2]), cost(bk, 3, STEPS[3]));
                    rd[k] = min(min(min(rd[k], db[k] + c1), dc[k] + c2), da[k] + c3);
                    ru[k] = min(min(min(ru[k], ub[k] + c1), uc[k] + c2), ua[k] + c3);
                }
            }
        }
        // Then along the row (bit 0: the pixel the pass has just left, already final).
        let (mut last_d, mut last_u) = (f32::INFINITY, f32::INFINITY);
        for m in 0..w {
            let x = if FORWARD { m } else { w - 1 - m };
            let c0 = cost(bits[x] >> shift, 0, STEPS[0]);
            (last_d, last_u) = (min(row_d[x], last_d + c0), min(row_u[x], last_u + c0));
            (row_d[x], row_u[x]) = (last_d, last_u);
        }
    }
}

/// The previous row's neighbours of the pixels inside a row (`prev`, that row, at least 3 long): behind, level and
/// ahead of each in the pass's direction, as three slices of its length less 2.
#[inline(always)] // into `isa::dispatch` in `chamfer_pair`
fn behind_level_ahead<const FORWARD: bool>(prev: &[f32]) -> (&[f32], &[f32], &[f32]) {
    let n = prev.len();
    let (left, level, right) = (&prev[..n - 2], &prev[1..n - 1], &prev[2..]);
    if FORWARD { (left, level, right) } else { (right, level, left) }
}

/// Row `y` of `map` (rows of `w`), writable, and the row a pass came from: the one above going forward, the one below
/// going backward (empty where there is none).
#[inline(always)] // into `isa::dispatch` in `chamfer_pair`
fn split_rows<const FORWARD: bool>(map: &mut [f32], y: usize, w: usize) -> (&mut [f32], &[f32]) {
    if FORWARD {
        let (above, rest) = map.split_at_mut(y * w);
        (&mut rest[..w], &above[above.len().saturating_sub(w)..])
    } else {
        let (upto, below) = map.split_at_mut((y + 1) * w);
        (&mut upto[y * w..], &below[..below.len().min(w)])
    }
}

/// The step lengths to the neighbours a chamfer pass relaxes a pixel from, forward (left, up-left, up,
/// up-right: bits 0–3 of [`terrace_neighbours`]) and backward (the same turned half a turn: right, down-right, down,
/// down-left, bits 4–7).
const STEPS: [f32; 4] = [1.0, std::f32::consts::SQRT_2, 1.0, std::f32::consts::SQRT_2];

/// [`chamfer_pair`] for one distance map `map` that carries `values` from the seed it came from (the first neighbour,
/// in the order of [`STEPS`], that offers a shorter path), over the pixels `members` only (in raster order, of
/// an image `w` wide): `map` is +∞ at every other pixel.
fn chamfer_carrying(w: usize, same: &[u8], members: &[u32], map: &mut [f32], values: &mut [f32]) {
    let offsets = [1, w + 1, w, w.saturating_sub(1)];
    let relax = |i: usize, forward: bool, map: &mut [f32], values: &mut [f32]| {
        let bits = if forward { same[i] & 0xF } else { same[i] >> 4 };
        if bits == 0 {
            return;
        }
        let (mut best, mut src) = (map[i], usize::MAX);
        for (b, &c) in STEPS.iter().enumerate() {
            if bits & (1 << b) != 0 {
                let j = if forward { i - offsets[b] } else { i + offsets[b] };
                let through = map[j] + c;
                if through < best {
                    (best, src) = (through, j);
                }
            }
        }
        if src != usize::MAX {
            map[i] = best;
            values[i] = values[src];
        }
    };
    for _ in 0..2 {
        members.iter().for_each(|&i| relax(i as usize, true, map, values));
        members.iter().rev().for_each(|&i| relax(i as usize, false, map, values));
    }
}

/// A pixel's index in a list of pixels (images are at most `u32::MAX` pixels: `rangeimage` refuses larger).
fn as_index(i: usize) -> u32 {
    u32::try_from(i).expect("an image of at most u32::MAX pixels")
}

#[cfg(test)]
mod tests {
    use super::*;
    use rangeimage::Grid;

    /// A deterministic pattern in [−1, 1) per pixel.
    fn pattern(x: u32, y: u32) -> f64 {
        f64::from((x * 7919 + y * 104_729 + (x * y) % 31) % 101) / 50.5 - 1.0
    }

    /// The plane `z(x, y)`, plus `noise` times the pattern, rounded to steps of `q`.
    fn rounded(z: impl Fn(f64, f64) -> f64, q: f64, noise: f64) -> RangeImage {
        Grid::from_fn(160, 120, |x, y| {
            let v = z(f64::from(x), f64::from(y)) + noise * pattern(x, y);
            ((v / q).round() * q) as f32
        })
    }

    /// A floor seen by a Kinect-like camera (f = 150 px, 1.2 m below it, pitched down 20°), its disparity rounded to
    /// 1/8 px of f · b = 150 px × 75 mm, plus `noise` (m, at 1 m, growing with z²) times the pattern before the
    /// rounding, its depth then stored in `unit` metres; no data beyond 4 m.
    fn kinect_floor(noise: f64, unit: f64, disparity_steps: bool) -> RangeImage {
        let (f, fb) = (150.0, 150.0 * 0.075);
        let (s, c) = (20f64.to_radians().sin(), 20f64.to_radians().cos());
        Grid::from_fn(160, 120, |x, y| {
            // The ray's height drop per metre of depth; the floor lies 1.2 m below the camera.
            let down = (f64::from(y) - 59.5) / f * c + s;
            if down <= 0.0 {
                return f32::NAN;
            }
            let z = 1.2 / down;
            if z > 4.0 {
                return f32::NAN;
            }
            let z = z + noise * z * z * pattern(x, y);
            let z = if disparity_steps { fb / ((fb / z * 8.0).round() / 8.0) } else { z };
            ((z / unit).round() * unit) as f32
        })
    }

    #[test]
    fn a_disparity_staircase_is_found_and_dequantised_in_inverse_depth() {
        let exact = kinect_floor(0.0, 1e-9, false);
        // TUM's 0.2 mm units: the step of the inverse depth is 1 / (8 f b).
        let img = kinect_floor(0.0, 0.0002, true);
        let q = disparity_step(&img, &mut Vec::new()).expect("a disparity staircase");
        let expected = 1.0 / (8.0 * 150.0 * 0.075);
        assert!((q / expected - 1.0).abs() < 0.02, "step {q}, expected {expected}");
        let mut scratch = Scratch::default();
        let prepared = disparity_staircase(&img, &mut Vec::new(), &mut scratch).expect("dequantised");
        let (step, out) = prepared.dequantised.expect("dequantised");
        assert!(step > 0.0 && step.is_finite());
        // Much nearer the floor than the stored terraces, and within half a step of them, in inverse depth (where the
        // steps are even).
        let (mut se_in, mut se_out, mut n) = (0.0, 0.0, 0);
        for (x, y, &t) in exact.enumerate() {
            if !t.is_finite() {
                assert!(!out[(x, y)].is_finite());
                continue;
            }
            let (t, s, o) = (f64::from(t), f64::from(img[(x, y)]), f64::from(out[(x, y)]));
            assert!((1.0 / o - 1.0 / s).abs() <= 0.5 * q * 1.05 + 1e-9, "({x}, {y}): {o} against {s}");
            se_in += (1.0 / s - 1.0 / t).powi(2);
            se_out += (1.0 / o - 1.0 / t).powi(2);
            n += 1;
        }
        let (rms_in, rms_out) = ((se_in / f64::from(n)).sqrt() / q, (se_out / f64::from(n)).sqrt() / q);
        assert!(rms_in > 0.25, "the staircase's own error, {rms_in} steps");
        // Terraces 2 rows wide here: the ramps between risers are as fine as pixels allow (0.14 steps).
        assert!(rms_out < 0.2, "dequantised: {rms_out} steps from the floor (stored: {rms_in})");
    }

    #[test]
    fn depth_without_disparity_steps_is_no_disparity_staircase() {
        // Continuous depth with noise, depth in uniform steps (8-bit renderings such as the NYU frames), and a
        // disparity staircase whose noise dithers its risers: none is dequantised.
        let noisy = kinect_floor(0.004, 1e-6, false);
        assert_eq!(disparity_step(&noisy, &mut Vec::new()), None);
        let uniform = kinect_floor(0.0, 0.01, false);
        assert_eq!(disparity_step(&uniform, &mut Vec::new()), None);
        let dithered = kinect_floor(0.02, 0.0002, true);
        assert!(disparity_staircase(&dithered, &mut Vec::new(), &mut Scratch::default()).is_none());
    }

    fn dequantised(img: &RangeImage, q: f64) -> RangeImage {
        dequantise(img, q, &mut Scratch::default())
    }

    #[test]
    fn a_staircase_becomes_its_plane_and_rounds_back_to_itself() {
        // Risers 25 px apart across the slope.
        let plane = |x: f64, y: f64| 100.0 + 0.11 * x + 0.045 * y;
        let q = 3.0;
        let img = rounded(plane, q, 0.0);
        let out = dequantised(&img, q);
        let (mut se_in, mut se_out, mut n) = (0.0, 0.0, 0);
        for (x, y, &s) in img.enumerate() {
            let o = f64::from(out[(x, y)]);
            assert!(
                (o - f64::from(s)).abs() <= q / 2.0 + 1e-4,
                "({x}, {y}): {o} is not within half a step of {s}"
            );
            // The terraces the image border cuts included (they ramp at their neighbour's slope).
            let t = plane(f64::from(x), f64::from(y));
            se_in += (f64::from(s) - t).powi(2);
            se_out += (o - t).powi(2);
            n += 1;
        }
        let (rms_in, rms_out) = ((se_in / f64::from(n)).sqrt(), (se_out / f64::from(n)).sqrt());
        assert!(rms_in > 0.25 * q, "the staircase's own error, {rms_in}");
        assert!(rms_out < 0.05 * q, "dequantised: {rms_out} from the plane (stored: {rms_in})");
    }

    #[test]
    fn a_ridge_keeps_its_roof() {
        // Two planes meeting at a ridge along x = 80: the top terrace has risers down on both sides.
        let roof = |x: f64, y: f64| 100.0 + 0.2 * (40.0 - (x - 80.0).abs()) + 0.05 * y;
        let q = 2.0;
        let img = rounded(roof, q, 0.0);
        let out = dequantised(&img, q);
        let (mut se, mut n, mut worst) = (0.0, 0, 0.0f64);
        for (x, y, _) in img.enumerate() {
            let e = f64::from(out[(x, y)]) - roof(f64::from(x), f64::from(y));
            se += e * e;
            n += 1;
            worst = worst.max(e.abs());
        }
        let rms = (se / f64::from(n)).sqrt();
        // The stored staircase is q / √12 = 0.29 q from the roof; the crest, where the two ramps meet within the
        // top terrace, is the worst (0.36 q here, within half a step as everywhere).
        assert!(rms < 0.1 * q, "{rms} from the roof");
        assert!(worst <= 0.5 * q + 1e-4, "{worst} from the roof");
    }

    #[test]
    fn jumps_and_no_data_are_kept() {
        let q = 2.0;
        // A ramp whose right half lies 10 steps higher, and a hole.
        let mut img = rounded(|x, y| 50.0 + 0.1 * x + 0.02 * y + if x >= 48.0 { 20.0 } else { 0.0 }, q, 0.0);
        for y in 20..30 {
            for x in 10..20 {
                img[(x, y)] = f32::NAN;
            }
        }
        let out = dequantised(&img, q);
        for (x, y, &s) in img.enumerate() {
            let o = out[(x, y)];
            assert_eq!(s.is_nan(), o.is_nan(), "({x}, {y})");
            if s.is_finite() {
                assert!((f64::from(o) - f64::from(s)).abs() <= q / 2.0 + 1e-4, "({x}, {y})");
            }
        }
        // A flat terrace bordered only by a jump keeps its value.
        let mut flat = Grid::new(40, 30, 10.0f32);
        for y in 0..30 {
            for x in 20..40 {
                flat[(x, y)] = 30.0;
            }
        }
        assert_eq!(dequantised(&flat, q), flat);
    }

    #[test]
    fn only_staircases_are_dequantised() {
        let plane = |x: f64, y: f64| 100.0 + 0.31 * x + 0.17 * y;
        let q = 3.0;
        let mut noise = Vec::new();
        for screen in [false, true] {
            let mut test = |img: &RangeImage| staircase(img, &mut noise, screen);
            let stairs = test(&rounded(plane, q, 0.0));
            assert_eq!(stairs.step, Some(q), "screen {screen}");
            assert!(stairs.sigma.is_some_and(|s| s < q / 12f64.sqrt()), "screen {screen}: {stairs:?}");
            // Noise of ±1.5 steps before the rounding dithers the risers: noise, not a staircase.
            let noisy = test(&rounded(plane, q, 1.5 * q));
            assert_eq!(noisy.step, None, "screen {screen}");
            assert_eq!(noisy.sigma.is_some(), !screen, "the screen stops before the full σ");
            // Continuous depth has no step.
            let smooth = Grid::from_fn(160, 120, |x, y| plane(f64::from(x), f64::from(y)) as f32);
            assert_eq!(test(&smooth).step, None, "screen {screen}");
        }
    }

    #[test]
    fn tiny_and_ragged_images_keep_every_value_within_half_a_step() {
        // Single rows and columns, no data, jumps: the passes' row slices and neighbour bits at every border.
        for (w, h) in [(0, 0), (0, 3), (1, 1), (1, 6), (6, 1), (2, 3), (7, 4), (33, 9)] {
            let img: RangeImage = Grid::from_fn(w, h, |x, y| {
                if (x * 5 + y * 3) % 11 == 4 {
                    f32::NAN
                } else {
                    (f64::from(x) * 0.4 + f64::from(y) * 0.3 + 3.0 * f64::from(u8::from((x + y) % 9 == 0)))
                        .round() as f32
                }
            });
            let v = img.as_slice();
            let (wu, hu) = (w as usize, h as usize);
            let mut same = Vec::new();
            terrace_neighbours(v, (wu, hu), 1.0, &mut same);
            for (x, y, _) in img.enumerate() {
                let (x, y) = (x as isize, y as isize);
                let i = (y * w as isize + x) as usize;
                for (bit, (dx, dy)) in [(-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0), (1, 1), (0, 1), (-1, 1)]
                    .into_iter()
                    .enumerate()
                {
                    let (nx, ny) = (x + dx, y + dy);
                    let inside = nx >= 0 && ny >= 0 && nx < w as isize && ny < h as isize;
                    let expected = inside
                        && (f64::from(v[(ny * w as isize + nx) as usize]) - f64::from(v[i])).abs() < 0.5;
                    assert_eq!(same[i] & (1 << bit) != 0, expected, "{w}×{h} ({x}, {y}) bit {bit}");
                }
            }
            let out = dequantised(&img, 1.0);
            for (s, o) in v.iter().zip(out.as_slice()) {
                assert!(s.is_nan() && o.is_nan() || (o - s).abs() <= 0.5 + 1e-4, "{w}×{h}: {s} became {o}");
            }
        }
    }

    /// [`dequantise`] as first written, pixel by pixel over the whole image: the oracle its faster passes must match
    /// bit for bit (the seeds of every map from all four neighbours, both chamfer rounds over every pixel, the ramps'
    /// passes over every pixel of a terrace without a far riser).
    fn reference(v: &[f32], (w, h): (usize, usize), q: f64) -> Vec<f32> {
        let idx = |x: usize, y: usize| y * w + x;
        let inside = |x: isize, y: isize| x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h;
        // [left, up-left, up, up-right, right, down-right, down, down-left]
        let dirs: [(isize, isize); 8] =
            [(-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0), (1, 1), (0, 1), (-1, 1)];
        let four = [(-1, 0), (1, 0), (0, -1), (0, 1)];
        let neighbour = |i: usize, (dx, dy): (isize, isize)| {
            let (x, y) = ((i % w) as isize + dx, (i / w) as isize + dy);
            inside(x, y).then(|| idx(x as usize, y as usize))
        };
        let same =
            |i: usize, k: usize| neighbour(i, dirs[k]).filter(|&j| relation(v[i], v[j], q) == Some(0.0));
        // Chamfer rounds over every pixel: forward from bits 0–3, backward from 4–7, each carrying `values`
        // from the first neighbour (in bit order) that offers a shorter path; `takes_part` pixels only.
        let chamfer = |map: &mut Vec<f32>, values: &mut Vec<f32>, takes_part: &dyn Fn(usize) -> bool| {
            for _ in 0..2 {
                for forward in [true, false] {
                    let order: Vec<usize> =
                        if forward { (0..w * h).collect() } else { (0..w * h).rev().collect() };
                    for i in order {
                        if !takes_part(i) {
                            continue;
                        }
                        let (mut best, mut src) = (map[i], None);
                        for (b, &c) in STEPS.iter().enumerate() {
                            if let Some(j) = same(i, if forward { b } else { b + 4 })
                                && map[j] + c < best
                            {
                                (best, src) = (map[j] + c, Some(j));
                            }
                        }
                        if let Some(j) = src {
                            map[i] = best;
                            values[i] = values[j];
                        }
                    }
                }
            }
        };
        let seeds = |dir: f64| -> Vec<f32> {
            (0..w * h)
                .map(|i| {
                    let riser = four
                        .iter()
                        .any(|&d| neighbour(i, d).is_some_and(|j| relation(v[i], v[j], q) == Some(dir)));
                    if riser { 0.5 } else { f32::INFINITY }
                })
                .collect()
        };
        let (mut down, mut up) = (seeds(-1.0), seeds(1.0));
        let mut unused = vec![0.0; w * h];
        chamfer(&mut down, &mut unused, &|_| true);
        chamfer(&mut up, &mut unused, &|_| true);
        let mut out: Vec<f32> = (0..w * h)
            .map(|i| {
                if down[i].is_finite() && up[i].is_finite() {
                    (f64::from(v[i]) + q * (f64::from(down[i]) / f64::from(down[i] + up[i]) - 0.5)) as f32
                } else {
                    v[i]
                }
            })
            .collect();
        for (dir, near, far) in [(-1.0, &down, &up), (1.0, &up, &down)] {
            let (mut ramp, mut width) = (vec![f32::INFINITY; w * h], vec![f32::INFINITY; w * h]);
            for i in 0..w * h {
                if near[i] != 0.5 || far[i].is_finite() || !v[i].is_finite() {
                    continue;
                }
                let beyond = four
                    .iter()
                    .filter_map(|&d| neighbour(i, d))
                    .filter(|&j| relation(v[i], v[j], q) == Some(dir) && (down[j] + up[j]).is_finite())
                    .map(|j| down[j] + up[j])
                    .reduce(f32::min);
                if let Some(b) = beyond {
                    (ramp[i], width[i]) = (0.5, b);
                }
            }
            chamfer(&mut ramp, &mut width, &|i| far[i].is_infinite());
            for i in 0..w * h {
                if near[i].is_finite() && far[i].is_infinite() && ramp[i].is_finite() {
                    let rise = (f64::from(ramp[i]) / f64::from(width[i])).min(1.0);
                    out[i] = (f64::from(v[i]) + dir * q * (0.5 - rise)) as f32;
                }
            }
        }
        out
    }

    /// A staircase of step `q` for the property tests: planes of random slopes in random bands, with ridges, valleys,
    /// jumps and no data, rounded to steps of `q` (the size, planes and holes from `seed`).
    fn random_staircase(w: u32, h: u32, seed: u64, q: f64) -> RangeImage {
        let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut next = move || {
            // xorshift64*: deterministic and portable.
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            (state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
        };
        let planes: Vec<[f64; 3]> =
            (0..4).map(|_| [next() * 40.0, next() * 0.8 - 0.4, next() * 0.8 - 0.4]).collect();
        let (cut_x, cut_y, hole) = (next() * f64::from(w), next() * f64::from(h), next() * 0.15);
        let hole_seed = (next() * 1000.0) as u32;
        Grid::from_fn(w, h, |x, y| {
            let (fx, fy) = (f64::from(x), f64::from(y));
            let k = usize::from(fx > cut_x) + 2 * usize::from(fy > cut_y + 0.3 * (fx - cut_x));
            let [c, a, b] = planes[k];
            // A roof: the slope turns at the middle of the band (a ridge or a valley).
            let z = c + a * (fx - cut_x).abs() + b * fy;
            let dropped = f64::from((x * 7919 + y * 104_729 + hole_seed) % 1000) < hole * 1000.0;
            if dropped { f32::NAN } else { ((z / q).round() * q) as f32 }
        })
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config {
            cases: 96,
            rng_seed: proptest::test_runner::RngSeed::Fixed(7),
            failure_persistence: None,
            ..proptest::test_runner::Config::default()
        })]

        /// The faster passes (seeds from rows, chamfer rows at a time, the ramps over their members only) give the
        /// reference's bits on random staircases, from single pixels to ragged frames with holes and jumps.
        #[test]
        fn dequantise_matches_the_pixel_by_pixel_reference(
            w in 0u32..48,
            h in 0u32..40,
            seed in proptest::prelude::any::<u64>(),
            q in proptest::prelude::prop_oneof![proptest::prelude::Just(1.0), proptest::prelude::Just(0.25), proptest::prelude::Just(3.0)],
        ) {
            let img = random_staircase(w, h, seed, q);
            let expected = reference(img.as_slice(), (w as usize, h as usize), q);
            let got = dequantised(&img, q);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            proptest::prop_assert_eq!(bits(got.as_slice()), bits(&expected));
            // The same with working memory a larger frame left behind (a stream of frames reuses it).
            let mut used = Scratch::default();
            let first = dequantise(&random_staircase(47, 39, !seed, q), q, &mut used);
            used.recycle(first);
            let again = dequantise(&img, q, &mut used);
            proptest::prop_assert_eq!(bits(again.as_slice()), bits(&expected));
        }
    }

    #[test]
    fn every_instruction_set_dequantises_to_the_same_bits() {
        // The passes run compiled for each instruction set of this CPU (isa::dispatch).
        let img = random_staircase(97, 61, 11, 1.0);
        let floor = kinect_floor(0.0, 0.0002, true);
        let run = || {
            let mut scratch = Scratch::default();
            let a = dequantise(&img, 1.0, &mut scratch).into_vec();
            let b =
                disparity_staircase(&floor, &mut Vec::new(), &mut scratch).expect("a disparity staircase");
            let b = b.dequantised.expect("dequantised").1.into_vec();
            (
                a.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                b.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            )
        };
        let baseline = isa::with_isa(isa::Isa::Baseline, run).expect("baseline");
        for other in isa::Isa::available() {
            assert!(isa::with_isa(other, run).expect("available") == baseline, "{} differs", other.name());
        }
    }
}
