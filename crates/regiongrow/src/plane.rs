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
}
