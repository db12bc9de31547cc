//! Region planes: the moments of a 3D point set and the least-squares plane through them.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rangeimage::Camera;

/// First and second moments of a 3D point set.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Moments {
    n: f64,
    s: [f64; 3],
    /// xx, xy, xz, yy, yz, zz.
    ss: [f64; 6],
}

impl Moments {
    pub(crate) fn add(&mut self, p: [f64; 3]) {
        self.n += 1.0;
        for k in 0..3 {
            self.s[k] += p[k];
        }
        let [x, y, z] = p;
        for (acc, v) in self.ss.iter_mut().zip([x * x, x * y, x * z, y * y, y * z, z * z]) {
            *acc += v;
        }
    }

    pub(crate) fn merge(&mut self, o: &Moments) {
        self.n += o.n;
        for k in 0..3 {
            self.s[k] += o.s[k];
        }
        for k in 0..6 {
            self.ss[k] += o.ss[k];
        }
    }

    pub(crate) fn mean(&self) -> [f64; 3] {
        let n = self.n.max(1.0);
        self.s.map(|v| v / n)
    }

    /// Covariance matrix (divided by n).
    pub(crate) fn cov(&self) -> Matrix3<f64> {
        let n = self.n.max(1.0);
        let c = self.mean();
        let e = |k: usize, a: usize, b: usize| self.ss[k] / n - c[a] * c[b];
        let (xx, xy, xz, yy, yz, zz) =
            (e(0, 0, 0), e(1, 0, 1), e(2, 0, 2), e(3, 1, 1), e(4, 1, 2), e(5, 2, 2));
        Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
    }

    /// Mean squared distance of the points to `plane`.
    pub(crate) fn mean_sq_residual(&self, plane: &Plane) -> f64 {
        let nv = Vector3::from(plane.normal);
        let c = self.mean();
        let along = plane.normal[0] * c[0] + plane.normal[1] * c[1] + plane.normal[2] * c[2] + plane.offset;
        ((nv.transpose() * self.cov() * nv)[0]).max(0.0) + along * along
    }
}

/// A fitted 3D plane `normal · p + offset = 0` with the statistics of its support.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Plane {
    pub(crate) normal: [f64; 3],
    pub(crate) offset: f64,
    pub(crate) rms: f64,
}

impl Plane {
    pub(crate) fn residual(&self, p: [f64; 3]) -> f64 {
        (self.normal[0] * p[0] + self.normal[1] * p[1] + self.normal[2] * p[2] + self.offset).abs()
    }
}

/// Least-squares plane of the points summarised by `m` (smallest eigenvector of the
/// covariance), with the normal oriented toward the sensor.
pub(crate) fn fit_plane(m: &Moments, camera: &Camera) -> Plane {
    let c = m.mean();
    let eig = SymmetricEigen::new(m.cov());
    let mut k = 0;
    for i in 1..3 {
        if eig.eigenvalues[i] < eig.eigenvalues[k] {
            k = i;
        }
    }
    let v = eig.eigenvectors.column(k);
    let len = v.norm();
    let mut normal = if len > 0.0 { [v[0] / len, v[1] / len, v[2] / len] } else { [0.0, 0.0, 1.0] };
    let toward = camera.toward_sensor(c);
    if normal[0] * toward[0] + normal[1] * toward[1] + normal[2] * toward[2] < 0.0 {
        normal = normal.map(|x| -x);
    }
    let offset = -(normal[0] * c[0] + normal[1] * c[1] + normal[2] * c[2]);
    let mut plane = Plane { normal, offset, rms: 0.0 };
    plane.rms = m.mean_sq_residual(&plane).sqrt();
    plane
}
