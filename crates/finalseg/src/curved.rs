//! Step 8 of the final segmentation: adjacent regions that one gently curved surface explains are merged.
//!
//! A depth encoding that is not linear in depth (the 8-bit NYU frames) bends a flat wall, and region growing cuts a
//! bent wall into pieces a few degrees apart along folds that are not there. The plane tests of step 4 cannot join
//! them: the joint plane misses the bend by more than the pieces' noise. A quadratic surface does not: over two pieces
//! of one bent wall its residual is no larger than the pieces' own plane residuals, while over two faces that meet at
//! a crease, or two parallel faces at a step, it is larger (a quadric cannot follow a corner or a step). So two
//! adjacent regions whose normals are at most `max_angle_deg` apart merge when the least-squares quadric of their
//! union (height over the union's plane as a quadratic function of the two in-plane coordinates) has an RMS residual
//! of at most `ratio` times the two regions' plane RMS residuals pooled over their pixels (at least the noise floor),
//! and at most `max_rms`. A test relative to the noise cannot see steps under about twice the noise; they merge.

use crate::Scene;
use crate::merge::differing_pairs;
use crate::plane::{Plane, fit_plane};
use crate::refine::SIGMA_FLOOR;
use nalgebra::{Matrix6, Vector6};
use planefit::{Moments, dot};
use rangeimage::union_find::find;

/// Most points a quadric test sums (the union's pixels taken at a common stride beyond it): the residual of a
/// surface this smooth is measured as well on a few thousand points as on all of them.
const MAX_POINTS: usize = 4096;

/// The working memory of [`merge_curved`], kept from one frame to the next.
#[derive(Debug, Default)]
pub(crate) struct Buffers {
    /// Per label: its first pixel in `pixels`, and one past its last (`start[l]..start[l + 1]`).
    start: Vec<u32>,
    /// The labelled pixels, grouped by label in raster order within a label.
    pixels: Vec<u32>,
    /// Per label: the next label of its group (a cycle through the group's labels).
    next: Vec<u32>,
    /// Per label: the moments of its group's pixels (valid at roots).
    moments: Vec<Moments>,
    /// Per label: the sum of squared residuals of its group's labels, each about its own plane over its own pixels
    /// (valid at roots).
    sse: Vec<f64>,
    /// The candidate pairs of adjacent labels (smaller first), sorted.
    pairs: Vec<(u32, u32)>,
    /// Per pair: the sizes of the two groups when its test last failed.
    failed: Vec<(f64, f64)>,
    /// The 3D points of one test.
    points: Vec<[f64; 3]>,
}

/// Merges, in `parent` (the forest over the labels of `labels`, whose pixels carry their groups' roots), adjacent
/// groups whose union one quadric explains (module doc), passes over the sorted adjacent pairs until none merges;
/// `moments` and `planes` (per label at `l − 1`: the core moments and planes the output reports) are merged and
/// refitted as step 4 does; `all` (per label at `l − 1`) holds the moments of each label over all of its pixels less
/// the points of the pixels listed with their labels beside it (those the outlier step released since), which the
/// tests use. Candidates are the pairs whose reported planes are within the angle; a pair is tested again only
/// once a merge has changed one of its groups. Returns the number of merges.
pub(crate) fn merge_curved(
    scene: &Scene<'_>,
    labels: &[u32],
    parent: &mut [u32],
    (moments, planes): (&mut [Moments], &mut [Plane]),
    (all, released): (&[Moments], &[(u32, u32)]),
    (ratio, max_angle_deg, max_rms): (f64, f64, f64),
    (bufs, room): (&mut Buffers, usize),
) -> u32 {
    let n = parent.len();
    let w = scene.w;
    bufs.reserve(labels.len(), room);
    // The adjacent pairs whose reported planes (of their core pixels) are within the angle: the candidates.
    let mut last = (0, 0);
    differing_pairs(labels, w, scene.h, |i, j| {
        let (a, b) = (labels[i], labels[j]);
        // Runs along a border repeat one pair: pushed once per run.
        if a != 0 && b != 0 && (a.min(b), a.max(b)) != last {
            last = (a.min(b), a.max(b));
            if bufs.pairs.len() == bufs.pairs.capacity() {
                // Full: the distinct pairs make room before the list grows.
                bufs.pairs.sort_unstable();
                bufs.pairs.dedup();
            }
            bufs.pairs.push(last);
        }
    });
    bufs.pairs.sort_unstable();
    bufs.pairs.dedup();
    let cos_max = max_angle_deg.to_radians().cos();
    bufs.pairs
        .retain(|&(a, b)| dot(planes[a as usize - 1].normal, planes[b as usize - 1].normal).abs() >= cos_max);
    if bufs.pairs.is_empty() {
        return 0;
    }
    bufs.group(labels, n);
    // Each label's moments over all of its pixels now (not only its core pixels): the pixels the test sums.
    bufs.moments.push(Moments::default());
    bufs.moments.extend_from_slice(&all[..n - 1]);
    for &(i, l) in released {
        if let Some(p) = scene.point(i as usize % w, i as usize / w) {
            bufs.moments[l as usize].remove(p);
        }
    }
    bufs.sse.extend(
        bufs.moments
            .iter()
            .map(|m| if m.n >= 3.0 { fit_plane(m, scene.camera).rms.powi(2) * m.n } else { 0.0 }),
    );
    // Per pair: the sizes of the two groups when their test last failed (a test is repeated only once a merge has
    // changed one of them).
    bufs.failed.clear();
    bufs.failed.resize(bufs.pairs.len(), (-1.0, -1.0));
    let mut merges = 0;
    loop {
        let mut changed = false;
        for k in 0..bufs.pairs.len() {
            let (a, b) = bufs.pairs[k];
            let (ra, rb) = (find(parent, a), find(parent, b));
            if ra == rb {
                continue;
            }
            let (ma, mb) = (bufs.moments[ra as usize], bufs.moments[rb as usize]);
            if ma.n < 3.0 || mb.n < 3.0 || bufs.failed[k] == (ma.n, mb.n) {
                continue;
            }
            bufs.failed[k] = (ma.n, mb.n);
            let (pa, pb) = (fit_plane(&ma, scene.camera), fit_plane(&mb, scene.camera));
            if dot(pa.normal, pb.normal).abs() < cos_max {
                continue;
            }
            // The pieces' own residual, pooled over their pixels; a merged group's stays that of its pieces (the bend a
            // merge joined does not loosen the next test).
            let sse = bufs.sse[ra as usize] + bufs.sse[rb as usize];
            let own = (sse / (ma.n + mb.n)).sqrt().max(SIGMA_FLOOR);
            let union = ma.combined(&mb);
            let Some(q) = bufs.quadric_rms(scene, (ra, rb), &union) else { continue };
            tracing::trace!(a = ra, b = rb, quadric = q, own, "curved merge test");
            if q > ratio * own || q > max_rms {
                continue;
            }
            let (root, other) = (ra.min(rb), ra.max(rb));
            parent[other as usize] = root;
            bufs.moments[root as usize] = union;
            bufs.sse[root as usize] = sse;
            // The two groups' label cycles become one.
            bufs.next.swap(root as usize, other as usize);
            let core = moments[other as usize - 1];
            moments[root as usize - 1].merge(&core);
            planes[root as usize - 1] = fit_plane(&moments[root as usize - 1], scene.camera);
            merges += 1;
            changed = true;
        }
        if !changed {
            return merges;
        }
    }
}

impl Buffers {
    /// Reserves, once, room for a frame of `px` pixels and `labels` labels (untouched memory: later frames of the
    /// size allocate nothing); the adjacent pairs get one per 8 pixels, more than the runs along borders of a frame.
    fn reserve(&mut self, px: usize, labels: usize) {
        // Emptied first: `reserve` counts from the length.
        self.pixels.clear();
        self.pixels.reserve(px);
        self.pairs.clear();
        self.pairs.reserve(px / 8);
        self.failed.clear();
        self.failed.reserve(px / 8);
        self.points.clear();
        self.points.reserve(2 * MAX_POINTS + 2);
        for v in [&mut self.start, &mut self.next] {
            v.clear();
            v.reserve(labels + 2);
        }
        self.moments.clear();
        self.moments.reserve(labels + 2);
        self.sse.clear();
        self.sse.reserve(labels + 2);
    }

    /// Groups the pixels of `labels` by label (`n` labels, 0 included) and makes each label a group of its own.
    fn group(&mut self, labels: &[u32], n: usize) {
        self.start.clear();
        self.start.resize(n + 1, 0);
        for &l in labels {
            if l != 0 {
                self.start[l as usize + 1] += 1;
            }
        }
        for l in 1..=n {
            self.start[l] += self.start[l - 1];
        }
        let total = self.start[n] as usize;
        self.pixels.clear();
        self.pixels.resize(total, 0);
        // `next` serves as the fill cursor first.
        self.next.clear();
        self.next.extend_from_slice(&self.start[..n]);
        for (i, &l) in labels.iter().enumerate() {
            if l != 0 {
                let c = &mut self.next[l as usize];
                self.pixels[*c as usize] = i as u32;
                *c += 1;
            }
        }
        self.next.clear();
        self.next.extend(0..n as u32);
    }

    /// RMS residual of the least-squares quadric over the pixels of the groups of `ra` and `rb` (moments `union`),
    /// at most [`MAX_POINTS`] of them at a common stride; `None` if the fit is degenerate.
    fn quadric_rms(&mut self, scene: &Scene<'_>, (ra, rb): (u32, u32), union: &Moments) -> Option<f64> {
        let total = union.n as usize;
        let stride = total.div_ceil(MAX_POINTS).max(1);
        self.points.clear();
        for r in [ra, rb] {
            let mut l = r;
            loop {
                let (a, b) = (self.start[l as usize] as usize, self.start[l as usize + 1] as usize);
                for &i in self.pixels[a..b].iter().step_by(stride) {
                    if let Some(p) = scene.point(i as usize % scene.w, i as usize / scene.w) {
                        self.points.push(p);
                    }
                }
                l = self.next[l as usize];
                if l == r {
                    break;
                }
            }
        }
        if self.points.len() < 12 {
            return None;
        }
        let c = union.centroid();
        let axes = union.axes();
        let mut order = [0usize, 1, 2];
        order.sort_by(|&i, &j| axes.values[i].total_cmp(&axes.values[j]));
        let unit = |v: [f64; 3]| {
            let len = dot(v, v).sqrt();
            if len > 0.0 { v.map(|x| x / len) } else { v }
        };
        let (nrm, e1, e2) =
            (unit(axes.vectors[order[0]]), unit(axes.vectors[order[1]]), unit(axes.vectors[order[2]]));
        // In-plane coordinates in units of the union's spread along its major axis (a well-conditioned system).
        let scale = axes.values[order[2]].max(0.0).sqrt().max(1e-12);
        // The sums of the monomials of (u, v) up to degree 4, of h times those up to degree 2, and of h².
        let mut m = [0.0f64; 15];
        let (mut hm, mut bb) = ([0.0f64; 6], 0.0);
        for p in &self.points {
            let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
            let (hgt, u, v) = (dot(nrm, d), dot(e1, d) / scale, dot(e2, d) / scale);
            let (uu, uv, vv) = (u * u, u * v, v * v);
            let terms = [
                1.0,
                u,
                v,
                uu,
                uv,
                vv,
                uu * u,
                uu * v,
                u * vv,
                vv * v,
                uu * uu,
                uu * uv,
                uu * vv,
                uv * vv,
                vv * vv,
            ];
            for (s, t) in m.iter_mut().zip(terms) {
                *s += t;
            }
            for (s, t) in hm.iter_mut().zip(&terms[..6]) {
                *s += hgt * t;
            }
            bb += hgt * hgt;
        }
        // The normal equations of h ≈ a·[1, u, v, u², uv, v²]: entry (i, j) sums the product of terms i and j, whose
        // exponents add up (index into `m` by the exponents of u and v).
        const EXP: [(usize, usize); 6] = [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)];
        let index = |(a, b): (usize, usize)| {
            let deg = a + b;
            deg * (deg + 1) / 2 + b
        };
        let ata = Matrix6::from_fn(|i, j| m[index((EXP[i].0 + EXP[j].0, EXP[i].1 + EXP[j].1))]);
        let atb = Vector6::from_column_slice(&hm);
        let coef = ata.cholesky()?.solve(&atb);
        let sse = (bb - coef.dot(&atb)).max(0.0);
        Some((sse / self.points.len() as f64).sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rangeimage::Camera;

    /// Merges of the two halves (label 1 for x < 30, label 2 beyond) of a 60×40 grid-camera image of `depth`, with the
    /// quadric ratio `ratio` and the default's other limits (15°, RMS 3).
    fn merges_at(ratio: f64, depth: impl Fn(f64, f64) -> f64) -> u32 {
        let (w, h) = (60usize, 40usize);
        // A deterministic noise of about 0.15 units.
        let noise = |x: usize, y: usize| (((x * 7919 + y * 104_729) % 13) as f64 - 6.0) * 0.04;
        let range: Vec<f32> = (0..w * h)
            .map(|i| (depth((i % w) as f64, (i / w) as f64) + noise(i % w, i / w)) as f32)
            .collect();
        let labels: Vec<u32> = (0..w * h).map(|i| if i % w < 30 { 1 } else { 2 }).collect();
        let camera = Camera::Grid;
        let mut points = Vec::new();
        let scene = Scene::new(&range, (w, h), &camera, &mut points);
        let mut moments = vec![Moments::default(); 2];
        for (i, &l) in labels.iter().enumerate() {
            moments[l as usize - 1].add(scene.point(i % w, i / w).expect("finite"));
        }
        let mut planes: Vec<Plane> = moments.iter().map(|m| fit_plane(m, &camera)).collect();
        let mut parent = vec![0, 1, 2];
        // Every pixel is a core pixel here: the moments over all pixels are the core moments.
        let all = (moments.clone(), Vec::new());
        let n = merge_curved(
            &scene,
            &labels,
            &mut parent,
            (&mut moments, &mut planes),
            (&all.0, &all.1),
            (ratio, 15.0, 3.0),
            (&mut Buffers::default(), 16),
        );
        assert_eq!(n == 1, find(&mut parent, 2) == 1, "a merge joins the two labels");
        n
    }

    /// [`merges_at`] with the default ratio, 1.1.
    fn merges(depth: impl Fn(f64, f64) -> f64) -> u32 {
        merges_at(1.1, depth)
    }

    #[test]
    fn a_bent_surface_merges() {
        // Depth quadratic across the fold at x = 30: the halves' planes are about 8° apart and each misses the bend
        // by about as much as the noise; one quadric explains both.
        assert_eq!(merges(|x, y| 100.0 + 0.004 * (x - 30.0) * (x - 30.0) + 0.1 * y), 1);
    }

    #[test]
    fn a_crease_a_step_and_a_steep_bend_stay() {
        // Two planes 13.7° apart meeting at x = 30: a quadric rounds the corner by more than the noise.
        let crease = |x: f64, y: f64| 100.0 + 0.12 * (x - 30.0).abs() + 0.1 * y;
        assert_eq!(merges(crease), 0);
        assert_eq!(merges_at(3.0, crease), 1, "the quadric's residual decides, not the angle");
        // A step of 1.5 units between parallel planes (six times the noise floor of 0.25).
        assert_eq!(merges(|x, y| 100.0 + 0.05 * x + if x < 30.0 { 0.0 } else { 1.5 } + 0.1 * y), 0);
        // A bend of 30° is beyond the angle, however well a quadric fits it.
        assert_eq!(merges(|x, y| 100.0 + 0.009 * (x - 30.0) * (x - 30.0) * 2.0 + 0.1 * y), 0);
    }

    #[test]
    fn pixels_are_grouped_by_label_in_raster_order() {
        let mut b = Buffers::default();
        b.group(&[0, 2, 1, 2, 0, 1], 3);
        assert_eq!(b.start, vec![0, 0, 2, 4]);
        assert_eq!(b.pixels, vec![2, 5, 1, 3]);
        assert_eq!(b.next, vec![0, 1, 2]);
    }
}
