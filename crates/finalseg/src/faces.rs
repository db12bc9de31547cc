//! Step 9 of the final segmentation: small faces among the pixels no region holds.
//!
//! A face too small to be kept as a region (under `min_region_px`), or too thin for a window to fit inside it, ends
//! the earlier steps unlabelled: its pixels lie off every neighbour's plane, so the fill leaves them. When such a
//! group of unlabelled pixels lies on one plane of its own, that plane is not a neighbour's, and the group sits
//! between at least two regions, it is a face, and it becomes a region. The tests keep out what else is left
//! unlabelled: a terrace of a quantised slope (within a few noise scales of the slope's plane), the mixed pixels of a
//! jump (a "plane" seen almost edge-on), a dent or an object on one surface (enclosed by that surface alone), a line
//! of pixels (any plane through it fits).
//!
//! A face's pixels that the fill gave a neighbour before the face existed (they lay within the fill limit of the
//! neighbour's plane) come back to it: ring by ring out from the group, a pixel of a region beside it moves to the face
//! when the face's plane explains it within the noise and better than its own region's plane does.

use crate::Scene;
use crate::plane::{Plane, fit_plane, mean_sq_residual};
use crate::refine::SIGMA_FLOOR;
use planefit::{Moments, dot};
use rangeimage::union_find::find;

/// Fewest regions a face borders (4-adjacency): a group inside one region is a dent or an object on it.
const MIN_NEIGHBOURS: usize = 2;
/// Smallest share of a face's pixels within [`Limits::scales`] noise scales of its plane (the others are the
/// mixed pixels along its border, which the face keeps).
const MIN_INLIER_SHARE: f64 = 0.75;
/// Smallest share of a face's pixels whose four neighbours are in the face too: a line of pixels, or a scatter of
/// specks, has almost none.
const MIN_INTERIOR_SHARE: f64 = 0.5;

/// Most concentration steps of the trimmed fit (it stops earlier once the best-fitting pixels stay the same).
const MAX_TRIM_STEPS: usize = 10;

/// The mark, in the labels, of a pixel of a group already gathered (until its group becomes a face, or until the end).
const GATHERED: u32 = u32::MAX;

/// The working memory of [`recover`], kept from one frame to the next.
#[derive(Debug, Default)]
pub(crate) struct Buffers {
    /// The pixels of the groups that are no faces, which stay [`GATHERED`] until the end.
    left: Vec<u32>,
    /// The flood fill's stack, the group it gathers, and the group's pixels that fit its plane.
    stack: Vec<u32>,
    group: Vec<u32>,
    inliers: Vec<u32>,
    /// The trimmed fit's working memory: the group's pixels by their residuals, and the best-fitting ones.
    ranked: Vec<(f64, u32)>,
    trimmed: Vec<u32>,
    /// The group's interior pixels (their four neighbours in the group).
    core: Vec<u32>,
    /// The merged groups (roots) of the regions beside the group.
    beside: Vec<u32>,
    /// The faces made, in order: their label, noise scale and the end of their group's pixels in `face_px`.
    made: Vec<(u32, f64, usize)>,
    /// The pixels of the faces' groups, one face after the other.
    face_px: Vec<u32>,
}

/// The limits of [`recover`] (the `small_face_*` parameters and `min_region_px`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Limits {
    /// Smallest face, in pixels.
    pub(crate) min_px: usize,
    /// Every face is smaller than this (larger groups had their chance as components).
    pub(crate) max_px: usize,
    /// A pixel lies on the face's plane within this many noise scales; the noise scale is the largest RMS of the
    /// regions beside the group (at least [`SIGMA_FLOOR`]), and the face's own RMS must be within it.
    pub(crate) scales: f64,
    /// Smallest RMS distance of the face's points to each neighbour's plane, in noise scales.
    pub(crate) min_gap: f64,
    /// Largest angle, in degrees, between the face's normal and the line of sight at its centroid.
    pub(crate) max_slant_deg: f64,
    /// How many rings of pixels out from its group a face may take from the regions beside it (0: none).
    pub(crate) grow_px: usize,
    /// How much nearer to the face's plane than to its own region's plane a pixel it takes lies, in noise scales.
    pub(crate) grow_margin: f64,
}

/// Makes a new region of each 4-connected group of valid unlabelled pixels of `comp` that is a face by [`Limits`]
/// and the constants above. `comp` holds a label per pixel whose merged group's root in `parent` indexes `planes`
/// (at `root − 1`); `parent`, `moments`, `planes` and `guide` grow by one entry per face (its own root, the moments
/// and plane of the pixels that fit it, no region-growing label). Groups are found in raster order of their first
/// pixel and their sums taken in raster order, so the result does not depend on the flood fill's path. Then each face,
/// in the order made, takes back its pixels from the regions beside it ([`grow`]). Returns the number of faces made.
pub(crate) fn recover(
    scene: &Scene<'_>,
    comp: &mut [u32],
    (parent, moments, planes, guide): (&mut Vec<u32>, &mut Vec<Moments>, &mut Vec<Plane>, &mut Vec<u32>),
    limits: Limits,
    bufs: &mut Buffers,
) -> usize {
    let (w, h) = (scene.w, scene.h);
    let Buffers { left, stack, group, inliers, ranked, trimmed, core, beside, made: faces, face_px } = bufs;
    // Room for every pixel once, reserved once, so later frames reuse the memory; the trimmed fit sees only groups
    // under the size limit.
    for v in [&mut *left, &mut *stack, &mut *group, &mut *core, &mut *face_px] {
        v.clear();
        v.reserve(w * h);
    }
    for v in [&mut *inliers, &mut *trimmed] {
        v.clear();
        v.reserve(limits.max_px);
    }
    ranked.clear();
    ranked.reserve(limits.max_px);
    faces.clear();
    let valid = |j: usize| scene.range[j].is_finite();
    // Labels from here on are faces.
    let first_face = planes.len() as u32 + 1;
    for s in 0..w * h {
        if comp[s] != 0 || !valid(s) {
            continue;
        }
        // The group: unlabelled valid pixels, marked as they are reached.
        group.clear();
        beside.clear();
        stack.push(s as u32);
        comp[s] = GATHERED;
        core.clear();
        while let Some(i) = stack.pop() {
            group.push(i);
            let i = i as usize;
            let mut inside = 0;
            for (ok, j) in four_neighbours(i, (w, h)) {
                if !ok {
                    continue;
                }
                match comp[j] {
                    // Another group's pixels are never 4-adjacent to this one's.
                    GATHERED => inside += 1,
                    0 if valid(j) => {
                        inside += 1;
                        comp[j] = GATHERED;
                        stack.push(j as u32);
                    }
                    0 => {}
                    l => {
                        let r = find(parent, l);
                        if !beside.contains(&r) {
                            beside.push(r);
                        }
                    }
                }
            }
            if inside == 4 {
                core.push(i as u32);
            }
        }
        match face(scene, (group, core), beside, planes, limits, (inliers, ranked, trimmed)) {
            Some((plane, m, sigma)) => {
                planes.push(plane);
                moments.push(m);
                guide.push(0);
                let label = planes.len() as u32;
                parent.push(label);
                for &i in group.iter() {
                    comp[i as usize] = label;
                }
                face_px.extend_from_slice(group);
                faces.push((label, sigma, face_px.len()));
            }
            None => left.extend_from_slice(group),
        }
    }
    for &i in left.iter() {
        comp[i as usize] = 0;
    }
    if limits.grow_px > 0 {
        let taken = grow(
            scene,
            comp,
            (&mut parent[..], &planes[..], first_face),
            limits,
            (faces, face_px),
            (stack, group),
        );
        tracing::debug!(faces = faces.len(), taken, "small faces grown");
    }
    faces.len()
}

/// Grows each face of `faces` (label, noise scale σ, end of its group's pixels in `face_px`), in that order: ring
/// after ring, out to `limits.grow_px` rings from its group, a 4-neighbour of the face's last ring that a region holds
/// (a label below `first_face`, whose merged group's root in `parent` indexes `planes`) joins the face when the face's
/// plane lies within `limits.scales` σ of it and nearer than its own region's plane by `limits.grow_margin` σ. The test
/// reads those two planes alone, never the labels around the pixel, so a ring does not depend on the order its pixels
/// are visited in; no face takes from another. `ring` and `next` are working memory. Returns the pixels moved.
fn grow(
    scene: &Scene<'_>,
    comp: &mut [u32],
    (parent, planes, first_face): (&mut [u32], &[Plane], u32),
    limits: Limits,
    (faces, face_px): (&[(u32, f64, usize)], &[u32]),
    (ring, next): (&mut Vec<u32>, &mut Vec<u32>),
) -> usize {
    let (w, h) = (scene.w, scene.h);
    let mut taken = 0;
    let mut start = 0;
    for &(label, sigma, end) in faces {
        let plane = planes[label as usize - 1];
        let reach = limits.scales * sigma;
        let margin = limits.grow_margin * sigma;
        ring.clear();
        ring.extend_from_slice(&face_px[start..end]);
        start = end;
        for _ in 0..limits.grow_px {
            next.clear();
            for &i in ring.iter() {
                for (ok, j) in four_neighbours(i as usize, (w, h)) {
                    let l = if ok { comp[j] } else { 0 };
                    // Unlabelled, or a face's (this one's included).
                    if l == 0 || l >= first_face {
                        continue;
                    }
                    let own = find(parent, l);
                    if own >= first_face {
                        continue;
                    }
                    let p = scene.points[j];
                    let d = plane.residual(p);
                    if d <= reach && d + margin < planes[own as usize - 1].residual(p) {
                        comp[j] = label;
                        next.push(j as u32);
                    }
                }
            }
            if next.is_empty() {
                break;
            }
            taken += next.len();
            std::mem::swap(ring, next);
        }
    }
    taken
}

/// Whether the gathered `group` (`core`, its pixels with their four neighbours in it; `beside`, the roots of the
/// regions around it, whose planes are `planes[root − 1]`) is a face by `limits` and the constants above: its plane and
/// the moments of the pixels that fit it if so. Sorts `group` and `core` into raster order; the last argument is
/// working memory.
fn face(
    scene: &Scene<'_>,
    (group, core): (&mut [u32], &mut [u32]),
    beside: &[u32],
    planes: &[Plane],
    limits: Limits,
    (inliers, ranked, trimmed): (&mut Vec<u32>, &mut Vec<(f64, u32)>, &mut Vec<u32>),
) -> Option<(Plane, Moments, f64)> {
    let n = group.len();
    if n < limits.min_px
        || n >= limits.max_px
        || beside.len() < MIN_NEIGHBOURS
        || (core.len() as f64) < MIN_INTERIOR_SHARE * n as f64
    {
        return None;
    }
    // Raster order, so the sums do not depend on the flood fill's path.
    group.sort_unstable();
    let sigma = beside.iter().map(|&r| planes[r as usize - 1].rms).fold(SIGMA_FLOOR, f64::max);
    // The plane of the interior pixels to start from (the mixed pixels of a face lie along its border), then a trimmed
    // fit, so that the spikes inside it do not tilt its plane either: the concentration steps of least trimmed squares,
    // each refitting on the pixels (the share that must fit) nearest the last plane.
    core.sort_unstable();
    let mut m = moments_of(scene, core);
    let mut plane = fit_plane(&m, scene.camera);
    let keep = ((MIN_INLIER_SHARE * n as f64).ceil() as usize).clamp(1, n);
    inliers.clear();
    for _ in 0..MAX_TRIM_STEPS {
        ranked.clear();
        ranked.extend(group.iter().map(|&i| (plane.residual(scene.points[i as usize]), i)));
        ranked.select_nth_unstable_by(keep - 1, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        trimmed.clear();
        trimmed.extend(ranked[..keep].iter().map(|&(_, i)| i));
        // Raster order again, for the sums.
        trimmed.sort_unstable();
        if trimmed == inliers {
            break;
        }
        std::mem::swap(trimmed, inliers);
        m = moments_of(scene, inliers);
        plane = fit_plane(&m, scene.camera);
    }
    // Twice: keep the pixels within the limit of the plane, refit on them.
    for _ in 0..2 {
        inliers.clear();
        inliers.extend(
            group
                .iter()
                .copied()
                .filter(|&i| plane.residual(scene.points[i as usize]) <= limits.scales * sigma),
        );
        if (inliers.len() as f64) < MIN_INLIER_SHARE * n as f64 {
            break;
        }
        m = moments_of(scene, inliers);
        plane = fit_plane(&m, scene.camera);
    }
    if (inliers.len() as f64) < MIN_INLIER_SHARE * n as f64 || plane.rms > sigma {
        return None;
    }
    let seen_from = dot(plane.normal, scene.camera.toward_sensor(m.centroid())).abs();
    // The RMS distance of the face's points to the nearest neighbour's plane, in noise scales.
    let gap = beside
        .iter()
        .map(|&r| mean_sq_residual(&m, &planes[r as usize - 1]).sqrt() / sigma)
        .fold(f64::INFINITY, f64::min);
    let first = group[0] as usize;
    tracing::trace!(
        x = first % scene.w,
        y = first / scene.w,
        n,
        rms = plane.rms,
        sigma,
        gap,
        seen_from,
        "small face candidate"
    );
    (seen_from >= limits.max_slant_deg.to_radians().cos() && gap > limits.min_gap)
        .then_some((plane, m, sigma))
}

/// The 4-neighbours of pixel `i` of a `w × h` frame, left, right, up, down: whether each lies in the frame, and its index
/// (meaningless where it does not).
#[inline]
fn four_neighbours(i: usize, (w, h): (usize, usize)) -> [(bool, usize); 4] {
    let (x, y) = (i % w, i / w);
    [(x > 0, i.wrapping_sub(1)), (x + 1 < w, i + 1), (y > 0, i.wrapping_sub(w)), (y + 1 < h, i + w)]
}

/// The moments of the points of `pixels`, summed in their order.
fn moments_of(scene: &Scene<'_>, pixels: &[u32]) -> Moments {
    let mut m = Moments::default();
    for &i in pixels {
        m.add(scene.points[i as usize]);
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use rangeimage::Camera;

    /// The limits of the default configuration.
    const LIMITS: Limits = Limits {
        min_px: 40,
        max_px: 200,
        scales: 2.5,
        min_gap: 4.0,
        max_slant_deg: 80.0,
        grow_px: 0,
        grow_margin: 0.25,
    };

    /// The middle of [`recovered`]'s default image: columns 15–24 of 12 rows (120 px).
    const MIDDLE: (usize, std::ops::Range<usize>) = (12, 15..25);

    /// A 40 × `h` grid image with ±0.2 of checkerboard noise: the plane v = 100 left of the columns `cols` (label 1),
    /// `middle(x)` in them (unlabelled) and v = 122 right of them (label `right`). Returns the labels after [`recover`]
    /// with `limits`, the number of faces made and the new planes' count.
    fn recovered(
        (h, cols): (usize, std::ops::Range<usize>),
        middle: impl Fn(usize) -> f32,
        right: u32,
        limits: Limits,
    ) -> (Vec<u32>, usize, usize) {
        recovered_with((h, cols), &|x, _| middle(x), right, limits)
    }

    /// [`recovered`] with the middle's depth a function of the column and the row.
    fn recovered_with(
        (h, cols): (usize, std::ops::Range<usize>),
        middle: &dyn Fn(usize, usize) -> f32,
        right: u32,
        limits: Limits,
    ) -> (Vec<u32>, usize, usize) {
        let w = 40usize;
        let range: Vec<f32> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let noise = if (x + y) % 2 == 0 { 0.2 } else { -0.2 };
                noise
                    + if x < cols.start {
                        100.0
                    } else if cols.contains(&x) {
                        middle(x, y)
                    } else {
                        122.0
                    }
            })
            .collect();
        let camera = Camera::Grid;
        let mut points = Vec::new();
        let scene = Scene::new(&range, (w, h), &camera, &mut points);
        let mut comp: Vec<u32> = (0..w * h)
            .map(|i| {
                let x = i % w;
                if x < cols.start {
                    1
                } else if cols.contains(&x) {
                    0
                } else {
                    right
                }
            })
            .collect();
        let mut moments = vec![Moments::default(); 2];
        for (i, &l) in comp.iter().enumerate() {
            if l != 0 {
                moments[l as usize - 1].add(scene.point(i % w, i / w).unwrap());
            }
        }
        let mut planes: Vec<Plane> = moments.iter().map(|m| fit_plane(m, &camera)).collect();
        let (mut parent, mut guide) = (vec![0, 1, 2], vec![0, 0]);
        let grow = (&mut parent, &mut moments, &mut planes, &mut guide);
        let n = recover(&scene, &mut comp, grow, limits, &mut Buffers::default());
        // Every new region is its own root, with its moments, plane and an empty guide label.
        assert_eq!((parent.len(), moments.len(), guide.len()), (3 + n, 2 + n, 2 + n));
        assert!(parent[3..].iter().enumerate().all(|(k, &p)| p == k as u32 + 3));
        (comp, n, planes.len())
    }

    /// A named case of [`recovered`]: the middle's depth, the right region's label and the limits.
    type Case<'a> = (&'a str, &'a dyn Fn(usize) -> f32, u32, Limits);

    /// The labels of the columns `cols`.
    fn middle_labels(comp: &[u32], cols: std::ops::Range<usize>) -> Vec<u32> {
        comp.chunks_exact(40).flat_map(|row| row[cols.clone()].to_vec()).collect()
    }

    #[test]
    fn a_face_between_two_regions_becomes_a_region() {
        // A slope of 2 per pixel (about 63° from the line of sight) between two flat regions.
        let (comp, n, planes) = recovered(MIDDLE, |x| 100.0 + 2.0 * (x as f32 - 14.0), 2, LIMITS);
        assert_eq!((n, planes), (1, 3));
        assert!(middle_labels(&comp, MIDDLE.1).iter().all(|&l| l == 3));
        // The regions beside it keep their pixels.
        assert!(
            comp.chunks_exact(40)
                .all(|row| row[..15].iter().all(|&l| l == 1) && row[25..].iter().all(|&l| l == 2))
        );
    }

    #[test]
    fn spikes_do_not_tilt_a_face() {
        // Every fifth pixel of the face's columns is a spike 15 above the slope (20 % of its pixels, as the scanner's
        // spikes and mixed pixels on a small real face). A plain least-squares plane lies 3 above the slope and fits no
        // pixel within 2.5 noise scales; the trimmed fit finds the slope, which 80 % of the pixels fit.
        let spiked = |x: usize, y: usize| {
            let slope = 100.0 + 2.0 * (x as f32 - 14.0);
            if (y * 10 + x).is_multiple_of(5) { slope + 15.0 } else { slope }
        };
        let (comp, n, planes) = recovered_with(MIDDLE, &spiked, 2, LIMITS);
        assert_eq!((n, planes), (1, 3));
        // The face keeps its spikes too.
        assert!(middle_labels(&comp, MIDDLE.1).iter().all(|&l| l == 3));
    }

    #[test]
    fn what_is_not_a_face_stays_unlabelled() {
        let slope = |x: usize| 100.0 + 2.0 * (x as f32 - 14.0);
        let cases: [Case<'_>; 6] = [
            // Within 0.6 of the left plane (2.4 noise scales): a terrace of that surface.
            ("terrace", &|_| 100.6, 2, LIMITS),
            // A slope of 10 per pixel: seen within 6° of edge-on, the ramp of a jump.
            ("edge-on", &|x| 100.0 + 10.0 * (x as f32 - 14.0), 2, LIMITS),
            // Enclosed by one region (label 1 on both sides).
            ("enclosed", &slope, 1, LIMITS),
            // 120 px is not under a min_region_px of 100: such a group had its chance as a component.
            ("large", &slope, 2, Limits { max_px: 100, ..LIMITS }),
            ("small", &slope, 2, Limits { min_px: 121, ..LIMITS }),
            // A rough surface: ±3 of noise on the slope is beyond one noise scale of RMS.
            ("rough", &|x| slope(x) + if x % 2 == 0 { 3.0 } else { -3.0 }, 2, LIMITS),
        ];
        for (name, middle, right, limits) in cases {
            let (comp, n, planes) = recovered(MIDDLE, middle, right, limits);
            assert_eq!((n, planes), (0, 2), "{name}");
            assert!(middle_labels(&comp, MIDDLE.1).iter().all(|&l| l == 0), "{name}");
        }
    }

    #[test]
    fn a_strip_without_interior_stays_unlabelled() {
        // The same slope 2 px wide and 40 rows tall (80 px): no pixel has its four neighbours in the group, and a
        // plane through so thin a strip means little. 6 px wide, half of its pixels are interior, and it is a face.
        let slope = |x: usize| 100.0 + 2.0 * (x as f32 - 14.0);
        let (comp, n, _) = recovered((40, 19..21), slope, 2, LIMITS);
        assert_eq!(n, 0);
        assert!(middle_labels(&comp, 19..21).iter().all(|&l| l == 0));
        let (comp, n, _) = recovered((30, 17..23), slope, 2, LIMITS);
        assert_eq!(n, 1);
        assert!(middle_labels(&comp, 17..23).iter().all(|&l| l == 3));
    }

    /// A 40 × 12 grid image with ±0.2 of checkerboard noise: v = 98 left of column 15 (label 1), a face sloping by 2 per
    /// pixel over columns 15–27 (v = 102 … 126) and v = 130 from column 28 on (label 2): steps of 4 on both sides of
    /// the face. Columns 15–24 are unlabelled; 25–27, the rest of the face, are label 2's, as the fill leaves a
    /// face's pixels within its limit of a neighbour's plane. The planes are those of the regions' pixels off the
    /// face. Returns the labels of one row after [`recover`] with `limits`, and the faces made.
    fn grown(limits: Limits) -> (Vec<u32>, usize) {
        let (w, h) = (40usize, 12usize);
        let depth = |x: usize| match x {
            0..15 => 98.0,
            15..28 => 100.0 + 2.0 * (x as f32 - 14.0),
            _ => 130.0,
        };
        let range: Vec<f32> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                depth(x) + if (x + y) % 2 == 0 { 0.2 } else { -0.2 }
            })
            .collect();
        let camera = Camera::Grid;
        let mut points = Vec::new();
        let scene = Scene::new(&range, (w, h), &camera, &mut points);
        let label = |x: usize| match x {
            0..15 => 1,
            15..25 => 0,
            _ => 2,
        };
        let mut comp: Vec<u32> = (0..w * h).map(|i| label(i % w)).collect();
        let mut moments = vec![Moments::default(); 2];
        for i in 0..w * h {
            let x = i % w;
            if !(15..28).contains(&x) {
                moments[label(x) as usize - 1].add(scene.point(x, i / w).unwrap());
            }
        }
        let mut planes: Vec<Plane> = moments.iter().map(|m| fit_plane(m, &camera)).collect();
        let (mut parent, mut guide) = (vec![0, 1, 2], vec![0, 0]);
        let grow = (&mut parent, &mut moments, &mut planes, &mut guide);
        let n = recover(&scene, &mut comp, grow, limits, &mut Buffers::default());
        // Every row alike.
        assert!(comp.chunks_exact(w).all(|row| row == &comp[..w]));
        (comp[..w].to_vec(), n)
    }

    #[test]
    fn a_face_takes_back_what_a_neighbour_held_of_it() {
        let row = |face_to: usize| -> Vec<u32> {
            (0..40)
                .map(|x| {
                    if x < 15 {
                        1
                    } else if x < face_to {
                        3
                    } else {
                        2
                    }
                })
                .collect()
        };
        // Without growth the face keeps its group, columns 15–24.
        assert_eq!(grown(LIMITS), (row(25), 1));
        // Growing, it takes columns 25–27 (its plane fits them; the neighbour's lies 4–8 off) and stops at the steps:
        // columns 14 and 28 lie 0.9 off the face's plane, beyond 2.5 noise scales (0.25, the floor).
        assert_eq!(grown(Limits { grow_px: 8, ..LIMITS }), (row(28), 1));
        // Two rings take two columns.
        assert_eq!(grown(Limits { grow_px: 2, ..LIMITS }), (row(27), 1));
        // A pixel its own plane explains as well as the face's stays: with a margin of 40 noise scales (10 units) none
        // moves.
        assert_eq!(grown(Limits { grow_px: 8, grow_margin: 40.0, ..LIMITS }), (row(25), 1));
    }
}
