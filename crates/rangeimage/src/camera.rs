//! Camera models: how a pixel and its stored value map to a 3D point.

use serde::{Deserialize, Serialize};

/// The USF `range-to-coords` calibration of one ABW scanner setting (docs/method.md §2.1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AbwCalibration {
    /// Added to `v / scal` to give the distance term `d`.
    pub offset: f64,
    /// Range units per 8-bit step.
    pub scal: f64,
    /// Focal length in pixels (only `|f|` is used).
    pub f: f64,
    /// Row-to-column aspect correction.
    pub c: f64,
}

impl AbwCalibration {
    /// Calibration 0: every ABW image except test 0, 19, 21, 25, 27, 28, 29.
    pub const CAL0: Self = Self { offset: 771.016866, scal: 0.791686, f: -1586.072821, c: 1.4508 };
    /// Calibration 1: ABW test images 0, 19, 21, 25, 27, 28 and 29.
    pub const CAL1: Self = Self { offset: 785.410786, scal: 0.773545, f: -1610.981722, c: 1.4508 };
}

/// Maps pixel `(x, y)` with stored range value `v` to a 3D point in the sensor frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Camera {
    /// The ABW structured-light scanner; `v` is the raw 8-bit range value.
    Abw(AbwCalibration),
    /// A pinhole depth camera; `v · depth_scale` is the depth Z along the optical axis.
    Pinhole {
        /// Focal length along x, in pixels.
        fx: f64,
        /// Focal length along y, in pixels.
        fy: f64,
        /// Principal point column.
        cx: f64,
        /// Principal point row.
        cy: f64,
        /// Multiplier from stored value to depth (1.0 when the image is already in metres).
        depth_scale: f64,
    },
    /// No calibration: the point is `(x, y, v)` itself.
    Grid,
}

impl Camera {
    /// The ABW camera for calibration 0.
    pub const ABW0: Camera = Camera::Abw(AbwCalibration::CAL0);
    /// The ABW camera for calibration 1.
    pub const ABW1: Camera = Camera::Abw(AbwCalibration::CAL1);

    /// The ABW calibration of the image with this split and index (docs/method.md §2.1).
    pub fn abw_for(test_split: bool, index: u32) -> Camera {
        if test_split && matches!(index, 0 | 19 | 21 | 25 | 27 | 28 | 29) { Self::ABW1 } else { Self::ABW0 }
    }

    /// The 3D point of pixel `(x, y)` with stored value `v`; `None` if `v` is not finite.
    pub fn point(&self, x: f64, y: f64, v: f64) -> Option<[f64; 3]> {
        if !v.is_finite() {
            return None;
        }
        Some(match *self {
            Camera::Abw(cal) => {
                let d = v / cal.scal + cal.offset;
                let f = cal.f.abs();
                [(x - 255.0) * d / f, (255.0 - y) / cal.c * d / f, (255.0 - v) / cal.scal]
            }
            Camera::Pinhole { fx, fy, cx, cy, depth_scale } => {
                let z = v * depth_scale;
                [(x - cx) * z / fx, (y - cy) * z / fy, z]
            }
            Camera::Grid => [x, y, v],
        })
    }

    /// The 3D points of row `y` with values `vals` into `out`: [`Camera::point`]'s formulas, operation for operation
    /// (the same bits), with the camera model resolved once per row; points of non-finite values are meaningless.
    /// Inlined into the caller, so a caller compiled for a wider instruction set (`isa::dispatch`) vectorises it.
    #[inline(always)]
    pub fn row_points(&self, y: u32, vals: &[f32], out: &mut [[f64; 3]]) {
        let y = f64::from(y);
        let cols = vals.iter().zip(out.iter_mut()).zip(0u32..);
        match *self {
            Camera::Abw(cal) => {
                let f = cal.f.abs();
                // `(255 − y) / c · d / f` groups as `((255 − y) / c · d) / f`.
                let ty = (255.0 - y) / cal.c;
                for ((&v, o), x) in cols {
                    let v = f64::from(v);
                    let d = v / cal.scal + cal.offset;
                    *o = [(f64::from(x) - 255.0) * d / f, ty * d / f, (255.0 - v) / cal.scal];
                }
            }
            Camera::Pinhole { fx, fy, cx, cy, depth_scale } => {
                let ty = y - cy;
                for ((&v, o), x) in cols {
                    let z = f64::from(v) * depth_scale;
                    *o = [(f64::from(x) - cx) * z / fx, ty * z / fy, z];
                }
            }
            Camera::Grid => {
                for ((&v, o), x) in cols {
                    *o = [f64::from(x), y, f64::from(v)];
                }
            }
        }
    }

    /// A unit vector from the 3D point of a pixel toward the sensor, to orient normals.
    pub fn toward_sensor(&self, p: [f64; 3]) -> [f64; 3] {
        let d = match *self {
            // ABW: Z = (255 − v)/scal grows toward the scanner.
            Camera::Abw(_) | Camera::Grid => {
                [0.0, 0.0, if matches!(self, Camera::Grid) { -1.0 } else { 1.0 }]
            }
            Camera::Pinhole { .. } => [-p[0], -p[1], -p[2]],
        };
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if n > 0.0 { [d[0] / n, d[1] / n, d[2] / n] } else { [0.0, 0.0, -1.0] }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn abw_centre_pixel_is_on_axis() {
        let p = Camera::ABW0.point(255.0, 255.0, 100.0).unwrap();
        assert_eq!(p[0], 0.0);
        assert_eq!(p[1], 0.0);
        assert!((p[2] - 155.0 / 0.791686).abs() < 1e-9);
    }

    #[test]
    fn abw_calibration_by_name() {
        assert_eq!(Camera::abw_for(true, 19), Camera::ABW1);
        assert_eq!(Camera::abw_for(true, 18), Camera::ABW0);
        assert_eq!(Camera::abw_for(false, 0), Camera::ABW0);
    }

    #[test]
    fn pinhole_back_projects() {
        let cam = Camera::Pinhole { fx: 500.0, fy: 500.0, cx: 320.0, cy: 240.0, depth_scale: 0.001 };
        let p = cam.point(420.0, 240.0, 2000.0).unwrap();
        assert!((p[0] - 0.4).abs() < 1e-12 && p[1] == 0.0 && (p[2] - 2.0).abs() < 1e-12);
        assert!(cam.point(0.0, 0.0, f64::NAN).is_none());
    }
    #[test]
    fn row_points_match_point_bit_for_bit() {
        let cams = [
            Camera::ABW0,
            Camera::ABW1,
            Camera::Pinhole { fx: 525.0, fy: 523.5, cx: 319.5, cy: 239.5, depth_scale: 0.0002 },
            Camera::Pinhole { fx: 5.1e2, fy: 4.9e2, cx: 0.3, cy: 477.0, depth_scale: 1.0 },
            Camera::Grid,
        ];
        // A fixed pseudo-random sequence of values (an LCG), with non-finite ones mixed in.
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for cam in cams {
            for y in [0u32, 1, 17, 255, 256, 479, 511] {
                let vals: Vec<f32> = (0..97)
                    .map(|k| match k % 13 {
                        5 => f32::NAN,
                        9 => f32::INFINITY,
                        _ => (next() * 6000.0 - 100.0) as f32,
                    })
                    .collect();
                let mut out = vec![[0.0; 3]; vals.len()];
                cam.row_points(y, &vals, &mut out);
                for (x, (&v, o)) in vals.iter().zip(&out).enumerate() {
                    if let Some(p) = cam.point(x as f64, f64::from(y), f64::from(v)) {
                        assert_eq!(p.map(f64::to_bits), o.map(f64::to_bits), "{cam:?} ({x}, {y}) {v}");
                    }
                }
            }
        }
    }
}
