//! Dense row-major grids, camera models and the plain data types every stage shares.
//!
//! Pixel `(x, y)` is `data[y * width + x]`: x is the column, y the row, row 0 at the top.
//! This crate does no I/O and depends on no math or image crate, so every stage can use it.

pub mod boundary;
mod camera;
pub mod distance;
mod grid;
mod params;
mod types;
pub mod union_find;

#[cfg(feature = "testing")]
pub mod testing;

pub use camera::{AbwCalibration, Camera};
pub use grid::Grid;
pub use params::ParamError;
pub use types::{EdgeMap, LabelImage, NormalMap, PlaneMap, RangeImage, Region, SurfaceFeatures, valid_mask};

/// Builds a [`RangeImage`] from rows of literals: `range_image![1.0, 2.0; f32::NAN, 3.0]`.
#[macro_export]
macro_rules! range_image {
    ($($($v:expr),+ $(,)?);+ $(;)?) => {{
        let rows: ::std::vec::Vec<::std::vec::Vec<f32>> = vec![$(vec![$($v as f32),+]),+];
        $crate::Grid::from_rows(rows).expect("range_image!: rows must be non-empty and of equal length")
    }};
}
