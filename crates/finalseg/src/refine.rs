//! Step 5 of the final segmentation: border pixels moved to the adjacent region whose plane fits
//! them better, so that a border lies where the two planes meet rather than where growth stopped.

use crate::Scene;
use crate::fill::{Limit, for_neighbours};
use crate::plane::{Plane, fit_plane};
use planefit::Moments;

/// Moves border pixels of `groups` (a label per pixel, 0 = none; `planes[l − 1]` is the plane of
/// label `l`) to the 8-adjacent region whose plane is nearest their 3D point, when it is nearer
/// than their own plane and within `limit` of it. At most `passes` passes: each is decided from
/// the labels of the previous one only (ties keep the pixel where it is, then go to the smaller
/// label), so the order of pixels does not matter; a border moves at most one pixel per pass.
/// Returns the number of moves.
pub(crate) fn refine(
    scene: &Scene<'_>,
    groups: &mut [u32],
    planes: &[Option<Plane>],
    limit: Limit,
    passes: u32,
) -> u32 {
    let (w, h) = (scene.w, scene.h);
    // Candidates of the first pass: every labelled pixel with a differently labelled 8-neighbour.
    let mut cand: Vec<u32> = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let l = groups[y * w + x];
            if l == 0 {
                continue;
            }
            let mut border = false;
            for_neighbours(x, y, w, h, |j, _, _| border |= groups[j] != 0 && groups[j] != l);
            if border {
                cand.push((y * w + x) as u32);
            }
        }
    }
    let mut moves: Vec<(u32, u32)> = Vec::new();
    let mut seen = vec![false; w * h];
    let mut total = 0u32;
    for _ in 0..passes {
        moves.clear();
        moves.extend(
            cand.iter()
                .filter_map(|&i| better_label(scene, groups, planes, i as usize, limit).map(|l| (i, l))),
        );
        if moves.is_empty() {
            break;
        }
        for &(i, l) in &moves {
            groups[i as usize] = l;
        }
        total += moves.len() as u32;
        // Next candidates: the moved pixels' labelled neighbours (their best plane may have come
        // next to them), each once, in raster order.
        cand.clear();
        for &(i, _) in &moves {
            let i = i as usize;
            for_neighbours(i % w, i / w, w, h, |j, _, _| {
                if groups[j] != 0 && !seen[j] {
                    seen[j] = true;
                    cand.push(j as u32);
                }
            });
        }
        cand.sort_unstable();
        for &j in &cand {
            seen[j as usize] = false;
        }
    }
    tracing::debug!(moves = total, "refined borders");
    total
}

/// Planes fitted to every valid pixel of each label of `groups` (`n` labels; `None` for labels
/// without pixels), moments summed in raster order.
pub(crate) fn refit(scene: &Scene<'_>, groups: &[u32], n: usize) -> Vec<Option<Plane>> {
    let mut moments = vec![Moments::default(); n];
    for (i, &l) in groups.iter().enumerate() {
        if l != 0
            && let Some(p) = scene.point(i % scene.w, i / scene.w)
        {
            moments[l as usize - 1].add(p);
        }
    }
    moments.iter().map(|m| (m.n > 0.0).then(|| fit_plane(m, scene.camera))).collect()
}

/// The label pixel `i` should move to, if an 8-adjacent region fits it better than its own (and
/// within `limit`). "Fits" is a Potts energy: the squared distance to the region's plane in units
/// of the noise (the largest RMS of the candidate planes, at least `SIGMA_FLOOR`), plus `BETA` per
/// 8-neighbour of another label, so that noise near a shallow crease does not fray the border.
fn better_label(
    scene: &Scene<'_>,
    groups: &[u32],
    planes: &[Option<Plane>],
    i: usize,
    limit: Limit,
) -> Option<u32> {
    let (w, h) = (scene.w, scene.h);
    let own = groups[i];
    let p = scene.point(i % w, i / w)?;
    let plane_of = |l: u32| planes[l as usize - 1].as_ref().expect("labelled pixels belong to kept regions");
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
    let sigma = labs[..n].iter().map(|e| plane_of(e.0).rms).fold(SIGMA_FLOOR, f64::max);
    // A pixel its own plane explains within the noise stays.
    if plane_of(own).residual(p) <= OUTLIER * sigma {
        return None;
    }
    let energy = |(l, k): (u32, u32)| {
        let r = plane_of(l).residual(p) / sigma;
        r * r + BETA * f64::from(8 - k)
    };
    let mut best = (energy(labs[0]), own);
    for &e in &labs[1..n] {
        let en = energy(e);
        if en < best.0 || (en == best.0 && best.1 != own && e.0 < best.1) {
            best = (en, e.0);
        }
    }
    let l = best.1;
    (l != own && !limit.refuses(plane_of(l).residual(p), plane_of(l))).then_some(l)
}

/// Weight of one disagreeing neighbour in the refinement energy.
const BETA: f64 = 0.5;
/// A pixel moves only if it lies farther than this many noise scales from its own plane.
const OUTLIER: f64 = 2.5;
/// Smallest noise scale of the refinement energy, in sensor units.
const SIGMA_FLOOR: f64 = 0.5;
