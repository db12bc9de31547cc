//! Step 5b of the final segmentation: bands that a region holds of its neighbour's plane, given back whole.
//!
//! A region whose growth leaked past a shallow crease holds a band of its neighbour's face: pixels a few tenths
//! of a unit nearer the neighbour's plane than their own. Step 5 decides pixel by pixel, and there a small gap of
//! distances loses to the Potts cost of the border; step 6 places only the pixels beside creases it recognises by
//! the regions' centroids, which a large region wrapping around the other's plane defeats. Over a band of
//! hundreds of pixels the two planes' fits decide clearly: a 4-connected part of a region, beside an adjacent
//! region whose normal is at most `band_max_angle_deg` from its own, whose pixels all lie nearer that region's
//! plane than their own and within its noise, moves to that region when its mean gain is at least
//! [`MIN_GAIN`] squared noise scales, its removal does not worsen the giving region's fit, the taking region's fit
//! stays within [`MAX_GROWTH`], and it is at most [`MAX_SHARE`] of the taking region (whose plane must be its own
//! pixels', not the band's).

use crate::Scene;
use crate::fill::for_neighbours;
use crate::plane::{Plane, fit_plane};
use crate::refine::{SIGMA_FLOOR, border_pixels_into};
use planefit::{Moments, dot};

/// A band pixel lies within this many noise scales of the taking region's plane (the noise scale: the larger RMS of
/// the two planes, at least [`SIGMA_FLOOR`]).
const GATE: f64 = 2.0;
/// Smallest band, in pixels (smaller parts of a region beside a crease are the noise of both planes).
const MIN_PX: usize = 50;
/// Smallest mean over the band of (own distance² − neighbour distance²), in squared noise scales.
const MIN_GAIN: f64 = 1.0;
/// The taking region's RMS about the plane refitted with the band at most this times its RMS (at least
/// [`SIGMA_FLOOR`]).
const MAX_GROWTH: f64 = 1.05;
/// Largest band as a fraction of the taking region's pixels: on the NYU frames a large region bent by the depth
/// encoding otherwise gave a small neighbour a band eight times its size.
const MAX_SHARE: f64 = 0.5;

/// The working memory of [`give_back`], kept from one frame to the next.
#[derive(Debug, Default)]
pub(crate) struct Buffers {
    /// Border pixels in raster order.
    border: Vec<u32>,
    /// Per pixel: already in a band (all false between calls).
    taken: Vec<bool>,
    /// The pixels of every band, band after band, and the flood's stack (each pixel with its [`in_band`] answer).
    members: Vec<u32>,
    stack: Vec<(u32, Distances)>,
    /// Per band: its members' range in `members`, and the label it moves to (0 = it stays).
    bands: Vec<(u32, u32, u32)>,
}

impl Buffers {
    /// The border list [`give_back`] examines when told its border is given.
    pub(crate) fn border_mut(&mut self) -> &mut Vec<u32> {
        &mut self.border
    }
}

/// A band found by [`flood`]: the labels of the giving and taking regions, its pixel count, the moments of its
/// points and its summed gain.
struct Band {
    from: u32,
    to: u32,
    n: usize,
    moments: Moments,
    gain: f64,
}

/// Moves bands of `groups` (a label per pixel, 0 = none; `planes[l − 1]` the plane of label `l`, fitted to the
/// points `moments[l − 1]` sums) to the adjacent region whose plane they lie on (see the module), for pairs of
/// regions whose normals are at most `max_angle_deg` apart. Bands are found from the labels given, in raster order
/// of their first border pixel, and moved together. Returns the number of pixels moved.
///
/// With `border_given`, the border pixels are those of [`Buffers::border_mut`] (the border pixels of `groups` in
/// raster order, as `refine::border_pixels_into` finds them); otherwise it scans for them.
pub(crate) fn give_back(
    scene: &Scene<'_>,
    groups: &mut [u32],
    (planes, moments): (&[Plane], &[Moments]),
    max_angle_deg: f64,
    border_given: bool,
    bufs: &mut Buffers,
) -> u32 {
    let (w, h) = (scene.w, scene.h);
    bufs.taken.resize(w * h, false);
    bufs.bands.clear();
    // Each list holds a pixel (or a band of at least one pixel) at most once: room reserved once, so later frames
    // reuse the memory (a given border list comes with that room).
    bufs.members.clear();
    bufs.members.reserve(w * h);
    bufs.stack.clear();
    bufs.stack.reserve(w * h);
    bufs.bands.reserve(w * h);
    if !border_given {
        bufs.border.clear();
        bufs.border.reserve(w * h);
        border_pixels_into(groups, w, h, &mut bufs.border);
    }
    let cos_min = max_angle_deg.to_radians().cos();
    for k in 0..bufs.border.len() {
        let i = bufs.border[k] as usize;
        let a = groups[i];
        if bufs.taken[i] || a == 0 {
            continue;
        }
        // The first neighbouring label (in neighbour order) whose band this pixel starts, and the pixel's distances
        // to the two planes (a label tested just before, and refused, is not tested again: the same answer).
        let (mut b, mut tried, mut first) = (0u32, 0u32, None);
        for_neighbours(i % w, i / w, w, h, |j, _, _| {
            let l = groups[j];
            if b == 0 && l != 0 && l != a && l != tried {
                first = in_band(scene, planes, i, (a, l));
                if first.is_some() {
                    b = l;
                }
                tried = l;
            }
        });
        let Some(first) = first.filter(|_| b != 0) else { continue };
        let start = bufs.members.len() as u32;
        let band = flood(scene, groups, planes, (i, a, b, first), bufs);
        let shallow = dot(planes[a as usize - 1].normal, planes[b as usize - 1].normal).abs() >= cos_min;
        let to = if shallow && accepts(&band, planes, moments, scene) { b } else { 0 };
        bufs.bands.push((start, bufs.members.len() as u32, to));
    }
    let mut moved = 0u32;
    let Buffers { taken, members, bands, .. } = bufs;
    for &(s, e, to) in bands.iter() {
        for &k in &members[s as usize..e as usize] {
            taken[k as usize] = false;
            if to != 0 {
                groups[k as usize] = to;
            }
        }
        if to != 0 {
            moved += e - s;
        }
    }
    tracing::debug!(moved, "bands given back");
    moved
}

/// A band pixel's squared distances to the giving and taking regions' planes in noise scales, and its 3D point.
type Distances = (f64, f64, [f64; 3]);

/// Whether pixel `i` of region `a` lies on a band of region `b`'s plane: valid, nearer `b`'s plane than `a`'s and
/// within [`GATE`] noise scales of it. Returns its squared distances to the two planes in noise scales and its 3D
/// point.
fn in_band(scene: &Scene<'_>, planes: &[Plane], i: usize, (a, b): (u32, u32)) -> Option<Distances> {
    let p = scene.point(i % scene.w, i / scene.w)?;
    let (pa, pb) = (&planes[a as usize - 1], &planes[b as usize - 1]);
    let sigma = pa.rms.max(pb.rms).max(SIGMA_FLOOR);
    let (da, db) = (pa.residual(p) / sigma, pb.residual(p) / sigma);
    (db < da && db <= GATE).then_some((da * da, db * db, p))
}

/// The 4-connected band of region `a` on region `b`'s plane that pixel `i` (in it, with [`in_band`]'s answer
/// `first`) starts: its pixels appended to `bufs.members` and marked in `bufs.taken`. A pixel is tested once, when
/// it is pushed, and its answer kept with it on the stack.
fn flood(
    scene: &Scene<'_>,
    groups: &[u32],
    planes: &[Plane],
    (i, a, b, first): (usize, u32, u32, Distances),
    bufs: &mut Buffers,
) -> Band {
    let (w, h) = (scene.w, scene.h);
    let Buffers { taken, members, stack, .. } = bufs;
    let mut band = Band { from: a, to: b, n: 0, moments: Moments::default(), gain: 0.0 };
    taken[i] = true;
    stack.clear();
    stack.push((i as u32, first));
    while let Some((k, (sa, sb, p))) = stack.pop() {
        members.push(k);
        band.gain += sa - sb;
        band.n += 1;
        band.moments.add(p);
        let k = k as usize;
        let (x, y) = (k % w, k / w);
        let mut visit = |j: usize| {
            if !taken[j]
                && groups[j] == a
                && let Some(d) = in_band(scene, planes, j, (a, b))
            {
                taken[j] = true;
                stack.push((j as u32, d));
            }
        };
        // The 4-neighbours in the order of `for_neighbours`: up, left, right, down.
        if y > 0 {
            visit(k - w);
        }
        if x > 0 {
            visit(k - 1);
        }
        if x + 1 < w {
            visit(k + 1);
        }
        if y + 1 < h {
            visit(k + w);
        }
    }
    band
}

/// Whether `band` moves: large enough, a clear mean gain, the giving region's fit no worse without it, the taking
/// region's fit about as good with it, and at most [`MAX_SHARE`] of the taking region.
fn accepts(band: &Band, planes: &[Plane], moments: &[Moments], scene: &Scene<'_>) -> bool {
    let (a, b) = (band.from as usize - 1, band.to as usize - 1);
    if band.n < MIN_PX || band.gain < MIN_GAIN * band.n as f64 || band.moments.n > MAX_SHARE * moments[b].n {
        return false;
    }
    let m = &band.moments;
    let without = Moments { n: -m.n, s: m.s.map(|v| -v), ss: m.ss.map(|v| -v) };
    let rest = fit_plane(&moments[a].combined(&without), scene.camera).rms;
    let taker = fit_plane(&moments[b].combined(m), scene.camera).rms;
    rest <= planes[a].rms && taker <= MAX_GROWTH * planes[b].rms.max(SIGMA_FLOOR)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rangeimage::Camera;

    /// 80×20 grid image of a flat face (`v = 100`, x ≤ 39) and a face sloping away at 0.5 per pixel (27°, x ≥ 40),
    /// with a little deterministic noise; the sloping face's region also holds columns `first..40` of the flat face
    /// (a band leaked past the shallow crease). Planes and moments fitted to the labels, as the pipeline does.
    /// Returns the labels after [`give_back`] with `max_angle_deg`.
    fn leaked_band(first: usize, max_angle_deg: f64) -> Vec<u32> {
        let (w, h) = (80usize, 20usize);
        let range: Vec<f32> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let noise = 0.1 * (((x * 7 + y * 13) % 5) as f32 - 2.0);
                100.0 + noise + if x >= 40 { 0.5 * (x as f32 - 39.5) } else { 0.0 }
            })
            .collect();
        let camera = Camera::Grid;
        let mut points = Vec::new();
        let scene = Scene::new(&range, (w, h), &camera, &mut points);
        let mut groups: Vec<u32> = (0..w * h).map(|i| if i % w < first { 1 } else { 2 }).collect();
        let mut moments = [Moments::default(); 2];
        for (i, &l) in groups.iter().enumerate() {
            moments[l as usize - 1].add(scene.point(i % w, i / w).unwrap());
        }
        let planes = moments.map(|m| fit_plane(&m, &camera));
        give_back(&scene, &mut groups, (&planes, &moments), max_angle_deg, false, &mut Buffers::default());
        groups
    }

    /// The band as the flood found it before it kept each pixel's answer on the stack: every pixel tested again when
    /// popped, its 4-neighbours taken from the 8 of `for_neighbours`.
    fn flood_testing_twice(
        scene: &Scene<'_>,
        groups: &[u32],
        planes: &[Plane],
        (i, a, b): (usize, u32, u32),
        taken: &mut [bool],
        members: &mut Vec<u32>,
    ) -> Band {
        let (w, h) = (scene.w, scene.h);
        let mut band = Band { from: a, to: b, n: 0, moments: Moments::default(), gain: 0.0 };
        taken[i] = true;
        let mut stack = vec![i as u32];
        while let Some(k) = stack.pop() {
            let k = k as usize;
            members.push(k as u32);
            if let Some((sa, sb, p)) = in_band(scene, planes, k, (a, b)) {
                band.gain += sa - sb;
                band.n += 1;
                band.moments.add(p);
            }
            for_neighbours(k % w, k / w, w, h, |j, x, y| {
                let four = x == k % w || y == k / w;
                if four && !taken[j] && groups[j] == a && in_band(scene, planes, j, (a, b)).is_some() {
                    taken[j] = true;
                    stack.push(j as u32);
                }
            });
        }
        band
    }

    /// The flood gives the same members in the same order and the same sums, bit for bit, as testing every pixel
    /// again when popped, on random noisy two-plane scenes with holes and random labels.
    #[test]
    fn flood_matches_testing_each_pixel_twice() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(57);
        let camera = Camera::Grid;
        let mut larger = 0;
        for case in 0..60 {
            let (w, h) = (rng.random_range(2..40usize), rng.random_range(2..30usize));
            let split = rng.random_range(0..w);
            let slope = rng.random_range(0.1..1.0f32);
            let range: Vec<f32> = (0..w * h)
                .map(|i| {
                    let x = i % w;
                    let v = 100.0
                        + rng.random_range(-0.3..0.3f32)
                        + if x >= split { slope * x as f32 } else { 0.0 };
                    if rng.random_bool(0.03) { f32::NAN } else { v }
                })
                .collect();
            let mut points = Vec::new();
            let scene = Scene::new(&range, (w, h), &camera, &mut points);
            let groups: Vec<u32> = (0..w * h)
                .map(|i| {
                    if rng.random_bool(0.1) {
                        rng.random_range(1..3)
                    } else if i % w < split / 2 + 1 {
                        1
                    } else {
                        2
                    }
                })
                .collect();
            let mut moments = [Moments::default(); 2];
            for (i, &l) in groups.iter().enumerate() {
                if let Some(p) = scene.point(i % w, i / w) {
                    moments[l as usize - 1].add(p);
                }
            }
            let planes = moments.map(|m| fit_plane(&m, &camera));
            for (a, b) in [(1, 2), (2, 1)] {
                for i in 0..w * h {
                    let Some(first) = in_band(&scene, &planes, i, (a, b)).filter(|_| groups[i] == a) else {
                        continue;
                    };
                    let mut bufs = Buffers { taken: vec![false; w * h], ..Buffers::default() };
                    let band = flood(&scene, &groups, &planes, (i, a, b, first), &mut bufs);
                    let (mut taken, mut members) = (vec![false; w * h], Vec::new());
                    let want =
                        flood_testing_twice(&scene, &groups, &planes, (i, a, b), &mut taken, &mut members);
                    assert_eq!(bufs.members, members, "case {case}, pixel {i}");
                    assert_eq!((band.n, band.gain.to_bits()), (want.n, want.gain.to_bits()), "case {case}");
                    assert_eq!(band.moments, want.moments, "case {case}");
                    larger += usize::from(band.n > 5);
                }
            }
        }
        assert!(larger > 100, "only {larger} floods of more than 5 pixels");
    }

    #[test]
    fn a_band_on_the_neighbours_plane_goes_back_whole() {
        // The band (8 columns, 160 px) moves, but for pixels where the leaking region's tilted plane crosses it
        // (the refinement after this step takes those) and those beside the crease that lie within the noise of
        // both planes (step 6 places them); the sloping face stays.
        let groups = leaked_band(32, 45.0);
        for y in 0..20 {
            for x in (0..36).chain(42..80) {
                let want = if x < 40 { 1 } else { 2 };
                assert_eq!(groups[y * 80 + x], want, "({x}, {y})");
            }
        }
        let band = (0..20).flat_map(|y| (32..40).map(move |x| y * 80 + x));
        assert!(band.filter(|&i| groups[i] == 1).count() >= 140, "most of the band moves");
        // Off, or the planes more than 20° apart allowed only: nothing moves.
        for max_angle in [0.0, 20.0] {
            let groups = leaked_band(32, max_angle);
            assert!(
                groups.iter().enumerate().all(|(i, &l)| l == if i % 80 < 32 { 1 } else { 2 }),
                "{max_angle}°"
            );
        }
        // A band larger than half the flat face's region stays: that plane is the band's as much as its own.
        let groups = leaked_band(12, 45.0);
        assert!(groups.iter().enumerate().all(|(i, &l)| l == if i % 80 < 12 { 1 } else { 2 }));
    }
}
