//! Step 3 of the final segmentation: every valid pixel outside the kept components given to the
//! adjacent region whose plane fits it best, ring by ring outward from the regions.

use crate::Scene;
use crate::plane::Plane;

const NBR8: [(i64, i64); 8] = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)];

/// How far from its plane a pixel may be and still join a region.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Limit {
    /// The limit in sensor units (0 = none).
    pub(crate) max_residual: f64,
    /// A region's limit is at least this × its plane's RMS (when `max_residual` > 0).
    pub(crate) rms_ratio: f64,
}

impl Limit {
    /// Whether a pixel at distance `res` from `plane` is too far to join it.
    pub(crate) fn refuses(&self, res: f64, plane: &Plane) -> bool {
        self.max_residual > 0.0 && res > self.max_residual.max(self.rms_ratio * plane.rms)
    }
}

/// Fills the unlabelled valid pixels of `comp` ring by ring (`planes[l − 1]` is the plane of label
/// `l`). Each ring is decided from the labels of the previous rings only, so the order of pixels
/// within a ring does not matter. A pixel beyond `limit` from its best plane stays 0 and grows no
/// further ring. `bufs` holds the working memory, reused from frame to frame.
pub(crate) fn fill(scene: &Scene<'_>, comp: &mut [u32], planes: &[Plane], limit: Limit, bufs: &mut Buffers) {
    let n = scene.w * scene.h;
    let Buffers { in_ring, ring, next, assign } = bufs;
    in_ring.clear();
    in_ring.resize(n, false);
    // A ring holds each pixel at most once: room for all, reserved once and touched only as far as used.
    for v in [&mut *ring, &mut *next] {
        v.clear();
        v.reserve(n);
    }
    assign.clear();
    assign.reserve(n);
    first_ring(scene, comp, in_ring, ring);
    let mut rings = 0u32;
    while !ring.is_empty() {
        rings += 1;
        assign.clear();
        assign.extend(
            ring.iter().map(|&(x, y)| best_label(scene, comp, planes, x as usize, y as usize, limit)),
        );
        for (&(x, y), &l) in ring.iter().zip(assign.iter()) {
            comp[y as usize * scene.w + x as usize] = l;
        }
        next_ring(scene, comp, ring, assign, in_ring, next);
        std::mem::swap(ring, next);
    }
    tracing::debug!(components = planes.len(), rings, "filled");
}

/// The working memory of [`fill`], kept between frames.
#[derive(Debug, Default)]
pub(crate) struct Buffers {
    /// Per pixel: whether it has been in a ring.
    in_ring: Vec<bool>,
    /// The current and the next ring.
    ring: Vec<(u32, u32)>,
    next: Vec<(u32, u32)>,
    /// The label decided for each pixel of the current ring.
    assign: Vec<u32>,
}

/// The valid unlabelled pixels 8-adjacent to a labelled one, in raster order (marked in `in_ring`), into the
/// empty `ring`.
fn first_ring(scene: &Scene<'_>, comp: &[u32], in_ring: &mut [bool], ring: &mut Vec<(u32, u32)>) {
    let (w, h, r) = (scene.w, scene.h, scene.range);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if comp[i] == 0 && r[i].is_finite() {
                let mut touches = false;
                for_neighbours(x, y, w, h, |j, _, _| touches |= comp[j] != 0);
                if touches {
                    in_ring[i] = true;
                    ring.push((x as u32, y as u32));
                }
            }
        }
    }
}

/// The label of the 8-adjacent region whose plane fits the ring pixel (x, y) best (ties to the
/// smaller label), or 0 if that plane is beyond `limit`.
fn best_label(scene: &Scene<'_>, comp: &[u32], planes: &[Plane], x: usize, y: usize, limit: Limit) -> u32 {
    let p = scene.point(x, y).expect("ring pixels are valid");
    let mut best: Option<(f64, u32, &Plane)> = None;
    let mut last = 0u32;
    for_neighbours(x, y, scene.w, scene.h, |j, _, _| {
        let l = comp[j];
        if l == 0 || l == last {
            return;
        }
        last = l;
        let plane = &planes[l as usize - 1];
        let res = plane.residual(p);
        if best.is_none_or(|(br, bl, _)| res < br || (res == br && l < bl)) {
            best = Some((res, l, plane));
        }
    });
    let (res, l, plane) = best.expect("ring pixels touch a region");
    // A pixel too far from every adjacent plane stays 0 (and grows no further ring).
    if limit.refuses(res, plane) { 0 } else { l }
}

/// The next ring into `next`: the valid unlabelled pixels not yet in a ring that are 8-adjacent to
/// a pixel of `ring` that was assigned a label.
fn next_ring(
    scene: &Scene<'_>,
    comp: &[u32],
    ring: &[(u32, u32)],
    assign: &[u32],
    in_ring: &mut [bool],
    next: &mut Vec<(u32, u32)>,
) {
    next.clear();
    for (&(x, y), _) in ring.iter().zip(assign).filter(|&(_, &l)| l != 0) {
        for_neighbours(x as usize, y as usize, scene.w, scene.h, |j, nx, ny| {
            if comp[j] == 0 && !in_ring[j] && scene.range[j].is_finite() {
                in_ring[j] = true;
                next.push((nx as u32, ny as u32));
            }
        });
    }
}

/// Calls `f(index, x, y)` for every in-image 8-neighbour of (x, y).
#[inline(always)]
pub(crate) fn for_neighbours(x: usize, y: usize, w: usize, h: usize, mut f: impl FnMut(usize, usize, usize)) {
    let i = y * w + x;
    if x > 0 && y > 0 && x + 1 < w && y + 1 < h {
        f(i - w - 1, x - 1, y - 1);
        f(i - w, x, y - 1);
        f(i - w + 1, x + 1, y - 1);
        f(i - 1, x - 1, y);
        f(i + 1, x + 1, y);
        f(i + w - 1, x - 1, y + 1);
        f(i + w, x, y + 1);
        f(i + w + 1, x + 1, y + 1);
    } else {
        for &(dx, dy) in &NBR8 {
            let (nx, ny) = (x as i64 + dx, y as i64 + dy);
            if nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64 {
                f(ny as usize * w + nx as usize, nx as usize, ny as usize);
            }
        }
    }
}
