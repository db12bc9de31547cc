//! Running moments of 3D points and the least-squares plane they define.

use nalgebra::{Matrix3, SymmetricEigen};

/// First and second moments of a set of 3D points, relative to a fixed origin, in `f64`.
///
/// Moments of disjoint sets add, so merged regions combine their moments in O(1).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Moments {
    /// Number of points.
    pub(crate) n: f64,
    /// Σx, Σy, Σz.
    pub(crate) s: [f64; 3],
    /// Σxx, Σxy, Σxz, Σyy, Σyz, Σzz.
    pub(crate) ss: [f64; 6],
}

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

impl Moments {
    /// Adds one point.
    #[inline]
    pub(crate) fn add(&mut self, p: [f64; 3]) {
        let [x, y, z] = p;
        self.n += 1.0;
        self.s[0] += x;
        self.s[1] += y;
        self.s[2] += z;
        self.ss[0] += x * x;
        self.ss[1] += x * y;
        self.ss[2] += x * z;
        self.ss[3] += y * y;
        self.ss[4] += y * z;
        self.ss[5] += z * z;
    }

    /// The moments of the union of two disjoint sets (`self` first, so the sum order is fixed).
    pub(crate) fn combined(&self, o: &Moments) -> Moments {
        let mut r = *self;
        r.n += o.n;
        for i in 0..3 {
            r.s[i] += o.s[i];
        }
        for i in 0..6 {
            r.ss[i] += o.ss[i];
        }
        r
    }

    /// Centroid; `[0; 3]` for an empty set.
    pub(crate) fn centroid(&self) -> [f64; 3] {
        if self.n <= 0.0 {
            return [0.0; 3];
        }
        [self.s[0] / self.n, self.s[1] / self.n, self.s[2] / self.n]
    }

    /// Least-squares plane (smallest eigenvector of the covariance), normal oriented so that
    /// `dot(normal, toward) ≥ 0`. `None` for fewer than 3 points or (nearly) collinear points.
    pub(crate) fn fit(&self, toward: impl Fn([f64; 3]) -> [f64; 3]) -> Option<Plane> {
        if self.n < 3.0 {
            return None;
        }
        let c = self.centroid();
        let n = self.n;
        let cov = |i: usize, a: usize, b: usize| self.ss[i] / n - c[a] * c[b];
        let m = Matrix3::new(
            cov(0, 0, 0),
            cov(1, 0, 1),
            cov(2, 0, 2),
            cov(1, 0, 1),
            cov(3, 1, 1),
            cov(4, 1, 2),
            cov(2, 0, 2),
            cov(4, 1, 2),
            cov(5, 2, 2),
        );
        let eig = SymmetricEigen::new(m);
        let ev = eig.eigenvalues;
        // Sort eigenvalue indices ascending; ties keep index order, so the result is deterministic.
        let mut idx = [0usize, 1, 2];
        idx.sort_by(|&i, &j| ev[i].total_cmp(&ev[j]));
        let (l0, l1) = (ev[idx[0]].max(0.0), ev[idx[1]].max(0.0));
        // Collinear points: the two smallest spreads both vanish relative to the largest.
        let l2 = ev[idx[2]].max(0.0);
        if l1.is_nan() || l1 <= 1e-9 * l2.max(1e-300) {
            return None;
        }
        let v = eig.eigenvectors.column(idx[0]);
        let mut normal = [v[0], v[1], v[2]];
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
}

/// Dot product.
#[inline]
pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
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
        let p = m.fit(|_| [0.0, 0.0, 1.0]).unwrap();
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
        assert!(m.fit(|_| [0.0, 0.0, 1.0]).is_none());
        let mut two = Moments::default();
        two.add([0.0; 3]);
        two.add([1.0; 3]);
        assert!(two.fit(|_| [0.0, 0.0, 1.0]).is_none());
        assert_eq!(two.combined(&m).n, 7.0);
    }
}
