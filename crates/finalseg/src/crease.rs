//! Step 6 of the final segmentation: the pixels beside a crease go to the face their line of sight meets.
//!
//! Where two regions meet at a crease, the pixels beside it lie within the noise of both planes, so their
//! distances to the planes cannot place the border (step 5 leaves such a pixel where growth or an edge put it). On
//! a face seen edge-on, a few pixels wide, that band of doubt is a large part of the face. The two planes place
//! the border instead: a pixel's line of sight meets both, and the surface it sees is, at a convex crease (each
//! region behind the other's plane), the plane it meets last, and at a concave crease (each in front), the plane
//! it meets first.

use crate::Scene;
use crate::plane::Plane;
use crate::refine::{SIGMA_FLOOR, border_pixels_into, next_candidates};
use planefit::{Moments, dot};

/// A pixel is a crease pixel of the neighbouring region only within this many noise scales of that region's plane
/// (the noise scale: the larger RMS of the two planes, at least [`SIGMA_FLOOR`]); farther, its own depth places it.
const GATE: f64 = 2.0;

/// The working memory of [`creases`], kept from one frame to the next.
#[derive(Debug, Default)]
pub(crate) struct Buffers {
    /// The pixels a pass examines, in raster order.
    cand: Vec<u32>,
    /// The moves a pass decided: (pixel, new label).
    moves: Vec<(u32, u32)>,
    /// Per pixel: already among the next pass's candidates (all false between passes).
    seen: Vec<bool>,
    /// The centroid of each label (`centroids[l − 1]`).
    centroids: Vec<[f64; 3]>,
}

impl Buffers {
    /// The list the first pass of [`creases`] examines when told its border is given.
    pub(crate) fn border_mut(&mut self) -> &mut Vec<u32> {
        &mut self.cand
    }
}

/// How two regions meet: the kind of crease between their planes, if they meet at one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Crease {
    /// Each region lies behind the other's plane: the line of sight sees the plane it meets last.
    Convex,
    /// Each region lies in front of the other's plane: the line of sight sees the plane it meets first.
    Concave,
}

/// The crease between regions `a` and `b` (planes and centroids), if the cosine of the angle between their normals
/// is at most `cos_max` in magnitude and each centroid lies on the same side of the other's plane.
fn crease(pa: &Plane, pb: &Plane, ca: [f64; 3], cb: [f64; 3], cos_max: f64) -> Option<Crease> {
    let cos = dot(pa.normal, pb.normal);
    if cos.abs() > cos_max {
        return None;
    }
    match (pb.signed(ca), pa.signed(cb)) {
        (sa, sb) if sa < 0.0 && sb < 0.0 => Some(Crease::Convex),
        (sa, sb) if sa > 0.0 && sb > 0.0 => Some(Crease::Concave),
        _ => None,
    }
}

/// Moves the crease pixels of `groups` (a label per pixel, 0 = none; `planes[l − 1]` and `moments[l − 1]` describe
/// label `l`) to the region whose plane their line of sight sees, for pairs of 4-adjacent regions whose normals
/// differ by more than `min_angle_deg` and that meet at a crease. A pixel is examined against its 4-neighbours'
/// labels in the order left, right, up, down and moves to the first whose plane it sees (and lies within [`GATE`]
/// noise scales of). At most `passes` passes, each decided from the labels of the previous one; the planes stay
/// those given. Returns the number of moves.
///
/// With `border_given`, the first pass examines the pixels of [`Buffers::border_mut`] (the border pixels of
/// `groups` in raster order, as `refine::border_pixels_into` finds them); otherwise it scans for them.
pub(crate) fn creases(
    scene: &Scene<'_>,
    groups: &mut [u32],
    (planes, moments): (&[Plane], &[Moments]),
    (min_angle_deg, passes): (f64, u32),
    border_given: bool,
    bufs: &mut Buffers,
) -> u32 {
    let (w, h) = (scene.w, scene.h);
    let Buffers { cand, moves, seen, centroids } = bufs;
    let cos_max = min_angle_deg.to_radians().cos();
    centroids.clear();
    centroids.extend(moments.iter().map(Moments::centroid));
    // All false between passes and between calls: only a new frame size resizes it.
    if seen.len() != w * h {
        seen.clear();
        seen.resize(w * h, false);
    }
    // Each list holds a pixel at most once: room reserved once, touched as far as used (a given border list
    // comes with that room).
    if !border_given {
        cand.clear();
        cand.reserve(w * h);
        border_pixels_into(groups, w, h, cand);
    }
    moves.clear();
    moves.reserve(w * h);
    let mut total = 0u32;
    for _ in 0..passes {
        moves.clear();
        moves.extend(cand.iter().filter_map(|&i| {
            seen_label(scene, groups, (planes, centroids), i as usize, cos_max).map(|l| (i, l))
        }));
        if moves.is_empty() {
            break;
        }
        for &(i, l) in moves.iter() {
            groups[i as usize] = l;
        }
        total += moves.len() as u32;
        // Next candidates: the moved pixels' labelled neighbours.
        next_candidates(moves, groups, (w, h), seen, cand);
    }
    tracing::debug!(moves = total, "crease pixels placed");
    total
}

/// The label whose plane the line of sight of pixel `i` sees instead of its own, if any (see [`creases`]).
fn seen_label(
    scene: &Scene<'_>,
    groups: &[u32],
    (planes, centroids): (&[Plane], &[[f64; 3]]),
    i: usize,
    cos_max: f64,
) -> Option<u32> {
    let (w, h) = (scene.w, scene.h);
    let (x, y) = (i % w, i / w);
    let a = groups[i];
    // The 4-neighbours' labels (left, right, up, down) that differ from the pixel's and meet it at a crease.
    let mut others = [(0u32, Crease::Convex); 4];
    let mut n = 0;
    if a != 0 {
        let (pa, ca) = (&planes[a as usize - 1], centroids[a as usize - 1]);
        for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
            let (nx, ny) = (x as i64 + dx, y as i64 + dy);
            if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                continue;
            }
            let b = groups[ny as usize * w + nx as usize];
            if b == 0 || b == a {
                continue;
            }
            if let Some(kind) = crease(pa, &planes[b as usize - 1], ca, centroids[b as usize - 1], cos_max) {
                others[n] = (b, kind);
                n += 1;
            }
        }
    }
    if n == 0 {
        return None;
    }
    let r = f64::from(scene.range[i]);
    let p0 = scene.camera.point(x as f64, y as f64, r)?;
    let pa = &planes[a as usize - 1];
    // Only the neighbours whose plane the pixel lies near (within the noise) are candidates.
    let near = |b: u32| {
        let pb = &planes[b as usize - 1];
        pb.residual(p0) <= GATE * pa.rms.max(pb.rms).max(SIGMA_FLOOR)
    };
    let first = others[..n].iter().position(|&(b, _)| near(b))?;
    // The line of sight: the pixel's point and the point one range unit farther (every camera model is affine in
    // the range value along a pixel's ray).
    let p1 = scene.camera.point(x as f64, y as f64, r + 1.0)?;
    let d = [p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]];
    // Where along the line of sight (in range units from the pixel's point) it meets `plane`.
    let meet = |plane: &Plane| {
        let along = dot(plane.normal, d);
        (along.abs() > 1e-12).then(|| -plane.signed(p0) / along)
    };
    let ta = meet(pa)?;
    others[first..n]
        .iter()
        .find(|&&(b, kind)| {
            near(b)
                && meet(&planes[b as usize - 1]).is_some_and(|tb| match kind {
                    Crease::Convex => tb > ta,
                    Crease::Concave => tb < ta,
                })
        })
        .map(|&(b, _)| b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plane::fit_plane;
    use rangeimage::Camera;

    /// 60×10 grid image of two planes meeting at x = 30.5 (`v = 100 ± |x − 30.5|`: + is a ridge toward the
    /// sensor, a convex crease; − a valley, concave), with columns 28–30 of the left plane labelled as the right
    /// region; each plane fitted to its true pixels, with an RMS of 1 (a gate of 2 units). Returns the labels
    /// after `passes` passes.
    fn displaced_crease(sign: f32, passes: u32) -> Vec<u32> {
        let (w, h) = (60usize, 10usize);
        let range: Vec<f32> = (0..w * h).map(|i| 100.0 + sign * ((i % w) as f32 - 30.5).abs()).collect();
        let camera = Camera::Grid;
        let mut points = Vec::new();
        let scene = Scene::new(&range, (w, h), &camera, &mut points);
        let mut groups: Vec<u32> = (0..w * h).map(|i| if i % w <= 27 { 1 } else { 2 }).collect();
        let mut moments = [Moments::default(); 2];
        for i in 0..w * h {
            let p = scene.point(i % w, i / w).unwrap();
            moments[usize::from(i % w > 30)].add(p);
        }
        let planes = moments.map(|m| Plane { rms: 1.0, ..fit_plane(&m, &camera) });
        creases(&scene, &mut groups, (&planes, &moments), (20.0, passes), false, &mut Buffers::default());
        groups
    }

    #[test]
    fn crease_pixels_go_to_the_face_the_line_of_sight_sees() {
        for sign in [-1.0, 1.0] {
            for (passes, last_left) in [(0, 27), (1, 28), (3, 30), (10, 30)] {
                let groups = displaced_crease(sign, passes);
                for y in 0..10 {
                    for x in 0..60 {
                        let want = if x <= last_left { 1 } else { 2 };
                        assert_eq!(groups[y * 60 + x], want, "sign {sign}, {passes} passes, ({x}, {y})");
                    }
                }
            }
        }
    }

    /// A plane through `c` with unit normal `n`.
    fn plane(n: [f64; 3], c: [f64; 3]) -> Plane {
        Plane { normal: n, offset: -(n[0] * c[0] + n[1] * c[1] + n[2] * c[2]), rms: 0.1 }
    }

    #[test]
    fn crease_kinds_follow_the_sides_of_the_planes() {
        // Seen from +z: a box's top (normal +y) and front (normal +z) meet at a convex edge along y = 0, z = 0.
        let (top, front) = (plane([0.0, 1.0, 0.0], [0.0, 0.0, 0.0]), plane([0.0, 0.0, 1.0], [0.0, 0.0, 0.0]));
        let (c_top, c_front) = ([0.0, 0.0, -1.0], [0.0, -1.0, 0.0]);
        assert_eq!(crease(&top, &front, c_top, c_front, 0.9), Some(Crease::Convex));
        // The floor in front of a wall: concave.
        let (floor, wall) =
            (plane([0.0, 1.0, 0.0], [0.0, 0.0, 0.0]), plane([0.0, 0.0, 1.0], [0.0, 0.0, 0.0]));
        assert_eq!(crease(&floor, &wall, [0.0, 0.0, 1.0], [0.0, 1.0, 0.0], 0.9), Some(Crease::Concave));
        // A step: one region in front of the other's plane, the other behind: no crease.
        assert_eq!(crease(&floor, &wall, [0.0, 0.0, 1.0], [0.0, -1.0, 0.0], 0.9), None);
        // Nearly parallel planes: no crease.
        let tilted = plane([0.0, 0.1f64.sin(), 0.1f64.cos()], [0.0, 0.0, 0.0]);
        assert_eq!(crease(&front, &tilted, c_front, [0.0, 1.0, -1.0], 20f64.to_radians().cos()), None);
    }
}
