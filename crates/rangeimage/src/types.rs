//! The image aliases and plain structs that cross stage boundaries.

use crate::Grid;

/// Range values in the image's own units (raw 8-bit value for ABW, metres for depth sensors);
/// `f32::NAN` means no data.
pub type RangeImage = Grid<f32>;

/// Region labels: 0 = unlabelled, any other value names a region.
pub type LabelImage = Grid<u32>;

/// Binary edge map: `true` = edge pixel.
pub type EdgeMap = Grid<bool>;

/// Unit normals in the sensor frame; `[NAN; 3]` where undefined.
pub type NormalMap = Grid<[f32; 3]>;

/// Per-pixel local plane `z = a·x + b·y + c` as `[a, b, c]`, with x and y measured from the
/// image centre in pixels and z in the range image's units; `[NAN; 3]` where no fit exists.
pub type PlaneMap = Grid<[f32; 3]>;

/// Per-pixel differential geometry of a range image, computed by the `features` stage.
///
/// Every grid has the range image's size; `NAN` marks pixels where the quantity is undefined. The principal
/// curvatures follow from H and K ([`SurfaceFeatures::principal`]); the first and second derivatives of the
/// quadratic fit are not kept here (nothing downstream reads them): the `features` stage offers them separately.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SurfaceFeatures {
    /// Local plane parameters `[a, b, c]`.
    pub plane: PlaneMap,
    /// Gaussian curvature K.
    pub k: Grid<f32>,
    /// Mean curvature H.
    pub h: Grid<f32>,
    /// Curvedness `sqrt((k1² + k2²) / 2)` of the principal curvatures k1, k2.
    pub curvedness: Grid<f32>,
    /// Standard deviation of K over a window (seed acceptance).
    pub k_std: Grid<f32>,
}

impl SurfaceFeatures {
    /// Principal curvatures `[k1, k2]` (k1 ≥ k2) of every pixel, `k1,2 = H ± sqrt(max(H² − K, 0))`.
    ///
    /// Computed in f64 from the stored f32 H and K, so near umbilics (`H² ≈ K`, e.g. a sphere) the half-difference
    /// carries the rounding of H and K: its absolute error is about `sqrt(3ε₃₂)·|H| ≈ 6e-4·|H|`. The `features`
    /// stage's derivative-based form has no such cancellation.
    pub fn principal(&self) -> Grid<[f32; 2]> {
        let (w, h) = self.h.dimensions();
        let data =
            self.h.as_slice().iter().zip(self.k.as_slice()).map(|(&h, &k)| principal_from_hk(h, k)).collect();
        Grid::from_vec(w, h, data).expect("H and K have one size")
    }
}

/// `[H + d, H − d]` with `d = sqrt(max(H² − K, 0))`, in f64; NaN propagates.
fn principal_from_hk(h: f32, k: f32) -> [f32; 2] {
    let (h, k) = (f64::from(h), f64::from(k));
    let d = (h * h - k).max(0.0).sqrt();
    // `max` would turn a NaN difference into 0: keep NaN where H or K is NaN.
    let d = if h.is_nan() || k.is_nan() { f64::NAN } else { d };
    [(h + d) as f32, (h - d) as f32]
}

/// One region of a segmentation, with its geometry in the sensor frame.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Region {
    /// The region's label in the label image.
    pub label: u32,
    /// Number of pixels.
    pub size_px: u32,
    /// Mean Gaussian curvature over the region.
    pub mean_k: f32,
    /// Unit normal of the region's 3D plane, oriented toward the sensor.
    pub normal: [f32; 3],
    /// Offset `d` of the plane `normal · p + d = 0` in sensor units.
    pub offset: f32,
    /// RMS point-to-plane distance of the region's 3D points, in sensor units.
    pub rms_residual: f32,
}

/// `true` where the range value is finite.
pub fn valid_mask(range: &RangeImage) -> Grid<bool> {
    range.map(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn principal_curvatures_from_h_and_k() {
        let g = |v: [f32; 4]| Grid::from_vec(4, 1, v.to_vec()).unwrap();
        // An umbilic (sphere of radius 50), a ridge (K = 0), a saddle, and no data.
        let f = SurfaceFeatures {
            h: g([0.02, 0.25, 0.0, f32::NAN]),
            k: g([0.0004, 0.0, -1.0, f32::NAN]),
            ..SurfaceFeatures::default()
        };
        let p = f.principal();
        let [s1, s2] = p[(0, 0)];
        assert!((s1 - 0.02).abs() < 2e-5 && (s2 - 0.02).abs() < 2e-5 && s1 >= s2, "{s1} {s2}");
        assert_eq!(p[(1, 0)], [0.5, 0.0]);
        assert_eq!(p[(2, 0)], [1.0, -1.0]);
        assert!(p[(3, 0)].iter().all(|v| v.is_nan()));
    }
}
