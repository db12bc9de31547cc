//! Per-pixel local planes, derivatives and curvatures of a range image (docs/method.md §3.1).
//!
//! - [`fit_planes`]: least-squares plane `z = a·x + b·y + c` per pixel over the valid pixels of a `w × w` window,
//!   x and y measured from the image centre.
//! - [`compute`]: the [`SurfaceFeatures`] the later stages read: the plane, Gaussian and mean curvature (from the
//!   derivatives of a least-squares quadratic, 2D Savitzky–Golay, kernels in closed form), curvedness and the
//!   windowed standard deviation of K. The principal curvatures follow from H and K
//!   ([`SurfaceFeatures::principal`]).
//! - [`compute_into`]: the same into the grids of a previous result, reusing their memory (frame streams).
//! - [`derivatives`]: the quadratic fit's first and second derivatives themselves, and from them the principal
//!   curvatures without cancellation at umbilics ([`Derivatives::principal`]); [`compute`] uses them row by row
//!   and keeps only the curvatures.
//!
//! All run one pass over the output rows (module `fit`): windows that are entirely valid and inside the image use
//! separable f32 filters on differences of nearby depths (small constant cost per pixel); windows clipped by the
//! border or holding no-data are fitted exactly to their valid pixels in f64. The curvatures (f32, in a form without
//! cancellation at umbilics) and the running-sum standard deviation of K (f64 sums) follow in the same row loop,
//! each output row written straight into its grid, once (new grids are zeroed memory from the allocator, never
//! filled first). [`fit_planes`] runs the engine's plane-only mode.
//! - [`shade`]: a Lambertian rendering for figures.
//!
//! No-data pixels (NaN) never enter a fit, and every output is NaN at no-data pixels.

mod curvature;
mod fit;
mod plane;
mod quadratic;
mod shade;

use rangeimage::ParamError;
use rangeimage::{Grid, PlaneMap, RangeImage, SurfaceFeatures};

/// The `[features]` table of a config file.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Side of the square window of the local plane fit (odd, ≥ 3).
    pub window_px: u32,
    /// Side of the square window of the quadratic (derivative) fit (odd, ≥ 3).
    pub deriv_window_px: u32,
    /// Side of the square window over which the standard deviation of K is taken (odd, ≥ 1).
    pub k_std_window_px: u32,
}

impl Default for Params {
    fn default() -> Self {
        Self { window_px: 5, deriv_window_px: 5, k_std_window_px: 5 }
    }
}

impl Params {
    /// Checks the values; the message names the offending field.
    pub fn validate(&self) -> Result<(), ParamError> {
        let odd = |name: &'static str, v: u32, min: u32| {
            if v < min || v.is_multiple_of(2) || v > 101 {
                Err(ParamError::new(name, format!("must be odd and in {min}..=101, got {v}")))
            } else {
                Ok(())
            }
        };
        odd("features.window_px", self.window_px, 3)?;
        odd("features.deriv_window_px", self.deriv_window_px, 3)?;
        odd("features.k_std_window_px", self.k_std_window_px, 1)
    }
}

/// Computes every field of [`SurfaceFeatures`] for `range` (NaN = no data).
///
/// # Panics
/// In debug builds, if `params` is invalid ([`Params::validate`]: callers validate once, at the edge).
#[must_use]
pub fn compute(range: &RangeImage, params: &Params) -> SurfaceFeatures {
    let _s = tracing::info_span!("features", w = range.width(), h = range.height()).entered();
    debug_assert_eq!(params.validate(), Ok(()), "invalid features params");
    let f = compute_with(range, params, fit::Path::Fast, SurfaceFeatures::default());
    tracing::debug!(
        valid_planes = f.plane.as_slice().iter().filter(|p| p[0].is_finite()).count(),
        valid_k = f.k.as_slice().iter().filter(|v| v.is_finite()).count(),
        "features done"
    );
    f
}

/// [`compute`] into the grids of `out`, reusing their memory: for a stream of frames of one size this saves the
/// fresh zeroed pages the operating system hands out for every new set of output grids. The result is
/// bit-identical to [`compute`]; `out` may hold any size before.
///
/// # Panics
/// In debug builds, if `params` is invalid ([`Params::validate`]: callers validate once, at the edge).
pub fn compute_into(range: &RangeImage, params: &Params, out: &mut SurfaceFeatures) {
    let _s = tracing::info_span!("features", w = range.width(), h = range.height()).entered();
    debug_assert_eq!(params.validate(), Ok(()), "invalid features params");
    let buffers = std::mem::take(out);
    *out = compute_with(range, params, fit::Path::Fast, buffers);
}

/// `g`'s vector if it holds `n` values (they are all overwritten), else a new vector of `n` zeros: zeroed memory
/// comes from the allocator's zeroed pages (`calloc`), so it is not filled first, and the stage writes each value
/// once.
fn reuse_or_zeroed<T: Copy + Default>(g: Grid<T>, n: usize) -> Vec<T> {
    let v = g.into_vec();
    if v.len() == n { v } else { vec![T::default(); n] }
}

/// [`compute`] without the checks; `path` selects the code of the full windows (the tests compare them); the
/// output grids reuse `reuse`'s where they have the image's size.
///
/// One pass over the output rows: the fits of row `y` (one engine, or a second, plane-only one if the plane and
/// the derivative windows differ), its curvatures from the engine's derivative rows, and the standard deviation of
/// K of row `y − r` (r = half the K window), each written straight into its output grid (every value of each row).
fn compute_with(
    range: &RangeImage,
    params: &Params,
    path: fit::Path,
    reuse: SurfaceFeatures,
) -> SurfaceFeatures {
    let (w, h) = range.dimensions();
    let (wu, hu) = (w as usize, h as usize);
    let src = range.as_slice();
    let mut quad = fit::RowFitter::new(src, wu, hu, params.deriv_window_px, path, fit::Fit::Quadratic);
    let mut plane_fitter = (params.window_px != params.deriv_window_px)
        .then(|| fit::RowFitter::new(src, wu, hu, params.window_px, path, fit::Fit::Plane));
    let mut kstd = curvature::WindowStd::new(wu, hu, params.k_std_window_px);
    let rk = (params.k_std_window_px / 2) as usize;
    // One row of derivatives (the curvatures' input), and of the derivative window's planes if they are not kept.
    let mut deriv = fit::deriv_row(wu);
    let mut scratch_plane = vec![[0.0f32; 3]; wu];
    let n = wu * hu;
    let mut plane = reuse_or_zeroed(reuse.plane, n);
    let (mut k, mut hm, mut curvedness, mut k_std) = (
        reuse_or_zeroed(reuse.k, n),
        reuse_or_zeroed(reuse.h, n),
        reuse_or_zeroed(reuse.curvedness, n),
        reuse_or_zeroed(reuse.k_std, n),
    );
    let row = |y: usize| y * wu..(y + 1) * wu;
    for y in 0..hu {
        match &mut plane_fitter {
            None => quad.row(y, &mut plane[row(y)], &mut deriv),
            Some(pf) => {
                quad.row(y, &mut scratch_plane, &mut deriv);
                pf.row(y, &mut plane[row(y)], &mut deriv);
            }
        }
        curvature::curvature_row(&deriv, &mut k[row(y)], &mut hm[row(y)], &mut curvedness[row(y)]);
        kstd.push_row(y, &k[row(y)]);
        if y >= rk {
            let yo = y - rk;
            kstd.out_row(yo, &k[row(yo)], &mut k_std[row(yo)]);
        }
    }
    for yo in hu.saturating_sub(rk)..hu {
        kstd.out_row(yo, &k[row(yo)], &mut k_std[row(yo)]);
    }
    let grid = |v| Grid::from_vec(w, h, v).expect("size matches");
    SurfaceFeatures {
        plane: Grid::from_vec(w, h, plane).expect("size matches"),
        k: grid(k),
        h: grid(hm),
        curvedness: grid(curvedness),
        k_std: grid(k_std),
    }
}

/// The first and second derivatives of the quadratic fit `z = c0 + c1x + c2y + c3x² + c4xy + c5y²` of every pixel
/// (docs/method.md §3.1: `Ix = c1, Iy = c2, Ixx = 2c3, Ixy = c4, Iyy = 2c5`), from [`derivatives`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Derivatives {
    /// First derivatives `[Ix, Iy]`.
    pub gradient: Grid<[f32; 2]>,
    /// Second derivatives `[Ixx, Ixy, Iyy]`.
    pub hessian: Grid<[f32; 3]>,
}

impl Derivatives {
    /// Principal curvatures `[k1, k2]` (k1 ≥ k2) of every pixel, in a form without cancellation at umbilics (its
    /// H, and the K and curvedness from the same derivatives, are bit-identical to [`compute`]'s).
    pub fn principal(&self) -> Grid<[f32; 2]> {
        let (w, h) = self.gradient.dimensions();
        let p = curvature::principal(self.gradient.as_slice(), self.hessian.as_slice());
        Grid::from_vec(w, h, p).expect("size matches")
    }
}

/// The quadratic fit's derivatives of every pixel over the valid pixels of its `deriv_window_px` window: the
/// values [`compute`] derives K, H and curvedness from (bit-identical). NaN at no-data pixels and where the valid
/// pixels do not determine a quadratic.
///
/// # Panics
/// In debug builds, if `params` is invalid ([`Params::validate`]: callers validate once, at the edge).
#[must_use]
pub fn derivatives(range: &RangeImage, params: &Params) -> Derivatives {
    let _s = tracing::info_span!("features::derivatives", w = range.width(), h = range.height()).entered();
    debug_assert_eq!(params.validate(), Ok(()), "invalid features params");
    derivatives_with(range, params.deriv_window_px, fit::Path::Fast)
}

/// [`derivatives`] without the checks, `path` as in [`compute_with`].
fn derivatives_with(range: &RangeImage, window_px: u32, path: fit::Path) -> Derivatives {
    let (w, h) = range.dimensions();
    let (wu, hu) = (w as usize, h as usize);
    let mut quad = fit::RowFitter::new(range.as_slice(), wu, hu, window_px, path, fit::Fit::Quadratic);
    let (mut scratch_plane, mut deriv) = (vec![[0.0f32; 3]; wu], fit::deriv_row(wu));
    let (mut gradient, mut hessian) = (Vec::with_capacity(wu * hu), Vec::with_capacity(wu * hu));
    for y in 0..hu {
        quad.row(y, &mut scratch_plane, &mut deriv);
        let [ix, iy, ixx, ixy, iyy] = &deriv;
        gradient.extend(ix.iter().zip(iy).map(|(&a, &b)| [a, b]));
        hessian.extend(ixx.iter().zip(ixy).zip(iyy).map(|((&a, &b), &c)| [a, b, c]));
    }
    Derivatives {
        gradient: Grid::from_vec(w, h, gradient).expect("size matches"),
        hessian: Grid::from_vec(w, h, hessian).expect("size matches"),
    }
}

/// Fits the local plane `[a, b, c]` of every pixel over the valid pixels of its `window_px × window_px` window.
///
/// x and y are pixel coordinates measured from the image centre `((w−1)/2, (h−1)/2)`, so `c` is the depth of the
/// plane at the image centre. `[NAN; 3]` at no-data pixels and where fewer than 3 non-collinear valid pixels remain.
///
/// # Panics
/// If `window_px` is even or smaller than 3.
#[must_use]
pub fn fit_planes(range: &RangeImage, window_px: u32) -> PlaneMap {
    let _s = tracing::info_span!("features::fit_planes", w = range.width(), h = range.height()).entered();
    assert!(
        window_px >= 3 && !window_px.is_multiple_of(2),
        "plane window must be odd and ≥ 3, got {window_px}"
    );
    plane::fit(range, window_px)
}

/// A Lambertian shading of `range` (light from the viewer's upper left, normals from 5×5 plane fits);
/// no-data pixels are 0 (black), valid pixels 1..=255.
#[must_use]
pub fn shade(range: &RangeImage) -> Grid<u8> {
    let _s = tracing::info_span!("features::shade", w = range.width(), h = range.height()).entered();
    shade::shade_planes(&plane::fit(range, 5))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    const NAN: f32 = f32::NAN;

    fn image(w: u32, h: u32, f: impl Fn(f64, f64) -> f64) -> RangeImage {
        Grid::from_fn(w, h, |x, y| f(f64::from(x), f64::from(y)) as f32)
    }

    #[test]
    fn tilted_plane_gives_its_parameters() {
        let (a, b, c) = (0.3, -0.2, 100.0);
        // Centre of a 40×30 image is (19.5, 14.5).
        let img = image(40, 30, |x, y| a * (x - 19.5) + b * (y - 14.5) + c);
        let f = compute(&img, &Params::default());
        let d = derivatives(&img, &Params::default());
        for (x, y, p) in f.plane.enumerate() {
            assert!((f64::from(p[0]) - a).abs() < 1e-4, "a at ({x}, {y}) = {}", p[0]);
            assert!((f64::from(p[1]) - b).abs() < 1e-4, "b at ({x}, {y}) = {}", p[1]);
            assert!((f64::from(p[2]) - c).abs() < 1e-4, "c at ({x}, {y}) = {}", p[2]);
        }
        for i in 0..img.len() {
            let g = d.gradient.as_slice()[i];
            assert!((f64::from(g[0]) - a).abs() < 1e-4 && (f64::from(g[1]) - b).abs() < 1e-4);
            // The f32 input itself is only exact to ~1e-5 at z = 100, which bounds the second derivatives.
            assert!(f.k.as_slice()[i].abs() < 1e-8, "K = {}", f.k.as_slice()[i]);
            assert!(f.h.as_slice()[i].abs() < 2e-5, "H = {}", f.h.as_slice()[i]);
            assert!(f.curvedness.as_slice()[i].abs() < 2e-5);
            assert!(f.k_std.as_slice()[i].abs() < 1e-8);
            for p in [f.principal().as_slice()[i], d.principal().as_slice()[i]] {
                assert!(p[0].abs() < 2e-5 && p[1].abs() < 2e-5, "principal {p:?}");
            }
        }
    }

    #[test]
    fn compute_into_reuses_buffers_and_equals_compute() {
        let big = image(37, 29, |x, y| 50.0 + 0.02 * x * x - 0.3 * y + if x > 20.0 { 4.0 } else { 0.0 });
        let mut small = image(11, 13, |x, y| 80.0 - 0.5 * x + 0.01 * y * y);
        small[(4, 4)] = NAN;
        // Same size as `big`, other content (holes, a no-data border row): reused grids are overwritten in place,
        // so every value must be written, including where `big` had data and this one has none.
        let mut other = random_image(7, 37, 29, 1.0, true);
        for x in 0..37 {
            other[(x, 0)] = NAN;
        }
        let mut out = SurfaceFeatures::default();
        for p in [Params::default(), Params { window_px: 3, deriv_window_px: 7, k_std_window_px: 9 }] {
            // A first call on another size, then reuse: every value must be the new image's, bit for bit.
            for img in [&big, &small, &big, &other, &big, &other] {
                // A value the call does not write keeps this marker (a NaN payload no stage produces).
                let marker = f32::from_bits(0x7fc0_1234);
                out.plane.as_mut_slice().fill([marker; 3]);
                for g in [&mut out.k, &mut out.h, &mut out.curvedness, &mut out.k_std] {
                    g.as_mut_slice().fill(marker);
                }
                compute_into(img, &p, &mut out);
                assert_eq!(out.k.dimensions(), img.dimensions());
                assert_eq!(bits(&out), bits(&compute(img, &p)));
            }
        }
    }

    #[test]
    fn fit_planes_matches_compute_plane() {
        // The plane-only engine gives the full engine's planes bit for bit (fused 3/5/7 windows, multi-pass 9,
        // holes and ±∞ sending windows to the general path).
        let plane_bits =
            |p: &PlaneMap| p.as_slice().iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
        let clean = image(20, 17, |x, y| 0.01 * x * x + 0.5 * y);
        for (seed, window_px) in [(0u64, 5u32), (1, 3), (2, 5), (3, 7), (4, 9)] {
            let holed = random_image(seed, 41, 33, 1.0, seed % 2 == 0);
            for img in [&clean, &holed] {
                let p = Params { window_px, deriv_window_px: window_px, k_std_window_px: 5 };
                let a = fit_planes(img, window_px);
                for path in [fit::Path::Fast, fit::Path::Unspecialised] {
                    let b = compute_with(img, &p, path, SurfaceFeatures::default()).plane;
                    assert_eq!(plane_bits(&a), plane_bits(&b), "seed {seed}, window {window_px}, {path:?}");
                }
            }
        }
    }

    #[test]
    fn derivatives_are_the_ones_behind_the_curvatures() {
        // K, H and curvedness of `compute` are those of `derivatives`, bit for bit, and `principal` from the
        // derivatives is consistent with them.
        for (seed, window_px) in [(5u64, 5u32), (6, 3), (7, 7), (8, 9)] {
            let img = random_image(seed, 37, 30, 1.0, seed % 2 == 1);
            let p = Params { window_px: 5, deriv_window_px: window_px, k_std_window_px: 3 };
            let (f, d) = (compute(&img, &p), derivatives(&img, &p));
            let n = img.len();
            let (mut k, mut h, mut c) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            let (g, s) = (d.gradient.as_slice(), d.hessian.as_slice());
            let deriv = [
                g.iter().map(|v| v[0]).collect(),
                g.iter().map(|v| v[1]).collect(),
                s.iter().map(|v| v[0]).collect(),
                s.iter().map(|v| v[1]).collect(),
                s.iter().map(|v| v[2]).collect(),
            ];
            curvature::curvature_row(&deriv, &mut k, &mut h, &mut c);
            let b = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(b(&k), b(f.k.as_slice()), "seed {seed}: K");
            assert_eq!(b(&h), b(f.h.as_slice()), "seed {seed}: H");
            assert_eq!(b(&c), b(f.curvedness.as_slice()), "seed {seed}: curvedness");
            for (i, pr) in d.principal().as_slice().iter().enumerate() {
                assert_eq!(pr[0].is_nan(), h[i].is_nan());
                if !h[i].is_nan() {
                    assert!(pr[0] >= pr[1], "seed {seed}: k1 < k2");
                    assert_relative_eq!(0.5 * (pr[0] + pr[1]), h[i], max_relative = 1e-6, epsilon = 1e-6);
                    let cv = (0.5 * (pr[0] * pr[0] + pr[1] * pr[1])).sqrt();
                    assert_relative_eq!(cv, c[i], max_relative = 1e-5, epsilon = 1e-6);
                }
            }
        }
    }

    /// Exact K and H of the graph z = f(x, y) from its analytic derivatives.
    fn kh(fx: f64, fy: f64, fxx: f64, fxy: f64, fyy: f64) -> (f64, f64) {
        let q = 1.0 + fx * fx + fy * fy;
        let k = (fxx * fyy - fxy * fxy) / (q * q);
        let h = ((1.0 + fy * fy) * fxx - 2.0 * fx * fy * fxy + (1.0 + fx * fx) * fyy) / (2.0 * q.powf(1.5));
        (k, h)
    }

    #[test]
    fn sphere_curvatures_match_formula() {
        // Lower hemisphere of radius 60 seen from above: z = z0 - sqrt(R² - ρ²), K = 1/R², |H| = 1/R.
        let (cx, cy, r, z0) = (32.0, 32.0, 60.0, 200.0);
        let img = image(64, 64, |x, y| z0 - (r * r - (x - cx).powi(2) - (y - cy).powi(2)).sqrt());
        let f = compute(&img, &Params::default());
        let (principal, exact) = (f.principal(), derivatives(&img, &Params::default()).principal());
        for y in 8..56u32 {
            for x in 8..56u32 {
                let k = f64::from(f.k[(x, y)]);
                let h = f64::from(f.h[(x, y)]);
                assert_relative_eq!(k, 1.0 / (r * r), max_relative = 0.05);
                assert_relative_eq!(h, 1.0 / r, max_relative = 0.05);
                // Both forms of the principal curvatures: from H and K, and from the derivatives.
                for [k1, k2] in [principal[(x, y)], exact[(x, y)]] {
                    assert_relative_eq!(f64::from(k1), 1.0 / r, max_relative = 0.05);
                    assert_relative_eq!(f64::from(k2), 1.0 / r, max_relative = 0.05);
                }
                assert_relative_eq!(f64::from(f.curvedness[(x, y)]), 1.0 / r, max_relative = 0.05);
            }
        }
    }

    #[test]
    fn paraboloid_curvatures_match_formula() {
        // z = 0.01 x'² − 0.005 y'² + 0.003 x'y' (a saddle, K < 0), x' and y' from (30, 25).
        let (p, q, s) = (0.01, -0.005, 0.003);
        let img = image(60, 50, |x, y| {
            50.0 + p * (x - 30.0).powi(2) + q * (y - 25.0).powi(2) + s * (x - 30.0) * (y - 25.0)
        });
        let f = compute(&img, &Params::default());
        for y in 5..45u32 {
            for x in 5..55u32 {
                let (u, v) = (f64::from(x) - 30.0, f64::from(y) - 25.0);
                let (k, h) = kh(2.0 * p * u + s * v, 2.0 * q * v + s * u, 2.0 * p, s, 2.0 * q);
                assert_relative_eq!(f64::from(f.k[(x, y)]), k, max_relative = 0.05);
                assert_relative_eq!(f64::from(f.h[(x, y)]), h, max_relative = 0.05, epsilon = 1e-7);
            }
        }
    }

    #[test]
    fn crease_has_large_h_and_zero_k() {
        // A roof: z = 100 + 0.5·|x − 20|, crease along x = 20.
        let img = image(41, 30, |x, _| 100.0 + 0.5 * (x - 20.0).abs());
        let f = compute(&img, &Params::default());
        for y in 3..27u32 {
            assert!(f.k[(20, y)].abs() < 1e-6, "K on crease = {}", f.k[(20, y)]);
            assert!(f.h[(20, y)].abs() > 0.05, "H on crease = {}", f.h[(20, y)]);
            assert!(f.curvedness[(20, y)] > 0.05);
            // Away from the crease the faces are flat.
            assert!(f.h[(10, y)].abs() < 1e-6 && f.h[(30, y)].abs() < 1e-6);
        }
        // The plane slope changes sign across the crease.
        assert!(f.plane[(15, 10)][0] < -0.49 && f.plane[(25, 10)][0] > 0.49);
    }

    #[test]
    fn no_data_never_leaks_into_fits() {
        let plane = |x: f64, y: f64| 0.7 * x - 0.4 * y + 30.0;
        let full = image(30, 30, plane);
        let mut holed = full.clone();
        // A block of no data with a wild value pattern around it would show up if it leaked.
        for y in 10..14 {
            for x in 12..20 {
                holed[(x, y)] = NAN;
            }
        }
        holed[(3, 25)] = NAN;
        let ff = compute(&full, &Params::default());
        let fh = compute(&holed, &Params::default());
        let (df, dh) = (derivatives(&full, &Params::default()), derivatives(&holed, &Params::default()));
        for (x, y, p) in fh.plane.enumerate() {
            if holed[(x, y)].is_nan() {
                assert!(p.iter().all(|v| v.is_nan()), "no-data pixel got a plane");
                assert!(fh.k[(x, y)].is_nan() && dh.gradient[(x, y)][0].is_nan());
                continue;
            }
            let q = ff.plane[(x, y)];
            for i in 0..3 {
                assert!((p[i] - q[i]).abs() < 1e-4, "plane at ({x}, {y}): {p:?} vs {q:?}");
            }
            let (g, gf) = (dh.gradient[(x, y)], df.gradient[(x, y)]);
            assert!((g[0] - gf[0]).abs() < 1e-4 && (g[1] - gf[1]).abs() < 1e-4, "gradient at ({x}, {y})");
            assert!(fh.k[(x, y)].abs() < 1e-8 && fh.h[(x, y)].abs() < 2e-5, "curvature at ({x}, {y})");
        }
        // Values inside the hole must not matter at all.
        let mut other = holed.clone();
        for y in 10..14 {
            for x in 12..20 {
                other[(x, y)] = f32::INFINITY;
            }
        }
        assert_eq!(bits(&compute(&other, &Params::default())), bits(&fh));
        assert_eq!(dbits(&derivatives(&other, &Params::default())), dbits(&dh));
    }

    /// Every float of the features as bits, so NaN compares equal to NaN.
    fn bits(f: &SurfaceFeatures) -> Vec<u32> {
        let mut v: Vec<u32> = f.plane.as_slice().iter().flatten().map(|x| x.to_bits()).collect();
        for g in [&f.k, &f.h, &f.curvedness, &f.k_std] {
            v.extend(g.as_slice().iter().map(|x| x.to_bits()));
        }
        v
    }

    /// Every float of the derivatives as bits.
    fn dbits(d: &Derivatives) -> Vec<u32> {
        let mut v: Vec<u32> = d.gradient.as_slice().iter().flatten().map(|x| x.to_bits()).collect();
        v.extend(d.hessian.as_slice().iter().flatten().map(|x| x.to_bits()));
        v
    }

    #[test]
    fn nan_only_window_gives_nan() {
        let mut img = Grid::new(11, 11, NAN);
        img[(5, 5)] = 10.0;
        img[(6, 5)] = 11.0;
        let f = compute(&img, &Params::default());
        assert!(f.plane[(5, 5)].iter().all(|v| v.is_nan()), "two points do not make a plane");
        assert!(f.k[(5, 5)].is_nan());
        // Collinear valid pixels: still no plane.
        let line = Grid::from_fn(11, 11, |x, y| if y == 5 { x as f32 } else { NAN });
        assert!(fit_planes(&line, 5).as_slice().iter().all(|p| p[0].is_nan()));
        let empty = Grid::new(7, 7, NAN);
        let f = compute(&empty, &Params::default());
        assert!(
            f.plane.as_slice().iter().all(|p| p[0].is_nan()) && f.k_std.as_slice().iter().all(|v| v.is_nan())
        );
    }

    #[test]
    fn partial_window_quadratic_is_exact_on_quadratics() {
        // Near NaN pixels and the border the quadratic is fitted from the valid pixels alone: still exact.
        let f_ = |x: f64, y: f64| 5.0 + 0.2 * x + 0.01 * x * x - 0.02 * x * y + 0.015 * y * y;
        let mut img = image(16, 16, f_);
        img[(7, 7)] = NAN;
        img[(8, 9)] = NAN;
        let f = derivatives(&img, &Params::default());
        for (x, y, g) in f.hessian.enumerate() {
            if img[(x, y)].is_nan() {
                continue;
            }
            assert!(
                (g[0] - 0.02).abs() < 1e-4 && (g[1] + 0.02).abs() < 1e-4 && (g[2] - 0.03).abs() < 1e-4,
                "{g:?}"
            );
            let d = f.gradient[(x, y)];
            let (xf, yf) = (f64::from(x), f64::from(y));
            assert!((f64::from(d[0]) - (0.2 + 0.02 * xf - 0.02 * yf)).abs() < 1e-4);
            assert!((f64::from(d[1]) - (-0.02 * xf + 0.03 * yf)).abs() < 1e-4);
        }
    }

    #[test]
    fn kernels_are_the_least_squares_pseudo_inverse() {
        // The 5×5 kernel of c1 is u / Σu² with Σu² = 50.
        for (i, p) in quadratic::SgKernels::new(5).pinv.iter().enumerate() {
            assert_relative_eq!(p[1], ((i % 5) as f64 - 2.0) / 50.0, epsilon = 1e-15);
        }
        for w in (3..=15u32).step_by(2) {
            let k = quadratic::SgKernels::new(w);
            let w = w as usize;
            let r = (w / 2) as f64;
            let at = |i: usize| quadratic::basis((i % w) as f64 - r, (i / w) as f64 - r);
            assert_eq!(k.pinv.len(), w * w);
            // A⁺A = I: a quadratic's coefficients come back exactly.
            for j in 0..6 {
                for m in 0..6 {
                    let got: f64 = k.pinv.iter().enumerate().map(|(i, p)| p[j] * at(i)[m]).sum();
                    let want = if j == m { 1.0 } else { 0.0 };
                    assert!((got - want).abs() < 1e-12, "w {w}: (A⁺A)[{j}][{m}] = {got}");
                }
            }
            // Least squares: the residual of any depth (here a fixed irregular one) is orthogonal to every column
            // of A, so no other left inverse passes.
            let z: Vec<f64> = (0..w * w).map(|i| ((i * 7919) % 101) as f64 * 0.37 - 11.0).collect();
            let c: Vec<f64> = (0..6).map(|j| k.pinv.iter().zip(&z).map(|(p, z)| p[j] * z).sum()).collect();
            for m in 0..6 {
                let dot: f64 = (0..w * w)
                    .map(|i| {
                        let b = at(i);
                        let fit: f64 = (0..6).map(|j| c[j] * b[j]).sum();
                        (z[i] - fit) * b[m]
                    })
                    .sum();
                assert!(dot.abs() < 1e-8, "w {w}: residual · column {m} = {dot}");
            }
        }
    }

    #[test]
    fn shade_is_black_on_no_data_and_lit_from_upper_left() {
        let mut img = image(20, 20, |x, y| 100.0 + 0.5 * (x - 10.0).abs() + 0.0 * y);
        img[(2, 2)] = NAN;
        let s = shade(&img);
        assert_eq!(s[(2, 2)], 0);
        assert!(s.as_slice().iter().enumerate().all(|(i, &v)| v > 0 || img.as_slice()[i].is_nan()));
        // Left half z decreases to the right: its normal turns toward the left, i.e. toward the light.
        assert!(s[(5, 10)] > s[(15, 10)], "{} vs {}", s[(5, 10)], s[(15, 10)]);
    }

    #[test]
    fn k_std_is_zero_inside_a_surface_and_positive_where_k_changes() {
        // Left half a paraboloid (K > 0 constant near the axis), right half a plane (K = 0), joined at x = 20.
        let img = image(41, 30, |x, y| {
            if x < 20.0 {
                100.0 + 0.02 * ((x - 20.0).powi(2) + (y - 15.0).powi(2))
            } else {
                100.0 + 0.02 * (y - 15.0).powi(2)
            }
        });
        let f = compute(&img, &Params::default());
        assert!(f.k_std[(35, 15)] < 1e-8, "plane: {}", f.k_std[(35, 15)]);
        assert!(f.k_std[(20, 15)] > 1e-5, "junction: {}", f.k_std[(20, 15)]);
        assert!(f.k_std.as_slice().iter().all(|v| v.is_finite() && *v >= 0.0));
    }

    /// A random piecewise-smooth range image with holes: quadratic patches, a jump and a crease, additive noise,
    /// optionally rounded to integers (8-bit like), scaled by `scale`, with random no-data blobs, single no-data
    /// pixels and a few ±∞ values.
    fn random_image(seed: u64, w: u32, h: u32, scale: f64, quantise: bool) -> RangeImage {
        use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let mut c = [0.0f64; 12];
        for v in &mut c {
            *v = rng.random_range(-1.0..1.0);
        }
        let (split, crease) =
            (rng.random_range(0.3..0.7) * f64::from(w), rng.random_range(0.2..0.8) * f64::from(h));
        let mut img = Grid::from_fn(w, h, |x, y| {
            let (x, y) = (f64::from(x), f64::from(y));
            let z = if x < split {
                120.0 + 0.8 * c[0] * x + 0.8 * c[1] * y + 0.01 * (c[2] * x * x + c[3] * x * y + c[4] * y * y)
            } else {
                150.0 + 0.5 * c[5] * x + 0.5 * c[6] * y + 0.8 * c[7] * (y - crease).abs()
            };
            z as f32
        });
        for v in img.as_mut_slice() {
            let z = f64::from(*v) + rng.random_range(-0.7..0.7);
            *v = ((if quantise { z.round() } else { z }) * scale) as f32;
        }
        if w == 0 || h == 0 {
            return img;
        }
        for _ in 0..4 {
            let (bx, by) = (rng.random_range(0..w), rng.random_range(0..h));
            let (bw, bh) = (rng.random_range(1..8), rng.random_range(1..8));
            for y in by..(by + bh).min(h) {
                for x in bx..(bx + bw).min(w) {
                    img[(x, y)] = NAN;
                }
            }
        }
        for i in 0..(w * h / 40) {
            let (x, y) = (rng.random_range(0..w), rng.random_range(0..h));
            img[(x, y)] = match i % 10 {
                0 => f32::INFINITY,
                1 => f32::NEG_INFINITY,
                _ => NAN,
            };
        }
        img
    }

    #[test]
    fn fast_paths_match_the_general_path_on_random_images() {
        let windows = [(5, 5, 5), (3, 3, 3), (7, 7, 5), (5, 3, 1), (9, 9, 3), (3, 5, 7)];
        for seed in 0..12u64 {
            let (w, h) = (20 + (seed as u32 * 7) % 45, 16 + (seed as u32 * 11) % 40);
            let (scale, quantise) = if seed % 3 == 2 { (0.013, false) } else { (1.0, seed % 3 == 0) };
            let img = random_image(seed, w, h, scale, quantise);
            let (window_px, deriv_window_px, k_std_window_px) = windows[seed as usize % windows.len()];
            let p = Params { window_px, deriv_window_px, k_std_window_px };
            let run = |path| {
                let f = compute_with(&img, &p, path, SurfaceFeatures::default());
                (f, derivatives_with(&img, p.deriv_window_px, path))
            };
            let (fast, unspec, general) =
                (run(fit::Path::Fast), run(fit::Path::Unspecialised), run(fit::Path::General));
            // The specialised loops do the same arithmetic in the same order as the multi-pass loops.
            assert_eq!(bits(&fast.0), bits(&unspec.0), "seed {seed}: specialised vs multi-pass");
            assert_eq!(
                dbits(&fast.1),
                dbits(&unspec.1),
                "seed {seed}: specialised vs multi-pass derivatives"
            );
            compare(&img, &fast, &general, seed);
        }
    }

    #[test]
    fn every_instruction_set_gives_the_same_bits() {
        // The row loops run compiled for each instruction set of this CPU (isa::dispatch): the same bits on each.
        let windows = [(5, 5, 5), (3, 3, 3), (7, 7, 5), (5, 3, 9)];
        for seed in 0..8u64 {
            let (w, h) = (40 + (seed as u32 * 13) % 50, 30 + (seed as u32 * 7) % 40);
            let (scale, quantise) = if seed % 3 == 2 { (0.013, false) } else { (1.0, seed % 3 == 0) };
            let img = random_image(100 + seed, w, h, scale, quantise);
            let (window_px, deriv_window_px, k_std_window_px) = windows[seed as usize % windows.len()];
            let p = Params { window_px, deriv_window_px, k_std_window_px };
            let run =
                || (bits(&compute(&img, &p)), dbits(&derivatives(&img, &p)), fit_planes(&img, window_px));
            let paths: Vec<_> = isa::Isa::available()
                .into_iter()
                .map(|i| (i, isa::with_isa(i, run).expect("available")))
                .collect();
            for (i, out) in &paths[1..] {
                let (base, b) = &paths[0];
                assert!(out.0 == b.0 && out.1 == b.1, "seed {seed}: {i:?} differs from {base:?}");
                let pb =
                    |m: &PlaneMap| m.as_slice().iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(pb(&out.2), pb(&b.2), "seed {seed}: fit_planes, {i:?} vs {base:?}");
            }
        }
    }

    #[test]
    fn exact_fits_equal_the_general_path_bit_for_bit() {
        // The fast path fits the top and bottom border rows a whole row at a time (and the side columns pixel by
        // pixel), and the full windows holding no-data four at a time (their solves side by side): the same
        // arithmetic as the general path's per-pixel fits, so the same bits.
        for (seed, window_px) in [(20u64, 3u32), (21, 5), (22, 7), (23, 5), (24, 9)] {
            let img = random_image(seed, 30 + seed as u32, 19, 1.0, seed % 2 == 0);
            let (w, h) = img.dimensions();
            let p = Params { window_px, deriv_window_px: window_px, k_std_window_px: 3 };
            let r = window_px / 2;
            let [fast, general] = [fit::Path::Fast, fit::Path::General].map(|path| {
                (
                    compute_with(&img, &p, path, SurfaceFeatures::default()),
                    derivatives_with(&img, window_px, path),
                )
            });
            let plane_mode = [
                fit_planes(&img, window_px),
                compute_with(&img, &p, fit::Path::General, SurfaceFeatures::default()).plane,
            ];
            let mut holed = 0;
            for (x, y, q) in general.0.plane.enumerate() {
                if y >= r && y + r < h && x >= r && x + r < w {
                    let window = (y - r..=y + r).flat_map(|v| (x - r..=x + r).map(move |u| (u, v)));
                    if window.clone().all(|(u, v)| img[(u, v)].is_finite()) {
                        continue;
                    }
                    holed += usize::from(img[(x, y)].is_finite());
                }
                let at = format!("seed {seed}, window {window_px}, ({x}, {y})");
                let b = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(b(&fast.0.plane[(x, y)]), b(q), "plane at {at}");
                assert_eq!(b(&plane_mode[0][(x, y)]), b(&plane_mode[1][(x, y)]), "fit_planes at {at}");
                assert_eq!(b(&fast.1.gradient[(x, y)]), b(&general.1.gradient[(x, y)]), "gradient at {at}");
                assert_eq!(b(&fast.1.hessian[(x, y)]), b(&general.1.hessian[(x, y)]), "hessian at {at}");
            }
            assert!(holed >= 8, "seed {seed}: only {holed} full windows with no-data");
        }
    }

    #[test]
    fn side_by_side_solves_equal_single_solves_bit_for_bit() {
        use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        for trial in 0..50 {
            // Normal matrices of random point sets (lane 2 of every other trial singular: 5 points), random sides.
            let singular = |lane: usize| lane == 2 && trial % 2 == 0;
            let systems: Vec<([[f64; 6]; 6], [f64; 6])> = (0..4)
                .map(|lane| {
                    let points = if singular(lane) { 5 } else { 6 + trial % 20 };
                    let mut n = [[0.0; 6]; 6];
                    for _ in 0..points {
                        let b = quadratic::basis(rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0));
                        for i in 0..6 {
                            for j in 0..=i {
                                n[i][j] += b[i] * b[j];
                            }
                        }
                    }
                    (n, std::array::from_fn(|_| rng.random_range(-10.0..10.0)))
                })
                .collect();
            let mut nl = [[[0.0; 4]; 6]; 6];
            let mut rl = [[0.0; 4]; 6];
            for (l, (n, rhs)) in systems.iter().enumerate() {
                for i in 0..6 {
                    for j in 0..6 {
                        nl[i][j][l] = n[i][j];
                    }
                    rl[i][l] = rhs[i];
                }
            }
            let ok = quadratic::cholesky_solve_lanes(&mut nl, &mut rl);
            for (l, (n, rhs)) in systems.into_iter().enumerate() {
                let (mut n, mut rhs) = (n, rhs);
                let single = quadratic::cholesky_solve(&mut n, &mut rhs);
                assert_eq!(ok[l], single, "trial {trial}, lane {l}: singular?");
                assert_eq!(single, !singular(l), "trial {trial}, lane {l}");
                if single {
                    let lane: [f64; 6] = std::array::from_fn(|i| rl[i][l]);
                    assert_eq!(lane.map(f64::to_bits), rhs.map(f64::to_bits), "trial {trial}, lane {l}");
                }
            }
        }
    }

    #[test]
    fn tiny_and_empty_images_match_the_general_path() {
        // Images narrower or lower than the windows (no fast pixel at all, or a single fast row/column).
        for (w, h) in [(0, 0), (0, 3), (1, 1), (2, 7), (7, 2), (5, 5), (6, 9), (9, 5)] {
            let img = random_image(u64::from(w * 31 + h), w, h, 1.0, true);
            for p in [Params::default(), Params { window_px: 3, deriv_window_px: 7, k_std_window_px: 9 }] {
                let fast = (compute(&img, &p), derivatives(&img, &p));
                assert_eq!(fast.0.k.dimensions(), (w, h));
                assert_eq!(fast.1.hessian.dimensions(), (w, h));
                let general = (
                    compute_with(&img, &p, fit::Path::General, SurfaceFeatures::default()),
                    derivatives_with(&img, p.deriv_window_px, fit::Path::General),
                );
                compare(&img, &fast, &general, u64::from(w * 100 + h));
            }
        }
    }

    /// Checks the fast-path features `f` against the general-path features `g`: same no-data pattern everywhere,
    /// and values within the f32 rounding bound of the fast path (see the comments).
    fn compare(
        img: &RangeImage,
        (f, fdv): &(SurfaceFeatures, Derivatives),
        (g, gdv): &(SurfaceFeatures, Derivatives),
        seed: u64,
    ) {
        let finite: Vec<f64> =
            img.as_slice().iter().filter(|v| v.is_finite()).map(|&v| f64::from(v)).collect();
        let range =
            finite.iter().fold(f64::MIN, |a, &b| a.max(b)) - finite.iter().fold(f64::MAX, |a, &b| a.min(b));
        // The fast path sums, in f32, differences of depths of one window (each ≤ `range`, so each rounding error
        // ≤ ε32·range/2), a few dozen terms per moment, then scales by the kernel gain (≤ 1/Σu² etc., small): the
        // error of a derivative is about one rounding of a depth difference, ≤ ε32·range. Observed: ≤ 0.9·ε32·range
        // over these images; the tolerance leaves a factor 4.
        let tol_d = 4.0 * f64::from(f32::EPSILON) * range;
        let (cx, cy) = ((f64::from(img.width()) - 1.0) / 2.0, (f64::from(img.height()) - 1.0) / 2.0);
        let mut hmax = 0.0f64;
        for (x, y, p) in g.plane.enumerate() {
            let q = f.plane[(x, y)];
            assert_eq!(
                p.map(f32::is_nan),
                q.map(f32::is_nan),
                "seed {seed}: plane NaN pattern at ({x}, {y})"
            );
            let (gd, fd) = (gdv.gradient[(x, y)], fdv.gradient[(x, y)]);
            let (gh, fh) = (gdv.hessian[(x, y)], fdv.hessian[(x, y)]);
            assert_eq!(gd.map(f32::is_nan), fd.map(f32::is_nan), "seed {seed}: gradient NaN pattern");
            assert_eq!(gh.map(f32::is_nan), fh.map(f32::is_nan), "seed {seed}: hessian NaN pattern");
            if p[0].is_nan() {
                continue;
            }
            // c = mean − a·x₀ − b·y₀: the slope errors are multiplied by the offset from the image centre, plus
            // the final f32 rounding of c (both paths round once).
            let (x0, y0) = (f64::from(x) - cx, f64::from(y) - cy);
            let tol_c =
                tol_d * (1.0 + x0.abs() + y0.abs()) + 2.0 * f64::from(p[2].abs()) * f64::from(f32::EPSILON);
            for i in 0..2 {
                let e = f64::from((p[i] - q[i]).abs());
                assert!(e <= tol_d, "seed {seed}: plane[{i}] at ({x}, {y}): {p:?} vs {q:?}");
            }
            let e = f64::from((p[2] - q[2]).abs());
            assert!(e <= tol_c, "seed {seed}: plane c at ({x}, {y}): {p:?} vs {q:?}");
            if gd[0].is_nan() {
                continue;
            }
            for i in 0..2 {
                let e = f64::from((gd[i] - fd[i]).abs());
                assert!(e <= tol_d, "seed {seed}: gradient at ({x}, {y}): {gd:?} vs {fd:?}");
            }
            for i in 0..3 {
                let e = f64::from((gh[i] - fh[i]).abs());
                assert!(e <= tol_d, "seed {seed}: hessian at ({x}, {y}): {gh:?} vs {fh:?}");
                hmax = hmax.max(f64::from(gh[i].abs()));
            }
        }
        // The curvatures are smooth functions of the derivatives with slopes ≤ a few times (1 + |hessian|)
        // (K is a product of second derivatives; H, k1,2 and curvedness are Lipschitz in them); the std of K is
        // 1-Lipschitz in the K values; plus f32 rounding of the values themselves.
        let tol_curv = 8.0 * tol_d * (1.0 + hmax);
        let pairs: [(&Grid<f32>, &Grid<f32>); 4] =
            [(&g.k, &f.k), (&g.h, &f.h), (&g.curvedness, &f.curvedness), (&g.k_std, &f.k_std)];
        for (a, b) in pairs {
            for (i, (&u, &v)) in a.as_slice().iter().zip(b.as_slice()).enumerate() {
                assert_eq!(u.is_nan(), v.is_nan(), "seed {seed}: curvature NaN pattern at {i}");
                if !u.is_nan() {
                    let e = f64::from((u - v).abs());
                    let tol = tol_curv + 4.0 * f64::from(u.abs()) * f64::from(f32::EPSILON);
                    assert!(e <= tol, "seed {seed}: curvature {u} vs {v} at {i}");
                }
            }
        }
        for (a, b) in gdv.principal().as_slice().iter().zip(fdv.principal().as_slice()) {
            for i in 0..2 {
                assert_eq!(a[i].is_nan(), b[i].is_nan());
                if !a[i].is_nan() {
                    let e = f64::from((a[i] - b[i]).abs());
                    assert!(
                        e <= tol_curv + 4.0 * f64::from(a[i].abs()) * f64::from(f32::EPSILON),
                        "seed {seed}: principal"
                    );
                }
            }
        }
    }

    #[test]
    fn validate_rejects_even_windows() {
        assert!(Params::default().validate().is_ok());
        assert!(
            Params { window_px: 4, ..Params::default() }.validate().unwrap_err().field
                == "features.window_px"
        );
        assert!(Params { deriv_window_px: 1, ..Params::default() }.validate().is_err());
    }
}
