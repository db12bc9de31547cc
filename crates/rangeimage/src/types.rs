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
/// Every grid has the range image's size; `NAN` marks pixels where the quantity is undefined.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SurfaceFeatures {
    /// Local plane parameters `[a, b, c]`.
    pub plane: PlaneMap,
    /// First derivatives `[Ix, Iy]` of the quadratic fit.
    pub gradient: Grid<[f32; 2]>,
    /// Second derivatives `[Ixx, Ixy, Iyy]` of the quadratic fit.
    pub hessian: Grid<[f32; 3]>,
    /// Gaussian curvature K.
    pub k: Grid<f32>,
    /// Mean curvature H.
    pub h: Grid<f32>,
    /// Principal curvatures `[k1, k2]` with `k1 ≥ k2`.
    pub principal: Grid<[f32; 2]>,
    /// Curvedness `sqrt((k1² + k2²) / 2)`.
    pub curvedness: Grid<f32>,
    /// Standard deviation of K over a window (seed acceptance).
    pub k_std: Grid<f32>,
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
