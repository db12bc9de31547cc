//! Step 5 of the final segmentation: border pixels moved to the adjacent region whose plane fits
//! them better, so that a border lies where the two planes meet rather than where growth stopped.

use crate::Scene;
use crate::fill::{Limit, for_neighbours};
use crate::plane::{Plane, fit_plane};
use planefit::Moments;

/// The working memory of [`refine`] and [`refit`], kept from one frame to the next.
#[derive(Debug, Default)]
pub(crate) struct Buffers {
    /// The pixels a pass examines, in raster order.
    cand: Vec<u32>,
    /// The moves a pass decided: (pixel, new label).
    moves: Vec<(u32, u32)>,
    /// Per pixel: already among the next pass's candidates (all false between passes).
    seen: Vec<bool>,
    /// [`refit`]: the moments of each label.
    moments: Vec<Moments>,
    /// The border pixels the last [`refine`] started from, in raster order, and every pixel it moved.
    border: Vec<u32>,
    moved: Vec<u32>,
    /// Per pixel: moved or next to a moved pixel (all false between calls), and those pixels.
    dirty: Vec<bool>,
    dirty_list: Vec<u32>,
}

impl Buffers {
    /// The moments of each label's points as the last [`refit`] summed them.
    pub(crate) fn moments(&self) -> &[Moments] {
        &self.moments
    }

    /// Into `out`, the border pixels of `groups` (labels as the last [`refine`] left them, which started from a
    /// scan or an update of these buffers) in raster order: that call's start list updated around its moves (kept,
    /// so a second call on labels left unchanged gives the same list).
    pub(crate) fn border_after(&mut self, groups: &[u32], (w, h): (usize, usize), out: &mut Vec<u32>) {
        let Buffers { cand, border, moved, dirty, dirty_list, .. } = self;
        update_border(groups, (w, h), border, moved, (dirty, dirty_list), cand);
        moved.clear();
        out.clear();
        // Room for every pixel once, so later frames reuse the memory.
        out.reserve(w * h);
        out.extend_from_slice(border);
    }
}

/// Where [`refine`] takes its first pass's candidates from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Start {
    /// A scan of the whole image for border pixels.
    Scan,
    /// The border pixels of the last call, updated around the pixels it moved (the labels must be as that call
    /// left them): the same list as a scan.
    Update,
}

/// Moves border pixels of `groups` (a label per pixel, 0 = none; `planes[l − 1]` is the plane of
/// label `l`) to the 8-adjacent region that fits them better (see `better_label`). At most
/// `passes` passes: each is decided from the labels of the previous one only (ties keep the pixel
/// where it is, then go to the smaller label), so the order of pixels does not matter; a border
/// moves at most one pixel per pass; `steep_cos` is the refinement's view limit (`Params::refine_steep_cos`). Returns
/// the number of moves.
pub(crate) fn refine(
    scene: &Scene<'_>,
    groups: &mut [u32],
    (planes, start): (&[Plane], Start),
    (limit, steep_cos): (Limit, f64),
    passes: u32,
    bufs: &mut Buffers,
) -> u32 {
    let (w, h) = (scene.w, scene.h);
    let Buffers { cand, moves, seen, border, moved, dirty, dirty_list, .. } = bufs;
    // Candidates of the first pass: every labelled pixel with a differently labelled 8-neighbour.
    match start {
        Start::Scan => {
            seen.clear();
            seen.resize(w * h, false);
            border_pixels_into(groups, w, h, border);
        }
        Start::Update => update_border(groups, (w, h), border, moved, (dirty, dirty_list), cand),
    }
    moved.clear();
    // Each list holds a pixel at most once (`moved` once per pass): room reserved once, touched as far as used.
    moved.reserve(w * h);
    cand.clear();
    cand.reserve(w * h);
    cand.extend_from_slice(border);
    let mut total = 0u32;
    for _ in 0..passes {
        moves.clear();
        moves.extend(cand.iter().filter_map(|&i| {
            better_label(scene, groups, planes, i as usize, (limit, steep_cos)).map(|l| (i, l))
        }));
        if moves.is_empty() {
            break;
        }
        for &(i, l) in moves.iter() {
            groups[i as usize] = l;
        }
        moved.extend(moves.iter().map(|&(i, _)| i));
        total += moves.len() as u32;
        // Next candidates: the moved pixels' labelled neighbours (their best plane may have come
        // next to them).
        next_candidates(moves, groups, (w, h), seen, cand);
    }
    tracing::debug!(moves = total, "refined borders");
    total
}

/// Into `cand`, the labelled 8-neighbours of the pixels of `moves` in `groups` (rows of `w`), each once, in raster
/// order; `seen` (all false before and after) marks those already listed.
pub(crate) fn next_candidates(
    moves: &[(u32, u32)],
    groups: &[u32],
    (w, h): (usize, usize),
    seen: &mut [bool],
    cand: &mut Vec<u32>,
) {
    cand.clear();
    for &(i, _) in moves {
        let i = i as usize;
        for_neighbours(i % w, i / w, w, h, |j, _, _| {
            if groups[j] != 0 && !seen[j] {
                seen[j] = true;
                cand.push(j as u32);
            }
        });
    }
    cand.sort_unstable();
    for &j in cand.iter() {
        seen[j as usize] = false;
    }
}

/// Whether labelled pixel (x, y) of `groups` has an 8-neighbour of another nonzero label (the rule itself).
#[inline(always)]
fn is_border(groups: &[u32], w: usize, h: usize, x: usize, y: usize) -> bool {
    let l = groups[y * w + x];
    let mut border = false;
    if l != 0 {
        for_neighbours(x, y, w, h, |j, _, _| border |= groups[j] != 0 && groups[j] != l);
    }
    border
}

/// Every labelled pixel of `groups` (rows of `w`) with an 8-neighbour of another nonzero label, in raster
/// order, into `cand`. In the interior rows, a chunk of pixels whose 3-row window holds no nonzero label but that
/// of its first pixel is skipped whole (none of them can be a border pixel); the others are tested side by side into a bit mask, by
/// the rule of [`is_border`] on the eight neighbours read directly. The frame's pixels go through [`is_border`].
pub(crate) fn border_pixels_into(groups: &[u32], w: usize, h: usize, cand: &mut Vec<u32>) {
    const CHUNK: usize = 16;
    cand.clear();
    let test = |x: usize, y: usize, cand: &mut Vec<u32>| {
        if is_border(groups, w, h, x, y) {
            cand.push((y * w + x) as u32);
        }
    };
    for y in 0..h {
        let mut x = 0;
        if y > 0 && y + 1 < h {
            let (up, row, dn) =
                (&groups[(y - 1) * w..y * w], &groups[y * w..(y + 1) * w], &groups[(y + 1) * w..(y + 2) * w]);
            test(0, y, cand);
            x = 1;
            // Pixels x .. x + CHUNK read columns x − 1 ..= x + CHUNK.
            while x + CHUNK < w {
                let v = row[x];
                let cols = x - 1..x + CHUNK + 1;
                // Nonzero iff the window holds a nonzero label other than `v` (each label's difference from `v`
                // masked to 0 where the label is 0).
                let diff = up[cols.clone()].iter().zip(&row[cols.clone()]).zip(&dn[cols.clone()]).fold(
                    0u32,
                    |a, ((&p, &q), &r)| {
                        let other = |l: u32| (l ^ v) & 0u32.wrapping_sub(u32::from(l != 0));
                        a | other(p) | other(q) | other(r)
                    },
                );
                if diff != 0 {
                    let (u, r, d) = (&up[cols.clone()], &row[cols.clone()], &dn[cols]);
                    let mut bits = 0u32;
                    for k in 0..CHUNK {
                        let l = r[k + 1];
                        let differs = |n: u32| (n != 0) & (n != l);
                        let any = differs(u[k])
                            | differs(u[k + 1])
                            | differs(u[k + 2])
                            | differs(r[k])
                            | differs(r[k + 2])
                            | differs(d[k])
                            | differs(d[k + 1])
                            | differs(d[k + 2]);
                        bits |= u32::from((l != 0) & any) << k;
                    }
                    while bits != 0 {
                        cand.push((y * w + x + bits.trailing_zeros() as usize) as u32);
                        bits &= bits - 1;
                    }
                }
                x += CHUNK;
            }
        }
        for xx in x..w {
            test(xx, y, cand);
        }
    }
}

/// Into `border`, the border pixels of `groups` (rows of `w`) in raster order, from `border`, the border pixels
/// before the pixels `moved` changed label: only a moved pixel or one of its 8-neighbours can change status, so
/// those (marked in `dirty`, listed in `list`) are tested again and merged with the others of the old list.
/// `out` is working memory.
fn update_border(
    groups: &[u32],
    (w, h): (usize, usize),
    border: &mut Vec<u32>,
    moved: &[u32],
    (dirty, list): (&mut Vec<bool>, &mut Vec<u32>),
    out: &mut Vec<u32>,
) {
    dirty.resize(w * h, false);
    list.clear();
    list.reserve(w * h);
    for &i in moved {
        let i = i as usize;
        let mark = |j: usize, dirty: &mut Vec<bool>, list: &mut Vec<u32>| {
            if !dirty[j] {
                dirty[j] = true;
                list.push(j as u32);
            }
        };
        mark(i, dirty, list);
        for_neighbours(i % w, i / w, w, h, |j, _, _| mark(j, dirty, list));
    }
    list.sort_unstable();
    out.clear();
    let mut old = border.iter().copied().filter(|&i| !dirty[i as usize]).peekable();
    for &j in list.iter() {
        while let Some(i) = old.next_if(|&i| i < j) {
            out.push(i);
        }
        if is_border(groups, w, h, j as usize % w, j as usize / w) {
            out.push(j);
        }
    }
    out.extend(old);
    for &j in list.iter() {
        dirty[j as usize] = false;
    }
    std::mem::swap(border, out);
}

/// Into `planes`, `base` refitted by [`refit`] to the labels of `groups` (a label without pixels keeps its plane of
/// `base`).
pub(crate) fn refit_from(
    scene: &Scene<'_>,
    groups: &[u32],
    base: &[Plane],
    planes: &mut Vec<Plane>,
    bufs: &mut Buffers,
) {
    planes.clear();
    planes.extend_from_slice(base);
    refit(scene, groups, planes, bufs);
}

/// Refits `planes` (`planes[l − 1]` for label `l`) to every valid pixel of each label of `groups`,
/// moments summed in raster order; a label without pixels keeps its plane.
pub(crate) fn refit(scene: &Scene<'_>, groups: &[u32], planes: &mut [Plane], bufs: &mut Buffers) {
    let moments = &mut bufs.moments;
    moments.clear();
    moments.resize(planes.len(), Moments::default());
    let w = scene.w;
    // Compiled for the best instruction set of this CPU (the same bits on every one).
    isa::dispatch(
        #[inline(always)]
        || {
            // Runs of one label are summed in a local copy of its moments (the same additions in the same
            // order, but in registers).
            let mut cur = 0u32;
            let mut acc = Moments::default();
            for (y, labels) in groups.chunks_exact(w.max(1)).enumerate() {
                if labels.iter().all(|&l| l == 0) {
                    continue;
                }
                let (vals, row) = scene.row(y);
                for (x, &l) in labels.iter().enumerate() {
                    if l != 0 && vals[x].is_finite() {
                        if l != cur {
                            if cur != 0 {
                                moments[cur as usize - 1] = acc;
                            }
                            cur = l;
                            acc = moments[cur as usize - 1];
                        }
                        acc.add(row[x]);
                    }
                }
            }
            if cur != 0 {
                moments[cur as usize - 1] = acc;
            }
        },
    );
    for (plane, m) in planes.iter_mut().zip(moments.iter()) {
        if m.n > 0.0 {
            *plane = fit_plane(m, scene.camera);
        }
    }
}

/// The label pixel `i` should move to, if an 8-adjacent region fits it better than its own (and
/// within `limit`). "Fits" is a Potts energy: the squared distance to the region's plane in units
/// of the noise (the largest RMS of the candidate planes, at least `SIGMA_FLOOR`), plus `BETA` per
/// 8-neighbour of another label, so that noise near a shallow crease does not fray the border. With `steep_cos` > 0,
/// the distances to and RMS of a plane that the pixel's line of sight meets at a cosine under `steep_cos` are divided
/// by [`Plane::view_factor`].
fn better_label(
    scene: &Scene<'_>,
    groups: &[u32],
    planes: &[Plane],
    i: usize,
    (limit, steep_cos): (Limit, f64),
) -> Option<u32> {
    let (w, h) = (scene.w, scene.h);
    let own = groups[i];
    let p = scene.point(i % w, i / w)?;
    let plane_of = |l: u32| &planes[l as usize - 1];
    // The distinct labels around (own first) and how many of the 8 neighbours carry each.
    let mut labs = [(own, 0u32); 9];
    let mut n = 1;
    for_neighbours(i % w, i / w, w, h, |j, _, _| {
        let l = groups[j];
        if l == 0 {
            return;
        }
        match labs[..n].iter_mut().find(|e| e.0 == l) {
            Some(e) => e.1 += 1,
            None => {
                labs[n] = (l, 1);
                n += 1;
            }
        }
    });
    if n == 1 {
        return None;
    }
    // Residuals and RMS of planes seen steeply from this pixel, scaled up toward their length along the line of
    // sight (`Plane::view_factor`; all 1 when `steep_cos` is 0), once per label.
    let ray = if steep_cos > 0.0 { scene.camera.toward_sensor(p) } else { [0.0; 3] };
    let (mut res, mut sigma) = ([0.0f64; 9], SIGMA_FLOOR);
    for (r, &(l, _)) in res.iter_mut().zip(&labs[..n]) {
        let plane = plane_of(l);
        let factor = plane.view_factor(ray, steep_cos);
        *r = plane.residual(p) / factor;
        sigma = sigma.max(plane.rms / factor);
    }
    // A pixel its own plane explains within the noise stays.
    if res[0] <= OUTLIER * sigma {
        return None;
    }
    let energy = |k: usize| {
        let r = res[k] / sigma;
        r * r + BETA * f64::from(8 - labs[k].1)
    };
    let mut best = (energy(0), own);
    for k in 1..n {
        let en = energy(k);
        if en < best.0 || (en == best.0 && best.1 != own && labs[k].0 < best.1) {
            best = (en, labs[k].0);
        }
    }
    let l = best.1;
    (l != own && !limit.refuses(plane_of(l).residual(p), plane_of(l))).then_some(l)
}

/// Weight of one disagreeing neighbour in the refinement energy. With 2.5 (and `OUTLIER` 1), a region whose
/// growth leaked past a shallow crease gives the leaked band back (its RMS, inflated by the leak, hid it from a
/// 2.5-scale gate), and the border that moves stays smooth: real ABW 15.40 -> 15.70 correct, boundary F up on
/// every set (docs/results.md).
const BETA: f64 = 2.5;
/// A pixel moves only if it lies farther than this many noise scales from its own plane.
const OUTLIER: f64 = 1.0;
/// Smallest noise scale of the refinement energy, in working units (where the NYU and Kinect frames have σ = 0.25,
/// ABW 0.34–0.49, the synthetic benchmark 0.67): a floor for noise-free planes, below every real image's noise.
pub(crate) const SIGMA_FLOOR: f64 = 0.25;

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// A pixel of a plane facing the sensor beside a face seen almost edge-on (grid camera, the face's normal at a
    /// cosine of 0.0995 with the line of sight), one unit off its own plane and ten units in front of the face's
    /// plane along its line of sight: only one unit from the face's plane in 3D. With most of its neighbours on the
    /// face, it joins the face when distances are taken as they are, and stays with `steep_cos` 0.3.
    #[test]
    fn a_face_seen_edge_on_does_not_take_the_pixels_beside_it() {
        let camera = rangeimage::Camera::Grid;
        let range = [100.0, 0.0, 0.0, 100.0, 101.0, 0.0, 100.0, 0.0, 0.0];
        let mut points = Vec::new();
        let scene = Scene::new(&range, (3, 3), &camera, &mut points);
        // Label 1 on the left column and the centre, label 2 (the face) on the other five pixels.
        let groups = [1, 2, 2, 1, 1, 2, 1, 2, 2];
        let k = 101f64.sqrt();
        let planes = [
            Plane { normal: [0.0, 0.0, -1.0], offset: 100.0, rms: 0.5 },
            Plane { normal: [10.0 / k, 0.0, -1.0 / k], offset: 101.0 / k, rms: 0.1 },
        ];
        assert!((planes[1].residual([1.0, 1.0, 101.0]) - 10.0 / k).abs() < 1e-12);
        let limit = Limit { max_residual: 2.0, rms_ratio: 2.0 };
        assert_eq!(better_label(&scene, &groups, &planes, 4, (limit, 0.0)), Some(2));
        assert_eq!(better_label(&scene, &groups, &planes, 4, (limit, 0.3)), None);
        // Facing the sensor more than the view limit, a plane's distances are taken as they are.
        assert_eq!(planes[0].view_factor([0.0, 0.0, -1.0], 0.3), 1.0);
        assert!((planes[1].view_factor([0.0, 0.0, -1.0], 0.3) - 1.0 / k / 0.3).abs() < 1e-12);
        assert_eq!(planes[1].view_factor([0.0, 0.0, -1.0], 0.01), 1.0);
        assert_eq!(planes[1].view_factor([0.0, 1.0, 0.0], 0.3), 0.2, "at most 5 times");
    }

    /// The border list updated around random moves is the list a scan of the moved labels finds.
    #[test]
    fn updated_border_matches_a_scan() {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(31);
        let (mut border, mut out, mut want) = (Vec::new(), Vec::new(), Vec::new());
        let (mut dirty, mut list) = (Vec::new(), Vec::new());
        for case in 0..300 {
            let (w, h) = (rng.random_range(1..60usize), rng.random_range(1..40usize));
            let (bw, bh) = (rng.random_range(1..30usize), rng.random_range(1..20usize));
            let mut groups: Vec<u32> = (0..w * h)
                .map(|i| {
                    let block = ((i % w) / bw + 3 * ((i / w) / bh)) as u32 % 5;
                    if rng.random_bool(0.02) { rng.random_range(0..5) } else { block }
                })
                .collect();
            border_pixels_into(&groups, w, h, &mut border);
            // Moves as refine makes them: labelled pixels to another nonzero label, some pixels twice.
            let mut moved = Vec::new();
            for _ in 0..rng.random_range(0..(w * h / 4 + 1)) {
                let i = rng.random_range(0..w * h);
                if groups[i] != 0 {
                    groups[i] = rng.random_range(1..6);
                    moved.push(i as u32);
                }
            }
            update_border(&groups, (w, h), &mut border, &moved, (&mut dirty, &mut list), &mut out);
            border_pixels_into(&groups, w, h, &mut want);
            assert_eq!(border, want, "case {case} ({w}×{h})");
            assert!(dirty.iter().all(|&d| !d), "case {case}: dirty flags left set");
        }
    }

    /// `border_after` gives the scan's list after moves, and the same list again when called a second time on the
    /// same labels (the band and crease steps both take it).
    #[test]
    fn border_after_twice_matches_a_scan() {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(44);
        let (mut out, mut want) = (Vec::new(), Vec::new());
        for case in 0..100 {
            let (w, h) = (rng.random_range(1..50usize), rng.random_range(1..30usize));
            let mut groups: Vec<u32> =
                (0..w * h).map(|i| ((i % w) / 7 + 2 * ((i / w) / 5)) as u32 % 4).collect();
            let mut bufs = Buffers::default();
            border_pixels_into(&groups, w, h, &mut bufs.border);
            for _ in 0..rng.random_range(0..(w * h / 4 + 1)) {
                let i = rng.random_range(0..w * h);
                if groups[i] != 0 {
                    groups[i] = rng.random_range(1..5);
                    bufs.moved.push(i as u32);
                }
            }
            border_pixels_into(&groups, w, h, &mut want);
            bufs.border_after(&groups, (w, h), &mut out);
            assert_eq!(out, want, "case {case}: first call");
            bufs.border_after(&groups, (w, h), &mut out);
            assert_eq!(out, want, "case {case}: second call");
        }
    }

    /// The chunked scan finds the same pixels as the rule at every pixel, on random label images of
    /// patches (so that chunks are skipped) with scattered noise and zeros.
    #[test]
    fn border_scan_matches_the_rule_at_every_pixel() {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(18);
        let mut cand = Vec::new();
        for case in 0..300 {
            let (w, h) = (rng.random_range(1..80usize), rng.random_range(1..40usize));
            let (bw, bh) = (rng.random_range(1..40usize), rng.random_range(1..20usize));
            let noise = [0.0, 0.002, 0.02, 0.2][case % 4];
            let groups: Vec<u32> = (0..w * h)
                .map(|i| {
                    let block = ((i % w) / bw + 3 * ((i / w) / bh)) as u32 % 4;
                    if rng.random_bool(noise) { rng.random_range(0..5) } else { block }
                })
                .collect();
            border_pixels_into(&groups, w, h, &mut cand);
            let want: Vec<u32> =
                (0..w * h).filter(|&i| is_border(&groups, w, h, i % w, i / w)).map(|i| i as u32).collect();
            assert_eq!(cand, want, "case {case} ({w}×{h})");
        }
    }
}
