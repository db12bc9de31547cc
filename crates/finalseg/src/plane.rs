//! Region planes: the least-squares plane through the moments of a region's 3D points.

use nalgebra::Vector3;
use planefit::{Moments, dot};
use rangeimage::Camera;

/// A fitted 3D plane `normal · p + offset = 0` with the statistics of its support.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Plane {
    /// Unit normal, oriented toward the sensor.
    pub(crate) normal: [f64; 3],
    /// Offset.
    pub(crate) offset: f64,
    /// RMS distance of the support's points to the plane.
    pub(crate) rms: f64,
}

impl Plane {
    /// Signed distance of `p` to the plane: positive on the side of the sensor (the normal's side).
    pub(crate) fn signed(&self, p: [f64; 3]) -> f64 {
        dot(self.normal, p) + self.offset
    }

    /// Distance of `p` to the plane.
    pub(crate) fn residual(&self, p: [f64; 3]) -> f64 {
        self.signed(p).abs()
    }

    /// How far a residual to this plane understates its misfit for a pixel whose line of sight is `ray` (a unit
    /// vector), as a divisor in `[1 / STEEP_MAX_GAIN, 1]`: 1 while `|normal · ray|` is at least `steep_cos`, then
    /// `|normal · ray| / steep_cos`. Range noise lies along the line of sight, and a point at distance `r` from a
    /// plane seen at an angle whose cosine is `c` lies `r / c` from it along that line: on a plane seen almost
    /// edge-on, the pixels beside it fit within the noise whatever their depth. 1 when `steep_cos` is 0 (off).
    pub(crate) fn view_factor(&self, ray: [f64; 3], steep_cos: f64) -> f64 {
        if steep_cos > 0.0 {
            (dot(self.normal, ray).abs() / steep_cos).clamp(1.0 / STEEP_MAX_GAIN, 1.0)
        } else {
            1.0
        }
    }
}

/// The most [`Plane::view_factor`] multiplies a residual by (a plane seen within about 3.4° of edge-on at
/// `steep_cos` 0.3).
pub(crate) const STEEP_MAX_GAIN: f64 = 5.0;

/// Mean squared distance of the points summarised by `m` to `plane` (`nᵀ·Σ·n` plus the centroid's
/// squared distance).
pub(crate) fn mean_sq_residual(m: &Moments, plane: &Plane) -> f64 {
    let nv = Vector3::from(plane.normal);
    let c = m.centroid();
    let along = plane.signed(c);
    ((nv.transpose() * m.covariance() * nv)[0]).max(0.0) + along * along
}

/// Least-squares plane of the points summarised by `m`: the eigenvector of the first smallest
/// eigenvalue of the covariance (`[0, 0, 1]` if it has no length), with the normal oriented toward
/// the sensor. Always a plane, even for degenerate point sets.
pub(crate) fn fit_plane(m: &Moments, camera: &Camera) -> Plane {
    let c = m.centroid();
    let axes = m.axes();
    let mut k = 0;
    for i in 1..3 {
        if axes.values[i] < axes.values[k] {
            k = i;
        }
    }
    let v = axes.vectors[k];
    // The same sum of squares, in the same order, as nalgebra's `norm`.
    let len = dot(v, v).sqrt();
    let mut normal = if len > 0.0 { [v[0] / len, v[1] / len, v[2] / len] } else { [0.0, 0.0, 1.0] };
    let toward = camera.toward_sensor(c);
    if normal[0] * toward[0] + normal[1] * toward[1] + normal[2] * toward[2] < 0.0 {
        normal = normal.map(|x| -x);
    }
    let offset = -(normal[0] * c[0] + normal[1] * c[1] + normal[2] * c[2]);
    let mut plane = Plane { normal, offset, rms: 0.0 };
    plane.rms = mean_sq_residual(m, &plane).sqrt();
    plane
}
