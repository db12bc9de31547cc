//! Region plane fits, shared by the stages: the first and second moments of a 3D point set
//! ([`Moments`], summed in `f64` in the order the points are added, so moments of disjoint sets
//! combine in O(1)) and the eigen-decomposition of their covariance ([`Moments::axes`]).
//!
//! The callers keep their own rules on top (docs/method.md §3.2 and §3.4): region growing picks the
//! smallest eigenvalue in a total order and gives no plane for fewer than three or collinear
//! points; the final segmentation picks the first smallest and always gives a plane. Both use the
//! same sums, covariance and eigen solver from here, so their planes are what they were when each
//! had its own copy, bit for bit.
//!
//! [`noise`] measures an image's own depth noise and quantisation step from local plane fits.

pub mod eigen3;
pub mod noise;

use nalgebra::Matrix3;

/// First and second moments of a set of 3D points, in `f64`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Moments {
    /// Number of points.
    pub n: f64,
    /// Σx, Σy, Σz.
    pub s: [f64; 3],
    /// Σxx, Σxy, Σxz, Σyy, Σyz, Σzz.
    pub ss: [f64; 6],
}

/// The eigen-decomposition of a covariance matrix, in the solver's order (not sorted).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axes {
    /// Eigenvalues.
    pub values: [f64; 3],
    /// `vectors[k]`: the eigenvector of `values[k]` (unit length up to rounding).
    pub vectors: [[f64; 3]; 3],
}

impl Moments {
    /// Adds one point.
    #[inline]
    pub fn add(&mut self, p: [f64; 3]) {
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

    /// Removes one point that was added (the sums less its terms; not the bits a sum without it would give).
    #[inline]
    pub fn remove(&mut self, p: [f64; 3]) {
        let [x, y, z] = p;
        self.n -= 1.0;
        self.s[0] -= x;
        self.s[1] -= y;
        self.s[2] -= z;
        self.ss[0] -= x * x;
        self.ss[1] -= x * y;
        self.ss[2] -= x * z;
        self.ss[3] -= y * y;
        self.ss[4] -= y * z;
        self.ss[5] -= z * z;
    }

    /// Adds the moments of a disjoint set (`self` first, so the sum order is fixed).
    pub fn merge(&mut self, o: &Moments) {
        self.n += o.n;
        for i in 0..3 {
            self.s[i] += o.s[i];
        }
        for i in 0..6 {
            self.ss[i] += o.ss[i];
        }
    }

    /// The moments of the union of two disjoint sets (`self` first).
    #[must_use]
    pub fn combined(&self, o: &Moments) -> Moments {
        let mut r = *self;
        r.merge(o);
        r
    }

    /// Centroid; `[0; 3]` for an empty set.
    #[must_use]
    pub fn centroid(&self) -> [f64; 3] {
        let n = self.n.max(1.0);
        self.s.map(|v| v / n)
    }

    /// Covariance matrix (divided by n; the zero matrix for an empty set).
    #[must_use]
    pub fn covariance(&self) -> Matrix3<f64> {
        let c = self.covariance_rows();
        Matrix3::from_fn(|r, k| c[r][k])
    }

    /// [`covariance`](Self::covariance) as rows.
    #[must_use]
    pub fn covariance_rows(&self) -> [[f64; 3]; 3] {
        let n = self.n.max(1.0);
        let c = self.centroid();
        let e = |k: usize, a: usize, b: usize| self.ss[k] / n - c[a] * c[b];
        let (xx, xy, xz, yy, yz, zz) =
            (e(0, 0, 0), e(1, 0, 1), e(2, 0, 2), e(3, 1, 1), e(4, 1, 2), e(5, 2, 2));
        [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]
    }

    /// The eigen-decomposition of [`covariance`](Self::covariance) (nalgebra's symmetric solver, bit for bit:
    /// [`eigen3::symmetric_eigen3`]).
    #[must_use]
    pub fn axes(&self) -> Axes {
        let (values, q) = eigen3::symmetric_eigen3(self.covariance_rows(), true);
        let v = |k: usize| [q[0][k], q[1][k], q[2][k]];
        Axes { values, vectors: [v(0), v(1), v(2)] }
    }
}

/// Dot product.
#[inline]
#[must_use]
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn removing_points_gives_the_moments_of_the_rest() {
        let pts: Vec<[f64; 3]> = (0..50).map(f64::from).map(|t| [t, 0.5 * t * t, 3.0 - t]).collect();
        let (mut all, mut rest) = (Moments::default(), Moments::default());
        pts.iter().for_each(|&p| all.add(p));
        pts[10..].iter().for_each(|&p| rest.add(p));
        pts[..10].iter().for_each(|&p| all.remove(p));
        assert_eq!(all.n, rest.n);
        for (a, b) in all.s.iter().chain(&all.ss).zip(rest.s.iter().chain(&rest.ss)) {
            assert_relative_eq!(a, b, max_relative = 1e-12);
        }
    }

    #[test]
    fn axes_of_a_tilted_plane() {
        // z = 0.5 x − 0.25 y + 3 on a 10×10 grid: the smallest axis is the plane normal, eigenvalue 0.
        let z = |x: f64, y: f64| 0.5 * x - 0.25 * y + 3.0;
        let mut m = Moments::default();
        (0..100).map(|i| (f64::from(i % 10), f64::from(i / 10))).for_each(|(x, y)| m.add([x, y, z(x, y)]));
        assert_eq!(m.n, 100.0);
        assert_relative_eq!(m.centroid()[2], z(4.5, 4.5), epsilon = 1e-12);
        let axes = m.axes();
        let k = (0..3).min_by(|&i, &j| axes.values[i].total_cmp(&axes.values[j])).unwrap();
        assert!(axes.values[k].abs() < 1e-9, "{axes:?}");
        let v = axes.vectors[k];
        let len = (0.25f64 + 0.0625 + 1.0).sqrt();
        let s = v[2].signum() / dot(v, v).sqrt();
        for (got, want) in v.iter().zip([-0.5 / len, 0.25 / len, 1.0 / len]) {
            assert_relative_eq!(got * s, want, epsilon = 1e-9);
        }
    }

    #[test]
    fn combined_moments_equal_the_moments_of_the_union() {
        let pts = [[0.0, 0.0, 1.0], [1.0, 0.0, 2.0], [0.0, 3.0, -1.0], [2.0, 2.0, 0.5]];
        let (mut a, mut b, mut all) = (Moments::default(), Moments::default(), Moments::default());
        pts[..2].iter().for_each(|&p| a.add(p));
        pts[2..].iter().for_each(|&p| b.add(p));
        pts.iter().for_each(|&p| all.add(p));
        assert_eq!(a.combined(&b), all);
        assert_eq!(Moments::default().centroid(), [0.0; 3]);
        assert_eq!(Moments::default().covariance(), Matrix3::zeros());
    }
}
