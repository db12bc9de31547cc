//! Test and bench helpers: synthetic piecewise-planar range images with their features, from the real
//! `features` stage (a dev-dependency: the one stage the tidy rule lets another stage's tests use).
//!
//! This file is also compiled into `benches/regiongrow.rs` through `#[path]`.
#![allow(dead_code)]

use rangeimage::{Grid, RangeImage, SurfaceFeatures};

/// A range image with its features.
pub(crate) struct Scene {
    /// Float range values (no quantisation).
    pub(crate) range: RangeImage,
    /// Features from [`features`].
    pub(crate) features: SurfaceFeatures,
}

/// The features of `range` from the `features` stage, with 3×3 windows (the smallest; the scenes are small).
pub(crate) fn features(range: &RangeImage) -> SurfaceFeatures {
    features::compute(range, &features::Params { window_px: 3, deriv_window_px: 3, k_std_window_px: 3 })
}

/// Which face of [`box_scene`] a pixel belongs to: 1 = face A, 2 = face B (crease with A at
/// x = 31/32), 3 = the box top (jump), 0 = no data.
pub(crate) fn box_face(x: u32, y: u32) -> u32 {
    if (10..12).contains(&x) && (50..54).contains(&y) {
        0
    } else if x >= 44 && y >= 40 {
        3
    } else if x <= 31 {
        1
    } else {
        2
    }
}

/// 64×64 scene in `Camera::Grid` units: a roof of two faces meeting at a 72° crease, a box top
/// in front of face B (depth jump of about 40), and a 2×4 patch of no data.
pub(crate) fn box_scene() -> Scene {
    let range = Grid::from_fn(64, 64, |x, y| {
        let (xf, yf) = (x as f32, y as f32);
        match box_face(x, y) {
            0 => f32::NAN,
            1 => 100.0 + 0.8 * xf + 0.2 * yf,
            2 => 100.0 + 0.8 * 31.0 - 0.7 * (xf - 31.0) + 0.2 * yf,
            _ => 60.0 + 0.1 * xf + 0.3 * yf,
        }
    });
    let features = features(&range);
    Scene { range, features }
}

/// A `side × side` ABW-like scene (raw range values, larger = farther, for `Camera::ABW0`):
/// a background wall, a two-faced box with a crease and a shadow beside it, a ridge-shaped
/// wedge and a small block, plus a deterministic ±0.05 ripple so K is not exactly zero.
pub(crate) fn abw_like_scene(side: u32) -> Scene {
    let s = side as f32;
    let range = Grid::from_fn(side, side, |x, y| {
        let (xf, yf) = (x as f32, y as f32);
        let ripple = 0.05 * (((x.wrapping_mul(7919) ^ y.wrapping_mul(104_729)) % 97) as f32 / 48.0 - 1.0);
        let (bx0, bx1, by0, by1) = (0.25 * s, 0.5 * s, 0.3 * s, 0.7 * s);
        let v = if xf >= bx0 && xf < bx1 && yf >= by0 && yf < by1 {
            let xc = 0.375 * s;
            let across = if xf < xc { 0.4 * (xf - bx0) } else { 0.4 * (xc - bx0) - 0.4 * (xf - xc) };
            120.0 - 0.5 * across + 0.1 * (yf - by0) * 128.0 / s
        } else if xf >= bx1 && xf < bx1 + 0.03 * s && yf >= by0 && yf < by1 {
            f32::NAN
        } else if xf >= 0.6 * s && xf < 0.85 * s && yf >= 0.2 * s && yf < 0.5 * s {
            100.0 + 0.3 * (yf - 0.35 * s).abs() * 256.0 / s
        } else if xf >= 0.6 * s && xf < 0.7 * s && yf >= 0.7 * s && yf < 0.8 * s {
            140.0 + 0.05 * xf * 256.0 / s
        } else {
            220.0 - 0.02 * xf * 512.0 / s
        };
        v + ripple
    });
    let features = features(&range);
    Scene { range, features }
}

/// Labels renumbered 1.. in raster order of first appearance (0 stays 0).
pub(crate) fn canonical(labels: &[u32]) -> Vec<u32> {
    let max = labels.iter().copied().max().unwrap_or(0) as usize;
    let mut map = vec![0u32; max + 1];
    let mut next = 0;
    labels
        .iter()
        .map(|&l| {
            if l == 0 {
                return 0;
            }
            if map[l as usize] == 0 {
                next += 1;
                map[l as usize] = next;
            }
            map[l as usize]
        })
        .collect()
}
