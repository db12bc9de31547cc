//! The least-squares plane of a region's 3D points (moments from `planefit`), and plane tests.

pub(crate) use planefit::{Moments, dot};

/// A plane `normal · p + offset = 0` (p relative to the moments' origin) with its fit quality.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Plane {
    /// Unit normal, oriented toward the sensor.
    pub(crate) normal: [f64; 3],
    /// Offset `d` with `normal · p + d = 0`.
    pub(crate) offset: f64,
    /// Centroid of the points.
    pub(crate) centroid: [f64; 3],
    /// Mean squared point-to-plane distance (smallest eigenvalue of the covariance).
    pub(crate) mean_sq: f64,
}

impl Plane {
    /// Plane through `p` with unit normal `n`.
    pub(crate) fn through(p: [f64; 3], n: [f64; 3]) -> Self {
        Self { normal: n, offset: -dot(n, p), centroid: p, mean_sq: 0.0 }
    }

    /// Signed distance of `p` to the plane.
    #[inline]
    pub(crate) fn distance(&self, p: [f64; 3]) -> f64 {
        dot(self.normal, p) + self.offset
    }

    /// Least-squares plane of the points summarised by `m` (smallest eigenvector of the
    /// covariance), normal oriented so that `dot(normal, toward) ≥ 0`. `None` for fewer than 3
    /// points or (nearly) collinear points.
    pub(crate) fn fit(m: &Moments, toward: impl Fn([f64; 3]) -> [f64; 3]) -> Option<Plane> {
        if m.n < 3.0 {
            return None;
        }
        let c = m.centroid();
        let axes = m.axes();
        let ev = axes.values;
        // Sort eigenvalue indices ascending; ties keep index order, so the result is deterministic.
        let mut idx = [0usize, 1, 2];
        idx.sort_by(|&i, &j| ev[i].total_cmp(&ev[j]));
        let (l0, l1) = (ev[idx[0]].max(0.0), ev[idx[1]].max(0.0));
        // Collinear points: the two smallest spreads both vanish relative to the largest.
        let l2 = ev[idx[2]].max(0.0);
        if l1.is_nan() || l1 <= 1e-9 * l2.max(1e-300) {
            return None;
        }
        let mut normal = axes.vectors[idx[0]];
        let len = dot(normal, normal).sqrt();
        if len.is_nan() || len <= 0.0 || !len.is_finite() {
            return None;
        }
        normal = [normal[0] / len, normal[1] / len, normal[2] / len];
        if dot(normal, toward(c)) < 0.0 {
            normal = [-normal[0], -normal[1], -normal[2]];
        }
        Some(Plane { normal, offset: -dot(normal, c), centroid: c, mean_sq: l0 })
    }

    /// `Plane::fit(m, ..).map(|p| p.mean_sq)` (the same bits; the orientation does not change it) from the
    /// eigenvalues alone: the solver (nalgebra's, as copied in `planefit::eigen3`) computes them by the same
    /// operations with or without the eigenvectors, and a finite covariance has finite unit eigenvectors, so only
    /// the eigenvalue tests of [`Plane::fit`] can fail. A covariance with a non-finite entry goes through
    /// [`Plane::fit`].
    pub(crate) fn fit_mean_sq(m: &Moments) -> Option<f64> {
        if m.n < 3.0 {
            return None;
        }
        let cov = m.covariance_rows();
        if !cov.iter().flatten().all(|v| v.is_finite()) {
            return Plane::fit(m, |_| [0.0, 0.0, 1.0]).map(|p| p.mean_sq);
        }
        let (ev, _) = planefit::eigen3::symmetric_eigen3(cov, false);
        // As in `fit`: ascending, ties in index order.
        let mut idx = [0usize, 1, 2];
        idx.sort_by(|&i, &j| ev[i].total_cmp(&ev[j]));
        let (l0, l1, l2) = (ev[idx[0]].max(0.0), ev[idx[1]].max(0.0), ev[idx[2]].max(0.0));
        if l1.is_nan() || l1 <= 1e-9 * l2.max(1e-300) {
            return None;
        }
        Some(l0)
    }

    /// Mean squared distance of the points summarised by `m` to this plane.
    pub(crate) fn mean_sq_distance(&self, m: &Moments) -> f64 {
        if m.n <= 0.0 {
            return 0.0;
        }
        let [a, b, c] = self.normal;
        let d = self.offset;
        let [sx, sy, sz] = m.s;
        let [sxx, sxy, sxz, syy, syz, szz] = m.ss;
        // Σ (a x + b y + c z + d)², expanded.
        let q = a * a * sxx + b * b * syy + c * c * szz + 2.0 * (a * b * sxy + a * c * sxz + b * c * syz);
        let l = 2.0 * d * (a * sx + b * sy + c * sz);
        ((q + l) / m.n + d * d).max(0.0)
    }
}

/// Whether the smallest eigenvalue [`Moments::axes`] gives for `m`'s covariance is certainly above `t` (`false`
/// when unsure): a cheap test that skips eigen-decompositions whose result could not pass a threshold.
///
/// With `C` the covariance as computed and `M` its largest entry (in magnitude), `λ₀ ≥ det C / E₂` where `E₂` is
/// the sum of `C`'s principal 2×2 minors (`λ₁λ₂ ≤ E₂` when every eigenvalue is positive, which `tr, E₂, det > 0`
/// ensure). The rounding of `det C` and `E₂` here is counted as `10⁻¹² M³` and `10⁻¹² M²` (thousands of times
/// the worst case of a few dozen ulps), the eigen-solver's error as `10⁻¹² M` (it is backward stable: every
/// computed eigenvalue lies within a small multiple of `ε‖C‖ ≤ 3εM` of a true one), and `t` gets a relative margin
/// of `10⁻⁹` for the square root a caller may take.
pub(crate) fn smallest_axis_exceeds(m: &Moments, t: f64) -> bool {
    const TOL: f64 = 1e-12;
    let c = m.covariance();
    let (a, b, e, d, f, g) = (c[(0, 0)], c[(0, 1)], c[(0, 2)], c[(1, 1)], c[(1, 2)], c[(2, 2)]);
    let entries = [a, b, e, d, f, g];
    if !entries.iter().all(|v| v.is_finite()) {
        return false;
    }
    let big = entries.iter().fold(0.0f64, |x, v| x.max(v.abs()));
    let (m2, m3) = (big * big, big * big * big);
    let (dg, eg, df) = (d * g - f * f, b * g - f * e, b * f - d * e);
    let det = a * dg - b * eg + e * df;
    let e2 = (a * d - b * b) + (a * g - e * e) + dg;
    let tr = a + d + g;
    let (det_lo, e2_lo, e2_hi) = (det - TOL * m3, e2 - TOL * m2, e2 + TOL * m2);
    if !(tr > 3.0 * TOL * big && e2_lo > 0.0 && det_lo > 0.0) {
        return false;
    }
    let bound = det_lo / e2_hi * (1.0 - TOL) - TOL * big;
    bound > t * (1.0 + 1e-9)
}

/// Cross product.
#[inline]
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn fit_recovers_tilted_plane() {
        // z = 0.5 x − 0.25 y + 3.
        let mut m = Moments::default();
        for y in 0..10 {
            for x in 0..10 {
                let (x, y) = (f64::from(x), f64::from(y));
                m.add([x, y, 0.5 * x - 0.25 * y + 3.0]);
            }
        }
        let p = Plane::fit(&m, |_| [0.0, 0.0, 1.0]).unwrap();
        let k = (0.25f64 + 0.0625 + 1.0).sqrt();
        assert_relative_eq!(p.normal[0], -0.5 / k, epsilon = 1e-9);
        assert_relative_eq!(p.normal[1], 0.25 / k, epsilon = 1e-9);
        assert_relative_eq!(p.normal[2], 1.0 / k, epsilon = 1e-9);
        assert_relative_eq!(p.distance([2.0, 2.0, 1.0 - 0.5 + 3.0]), 0.0, epsilon = 1e-9);
        assert!(p.mean_sq < 1e-9);
        assert_relative_eq!(p.mean_sq_distance(&m), 0.0, epsilon = 1e-9);
    }

    #[test]
    fn mean_sq_distance_matches_direct_sum() {
        let pts = [[0.0, 0.0, 1.0], [1.0, 0.0, 2.0], [0.0, 3.0, -1.0], [2.0, 2.0, 0.5]];
        let mut m = Moments::default();
        pts.iter().for_each(|&p| m.add(p));
        let plane = Plane::through([0.0, 0.0, 0.5], [0.0, 0.6, 0.8]);
        let direct: f64 = pts.iter().map(|&p| plane.distance(p).powi(2)).sum::<f64>() / 4.0;
        assert_relative_eq!(plane.mean_sq_distance(&m), direct, epsilon = 1e-12);
    }

    #[test]
    fn collinear_points_have_no_plane() {
        let mut m = Moments::default();
        for i in 0..5 {
            m.add([f64::from(i), 2.0 * f64::from(i), 1.0]);
        }
        assert!(Plane::fit(&m, |_| [0.0, 0.0, 1.0]).is_none());
        let mut two = Moments::default();
        two.add([0.0; 3]);
        two.add([1.0; 3]);
        assert!(Plane::fit(&two, |_| [0.0, 0.0, 1.0]).is_none());
        assert_eq!(two.combined(&m).n, 7.0);
    }
    /// `fit_mean_sq` gives the bits of `Plane::fit(..).mean_sq` (or `None` with it) on random point sets: near
    /// planes, near lines, repeated points, at several scales and offsets.
    #[test]
    fn fit_mean_sq_is_the_fit_s_mean_sq() {
        use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(23);
        let mut nones = 0;
        for k in 0..20000 {
            let scale = 10f64.powi(rng.random_range(-3..4));
            let off =
                [0, 1, 2].map(|_| rng.random_range(-1.0..1.0) * scale * 10f64.powi(rng.random_range(0..4)));
            let noise = [0.0, 1e-9, 1e-4, 1e-2, 0.3, 1.0][k % 6];
            let line = k % 7 == 0;
            let n = rng.random_range(1..40);
            let mut m = Moments::default();
            for i in 0..n {
                let same = k % 11 == 0 && i > 0;
                let (u, v) = if same {
                    (0.5, 0.5)
                } else {
                    (rng.random_range(-1.0..1.0), if line { 0.0 } else { rng.random_range(-1.0..1.0) })
                };
                let w = noise * rng.random_range(-1.0..1.0);
                // f32 coordinates, as the growth stage stores them.
                let p = [
                    off[0] + scale * (u + 0.3 * v),
                    off[1] + scale * (v - 0.2 * w),
                    off[2] + scale * (w + 0.5 * u),
                ];
                m.add(p.map(|c| f64::from(c as f32)));
            }
            let want = Plane::fit(&m, |_| [0.3, -0.2, 1.0]).map(|p| p.mean_sq.to_bits());
            nones += usize::from(want.is_none());
            assert_eq!(Plane::fit_mean_sq(&m).map(f64::to_bits), want, "case {k}");
        }
        assert!(nones > 1000 && nones < 15000, "{nones} sets without a plane");
    }

    #[test]
    fn smallest_axis_bound_never_exceeds_the_solver() {
        use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(11);
        let (mut tight, mut cases) = (0, 0);
        for k in 0..4000 {
            // Points near a random plane (noise from 0 to isotropic), some near a line, at several scales
            // and offsets from the origin.
            let scale = 10f64.powi(rng.random_range(-3..4));
            let off =
                [0, 1, 2].map(|_| rng.random_range(-1.0..1.0) * scale * 10f64.powi(rng.random_range(0..4)));
            let noise = [0.0, 1e-9, 1e-4, 1e-2, 0.3, 1.0][k % 6];
            let line = k % 7 == 0;
            let n = rng.random_range(3..60);
            let mut m = Moments::default();
            for _ in 0..n {
                let (u, v) =
                    (rng.random_range(-1.0..1.0), if line { 0.0 } else { rng.random_range(-1.0..1.0) });
                let w = noise * rng.random_range(-1.0..1.0);
                m.add([
                    off[0] + scale * (u + 0.3 * v),
                    off[1] + scale * (v - 0.2 * w),
                    off[2] + scale * (w + 0.5 * u),
                ]);
            }
            let ev = m.axes().values;
            let l0 = ev[0].min(ev[1]).min(ev[2]);
            cases += 1;
            // Never claims more than the solver's own smallest eigenvalue.
            assert!(!smallest_axis_exceeds(&m, l0), "case {k}: bound above the solver's {l0}");
            assert!(!smallest_axis_exceeds(&m, l0.max(0.0)), "case {k}");
            if l0 > 0.0 && smallest_axis_exceeds(&m, 0.25 * l0) {
                tight += 1;
            }
            // The skip it allows: a plane test at threshold t fails whenever the bound exceeds t.
            let t = l0 * [0.5, 0.9, 0.999_999, 1.0, 2.0][k % 5];
            if smallest_axis_exceeds(&m, t) {
                assert!(Plane::fit(&m, |_| [0.0, 0.0, 1.0]).is_none_or(|p| p.mean_sq > t), "case {k}");
            }
        }
        // Useful as well as safe: on most non-degenerate sets it is within a factor 4.
        assert!(tight * 3 > cases, "bound tight on only {tight} of {cases} sets");
    }
}
