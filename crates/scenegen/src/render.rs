//! Ray casting through the ABW camera, projector shadows, sensor artefacts and ground truth.

use crate::layout::Layout;
use crate::math::{V3, add, angle_deg, cross, dot, norm, normalize, scale, sub};
use crate::{Params, Scene};
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use rangeimage::{Grid, LabelImage};
use std::collections::BTreeSet;

const NO_FACE: u32 = u32::MAX;

/// The USF camera as a pinhole: centre `(0, 0, z0)`, looking along −Z; a pixel's point at depth
/// `d` (distance along the optical axis) is `(a·d, b·d, z0 − d)` and its range value is
/// `v = scal · (d − offset)`.
struct Cam {
    scal: f64,
    offset: f64,
    z0: f64,
    f: f64,
    c: f64,
    cx: f64,
    cy: f64,
}

impl Cam {
    fn dir(&self, col: f64, row: f64) -> V3 {
        [(col - self.cx) / self.f, (self.cy - row) / (self.c * self.f), -1.0]
    }

    /// Pixel coordinates of a 3D point in front of the camera.
    fn project(&self, p: V3) -> (f64, f64) {
        let d = self.z0 - p[2];
        (self.cx + p[0] / d * self.f, self.cy - p[1] / d * self.c * self.f)
    }
}

/// A convex piece in the camera frame: planes `n·p + e ≤ 0` inside, `n` outward and unit.
struct Solid {
    planes: Vec<(V3, f64, u32)>,
    /// Pixel bounding box `[x0, x1, y0, y1]` (inclusive, clamped to the image).
    pixel_box: Option<[u32; 4]>,
    /// Bounding box of the directions from the projector, `[u0, u1, w0, w1]`.
    proj_box: [f64; 4],
}

/// Entry and exit parameters of the line `o + t·r` through a convex solid, with the entry plane.
pub(crate) fn slab(planes: &[(V3, f64, u32)], o: V3, r: V3) -> Option<(f64, f64, u32)> {
    let (mut t0, mut t1, mut face) = (f64::NEG_INFINITY, f64::INFINITY, NO_FACE);
    for &(n, e, f) in planes {
        let den = dot(n, r);
        let num = -(dot(n, o) + e);
        if den < 0.0 {
            let t = num / den;
            if t > t0 {
                t0 = t;
                face = f;
            }
        } else if den > 0.0 {
            t1 = t1.min(num / den);
        } else if num < 0.0 {
            return None;
        }
        if t0 >= t1 {
            return None;
        }
    }
    Some((t0, t1, face))
}

/// Gaussian draw from the Irwin–Hall sum of 12 uniforms (unit variance, exactly portable).
pub(crate) fn gauss(rng: &mut Xoshiro256PlusPlus) -> f64 {
    (0..12).map(|_| rng.random::<f64>()).sum::<f64>() - 6.0
}

/// Renders `layout` into a scene with artefacts and ground truth.
///
/// The artefact families draw from their own streams, seeded from `seed`, so that without them
/// `rng` is used exactly as the benchmark always used it.
pub(crate) fn render(params: &Params, layout: &Layout, rng: &mut Xoshiro256PlusPlus, seed: u64) -> Scene {
    let world = World::build(params, layout);
    let hits = cast_primary(params, &world);
    let v_clean = clean_values(params, &world, &hits);
    let v_out = mixed_pixels(params, &world, &hits, &v_clean, rng);
    let mut range = quantise(params, &v_out, rng, seed);
    dropouts(params, &mut range, rng);
    if let Some(k) = &params.kinect {
        kinect_holes(params, k, &world, &hits, &v_out, &mut range, seed);
    }
    ground_truth(params, &world, &hits, range)
}

/// A random stream of its own for one artefact family of the scene of `seed`.
fn side_stream(seed: u64, family: u64) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(seed ^ (0xA27E_FAC7_0000_0000 | family))
}

/// The scene in the camera frame: the camera, the projector, every face plane `(n, e)` (table
/// first, then the wall if any, then the pieces' faces), the pieces as convex solids, and each
/// face's group of coincident planes.
struct World {
    cam: Cam,
    origin: V3,
    projector: V3,
    faces: Vec<(V3, f64)>,
    table_face: u32,
    wall: Option<u32>,
    solids: Vec<Solid>,
    group: Vec<u32>,
}

impl World {
    /// Places the layout in front of the camera.
    fn build(params: &Params, layout: &Layout) -> Self {
        let (w, h) = (params.width_px, params.height_px);
        let cal = params.calibration;
        let cam = Cam {
            scal: cal.scal,
            offset: cal.offset,
            z0: 255.0 / cal.scal + cal.offset,
            f: cal.f.abs(),
            c: cal.c,
            cx: f64::from(w) / 2.0 - 1.0,
            cy: f64::from(h) / 2.0 - 1.0,
        };
        let origin = [0.0, 0.0, cam.z0];
        let projector = [params.projector_baseline_mm, 0.0, cam.z0];

        // World → camera: table point on the optical axis, forward and up directions.
        let (se, ce) = crate::math::sin_cos(layout.elevation_rad);
        let c0 = [0.0, 0.0, cam.z0 - layout.table_distance_mm];
        let fwd = [0.0, se, -ce];
        let up = [0.0, ce, se];
        let to_cam = |p: V3| add(add(add(c0, [p[0], 0.0, 0.0]), scale(fwd, p[1])), scale(up, p[2]));

        // Faces: every plane of every piece, then groups of coincident planes (one visible face).
        let mut faces: Vec<(V3, f64)> = Vec::new();
        let table_face = 0u32;
        faces.push((up, -dot(up, c0)));
        let wall = layout.wall_y_mm.map(|y| {
            let n = scale(fwd, -1.0);
            faces.push((n, -dot(n, to_cam([0.0, y, 0.0]))));
            (faces.len() - 1) as u32
        });
        let mut solids = Vec::with_capacity(layout.pieces.len());
        for piece in &layout.pieces {
            let verts: Vec<V3> = piece.verts.iter().map(|&v| to_cam(v)).collect();
            let centroid = scale(verts.iter().fold([0.0; 3], |a, &v| add(a, v)), 1.0 / verts.len() as f64);
            let mut planes = Vec::with_capacity(piece.faces.len());
            for f in &piece.faces {
                // Newell's normal, oriented away from the centroid.
                let mut n = [0.0; 3];
                for i in 0..f.len() {
                    n = add(n, cross(verts[f[i]], verts[f[(i + 1) % f.len()]]));
                }
                let mut n = normalize(n);
                let p0 = scale(f.iter().fold([0.0; 3], |a, &i| add(a, verts[i])), 1.0 / f.len() as f64);
                if dot(n, sub(centroid, p0)) > 0.0 {
                    n = scale(n, -1.0);
                }
                let e = -dot(n, p0);
                faces.push((n, e));
                planes.push((n, e, (faces.len() - 1) as u32));
            }
            let (mut x0, mut x1, mut y0, mut y1) =
                (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
            let mut pb = [f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY];
            for &v in &verts {
                let (px, py) = cam.project(v);
                (x0, x1, y0, y1) = (x0.min(px), x1.max(px), y0.min(py), y1.max(py));
                let q = sub(v, projector);
                let (u, ww) = (q[0] / -q[2], q[1] / -q[2]);
                pb = [pb[0].min(u), pb[1].max(u), pb[2].min(ww), pb[3].max(ww)];
            }
            let pixel_box = (x1 >= 0.0 && y1 >= 0.0 && x0 <= f64::from(w - 1) && y0 <= f64::from(h - 1))
                .then(|| {
                    [
                        (x0.floor() - 1.0).max(0.0) as u32,
                        (x1.ceil() + 1.0).min(f64::from(w - 1)) as u32,
                        (y0.floor() - 1.0).max(0.0) as u32,
                        (y1.ceil() + 1.0).min(f64::from(h - 1)) as u32,
                    ]
                });
            let m = 1e-6;
            solids.push(Solid { planes, pixel_box, proj_box: [pb[0] - m, pb[1] + m, pb[2] - m, pb[3] + m] });
        }
        let group = plane_groups(&faces);
        Self { cam, origin, projector, faces, table_face, wall, solids, group }
    }
}

/// Where each pixel's primary ray first hits: its depth along the optical axis, the face hit
/// (`NO_FACE` for none) and the solid hit (`u32::MAX` for the table or the wall).
struct Hits {
    depth: Vec<f64>,
    face: Vec<u32>,
    solid_of: Vec<u32>,
}

/// Primary rays: table and wall everywhere, pieces inside their pixel boxes (z-buffer).
fn cast_primary(params: &Params, world: &World) -> Hits {
    let (w, h) = (params.width_px, params.height_px);
    let World { cam, origin, faces, table_face, wall, solids, .. } = world;
    let (origin, table_face, wall) = (*origin, *table_face, *wall);
    let n = w as usize * h as usize;
    let mut depth = vec![f64::INFINITY; n];
    let mut face = vec![NO_FACE; n];
    let mut solid_of = vec![u32::MAX; n];
    for y in 0..h {
        for x in 0..w {
            let r = cam.dir(f64::from(x), f64::from(y));
            let i = y as usize * w as usize + x as usize;
            for f in std::iter::once(table_face).chain(wall) {
                let (fnrm, fe) = faces[f as usize];
                let den = dot(fnrm, r);
                if den < 0.0 {
                    let t = -(dot(fnrm, origin) + fe) / den;
                    if t > 0.0 && t < depth[i] {
                        depth[i] = t;
                        face[i] = f;
                    }
                }
            }
        }
    }
    for (si, s) in solids.iter().enumerate() {
        let Some([x0, x1, y0, y1]) = s.pixel_box else { continue };
        for y in y0..=y1 {
            for x in x0..=x1 {
                let r = cam.dir(f64::from(x), f64::from(y));
                let i = y as usize * w as usize + x as usize;
                if let Some((t0, _, f)) = slab(&s.planes, origin, r)
                    && t0 > 0.0
                    && t0 < depth[i]
                {
                    depth[i] = t0;
                    face[i] = f;
                    solid_of[i] = si as u32;
                }
            }
        }
    }
    Hits { depth, face, solid_of }
}

/// Clean range values; out of the sensor's range and projector shadows are no data (NaN).
fn clean_values(params: &Params, world: &World, hits: &Hits) -> Vec<f64> {
    let (w, h) = (params.width_px, params.height_px);
    let n = w as usize * h as usize;
    let World { cam, origin, projector, faces, solids, .. } = world;
    let (origin, projector) = (*origin, *projector);
    let Hits { depth, face, solid_of } = hits;
    let mut v_clean = vec![f64::NAN; n];
    for y in 0..h {
        for x in 0..w {
            let i = y as usize * w as usize + x as usize;
            if face[i] == NO_FACE {
                continue;
            }
            let v = cam.scal * (depth[i] - cam.offset);
            if !(0.5..=255.5).contains(&v) {
                continue;
            }
            if params.shadows {
                let p = add(origin, scale(cam.dir(f64::from(x), f64::from(y)), depth[i]));
                if shadowed(p, face[i], solid_of[i], faces, solids, projector) {
                    continue;
                }
            }
            v_clean[i] = v;
        }
    }
    v_clean
}

/// Mixed pixels at jump edges: a value between the two surfaces; the label stays the hit face's.
fn mixed_pixels(
    params: &Params,
    world: &World,
    hits: &Hits,
    v_clean: &[f64],
    rng: &mut Xoshiro256PlusPlus,
) -> Vec<f64> {
    let (w, h) = (params.width_px, params.height_px);
    let World { cam, origin, faces, .. } = world;
    let origin = *origin;
    let face = &hits.face;
    let mut v_out = v_clean.to_vec();
    if params.mixed_pixel_prob > 0.0 {
        for y in 0..h {
            for x in 0..w {
                let i = y as usize * w as usize + x as usize;
                if v_clean[i].is_nan() {
                    continue;
                }
                let mut best: Option<f64> = None;
                for (dx, dy) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
                    let (nx, ny) = (i64::from(x) + dx, i64::from(y) + dy);
                    if nx < 0 || ny < 0 || nx >= i64::from(w) || ny >= i64::from(h) {
                        continue;
                    }
                    let j = ny as usize * w as usize + nx as usize;
                    let q = v_clean[j];
                    if q.is_nan() || face[j] == face[i] {
                        continue;
                    }
                    // A jump, not a crease: the neighbour is off the extension of this pixel's plane.
                    let (fnrm, fe) = faces[face[i] as usize];
                    let r = cam.dir(nx as f64, ny as f64);
                    let den = dot(fnrm, r);
                    let ext = if den == 0.0 {
                        f64::INFINITY
                    } else {
                        cam.scal * (-(dot(fnrm, origin) + fe) / den - cam.offset)
                    };
                    if (ext - q).abs() > params.jump_v
                        && (q - v_clean[i]).abs() > params.jump_v
                        && best.is_none_or(|b| (b - v_clean[i]).abs() < (q - v_clean[i]).abs())
                    {
                        best = Some(q);
                    }
                }
                if let Some(q) = best {
                    // Draw both numbers every time so the RNG stream does not depend on the branch.
                    let (p, a) = (rng.random::<f64>(), 0.15 + 0.7 * rng.random::<f64>());
                    if p < params.mixed_pixel_prob {
                        v_out[i] = v_clean[i] + a * (q - v_clean[i]);
                    }
                }
            }
        }
    }
    v_out
}

/// Depth noise, the artefact families' stripes, Kinect model and staircase, and 8-bit
/// quantisation (0 = no data).
fn quantise(params: &Params, v_out: &[f64], rng: &mut Xoshiro256PlusPlus, seed: u64) -> Grid<u8> {
    let (w, h) = (params.width_px, params.height_px);
    let mut range = Grid::new(w, h, 0u8);
    let stripes = params.stripes.map(|s| crate::family::stripe_field(&s, w, h, &mut side_stream(seed, 1)));
    let mut kinect_rng = side_stream(seed, 2);
    let disparity = params.disparity.then(|| Disparity::new(&params.calibration));
    for (i, px) in range.as_mut_slice().iter_mut().enumerate() {
        let g = gauss(rng);
        // Drawn for every pixel so the stream does not depend on which pixels hold data.
        let gk = if params.kinect.is_some() { gauss(&mut kinect_rng) } else { 0.0 };
        if !v_out[i].is_nan() {
            let mut v = disparity.as_ref().map_or(v_out[i], |d| d.value(v_out[i])) + params.noise_sigma_v * g;
            if let Some(f) = &stripes {
                v += f[i];
            }
            if let Some(k) = &params.kinect {
                v = k.measure(v, gk);
            }
            if let Some(s) = &params.staircase {
                v = (v / s.step_v).round() * s.step_v;
            }
            *px = v.round().clamp(1.0, 255.0) as u8;
        }
    }
    range
}

/// Inverse depth on the range axis: range value 0 (the nearest depth) stays 0 and 255 (the farthest) stays 255,
/// in between the value is affine in 1/depth, so every plane is affine in pixel coordinates.
struct Disparity {
    /// The calibration's range scale, and the depths of range values 0 (its offset) and 255.
    scal: f64,
    near: f64,
    far: f64,
}

impl Disparity {
    fn new(cal: &rangeimage::AbwCalibration) -> Self {
        Self { scal: cal.scal, near: cal.offset, far: 255.0 / cal.scal + cal.offset }
    }

    /// The stored value of range value `v` (depth `v / scal + offset` along the optical axis).
    fn value(&self, v: f64) -> f64 {
        let d = v / self.scal + self.near;
        255.0 * (1.0 / self.near - 1.0 / d) / (1.0 / self.near - 1.0 / self.far)
    }
}

/// Kinect holes: no data, with a probability rising on grazing surfaces and at far range.
fn kinect_holes(
    params: &Params,
    k: &crate::Kinect,
    world: &World,
    hits: &Hits,
    v_out: &[f64],
    range: &mut Grid<u8>,
    seed: u64,
) {
    let (w, h) = (params.width_px, params.height_px);
    let mut rng = side_stream(seed, 3);
    for y in 0..h {
        for x in 0..w {
            let i = y as usize * w as usize + x as usize;
            let u = rng.random::<f64>();
            if range[(x, y)] == 0 || hits.face[i] == NO_FACE || v_out[i].is_nan() {
                continue;
            }
            let r = world.cam.dir(f64::from(x), f64::from(y));
            let cos = dot(world.faces[hits.face[i] as usize].0, r).abs() / norm(r);
            if u < k.hole_probability(k.depth_mm(v_out[i]), cos) {
                range[(x, y)] = 0;
            }
        }
    }
}

/// Dropouts: small round blobs of no data.
fn dropouts(params: &Params, range: &mut Grid<u8>, rng: &mut Xoshiro256PlusPlus) {
    let (w, h) = (params.width_px, params.height_px);
    let n = w as usize * h as usize;
    let mean_area = 6.0;
    let blobs = (params.dropout_rate * n as f64 / mean_area).round() as u32;
    for _ in 0..blobs {
        let cx = rng.random::<f64>() * f64::from(w);
        let cy = rng.random::<f64>() * f64::from(h);
        let rad = 0.6 + 1.4 * rng.random::<f64>();
        let (xa, xb) = ((cx - rad).floor().max(0.0) as u32, ((cx + rad).ceil() as u32).min(w - 1));
        let (ya, yb) = ((cy - rad).floor().max(0.0) as u32, ((cy + rad).ceil() as u32).min(h - 1));
        for y in ya..=yb {
            for x in xa..=xb {
                let (dx, dy) = (f64::from(x) + 0.5 - cx, f64::from(y) + 0.5 - cy);
                if dx * dx + dy * dy <= rad * rad {
                    range[(x, y)] = 0;
                }
            }
        }
    }
}

/// Ground truth: connected pieces of one plane, on valid pixels (mixed ones included), and the
/// angles between adjacent pieces.
fn ground_truth(params: &Params, world: &World, hits: &Hits, range: Grid<u8>) -> Scene {
    let (w, h) = (params.width_px, params.height_px);
    let (faces, group, face) = (&world.faces, &world.group, &hits.face);
    let key = Grid::from_fn(w, h, |x, y| {
        let i = y as usize * w as usize + x as usize;
        if range[(x, y)] == 0 || face[i] == NO_FACE { u32::MAX } else { group[face[i] as usize] }
    });
    let (labels, region_group) = label_components(&key, params.min_region_px);
    let normal_of = |l: u32| faces[region_group[(l - 10) as usize] as usize].0;
    let mut pairs = BTreeSet::new();
    for y in 0..h {
        for x in 0..w {
            let a = labels[(x, y)];
            if a < 10 {
                continue;
            }
            for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                if let Some(&b) = labels.get(nx, ny)
                    && b >= 10
                    && b != a
                {
                    pairs.insert((a.min(b), a.max(b)));
                }
            }
        }
    }
    let angles = pairs.into_iter().map(|(a, b)| (a, b, angle_deg(normal_of(a), normal_of(b)))).collect();
    Scene { range, labels, angles }
}

/// True if the point `p` on face `f` of solid `own` does not see the projector.
fn shadowed(p: V3, f: u32, own: u32, faces: &[(V3, f64)], solids: &[Solid], projector: V3) -> bool {
    let s = sub(projector, p);
    if dot(faces[f as usize].0, s) <= 0.0 {
        return true;
    }
    let q = sub(p, projector);
    let (u, ww) = (q[0] / -q[2], q[1] / -q[2]);
    let len = norm(s);
    solids.iter().enumerate().any(|(i, sol)| {
        i as u32 != own
            && u >= sol.proj_box[0]
            && u <= sol.proj_box[1]
            && ww >= sol.proj_box[2]
            && ww <= sol.proj_box[3]
            && slab(&sol.planes, p, s)
                .is_some_and(|(t0, t1, _)| t1 > 1e-9 / len && t0 < 1.0 && t1 - t0 > 1e-9)
    })
}

/// Group index of every face: faces on the same plane (within rounding) share a group.
pub(crate) fn plane_groups(faces: &[(V3, f64)]) -> Vec<u32> {
    let mut group = vec![u32::MAX; faces.len()];
    for i in 0..faces.len() {
        if group[i] != u32::MAX {
            continue;
        }
        group[i] = i as u32;
        for j in i + 1..faces.len() {
            let (a, b) = (faces[i], faces[j]);
            if group[j] == u32::MAX && norm(sub(a.0, b.0)) < 1e-7 && (a.1 - b.1).abs() < 1e-4 {
                group[j] = i as u32;
            }
        }
    }
    group
}

/// 4-connected components of equal keys (`u32::MAX` = none); components of at least `min_px`
/// pixels get labels from 10 in raster order of first appearance (at most 246, the largest kept).
/// Returns the labels and the key of each label (index `label − 10`).
pub(crate) fn label_components(key: &Grid<u32>, min_px: u32) -> (LabelImage, Vec<u32>) {
    let (w, h) = key.dimensions();
    let mut comp = Grid::new(w, h, u32::MAX);
    let mut comps: Vec<(u32, usize)> = Vec::new(); // (key, size)
    let mut stack = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let k = key[(x, y)];
            if k == u32::MAX || comp[(x, y)] != u32::MAX {
                continue;
            }
            let id = comps.len() as u32;
            let mut size = 0;
            comp[(x, y)] = id;
            stack.push((x, y));
            while let Some((cx, cy)) = stack.pop() {
                size += 1;
                let nbrs = [(cx.wrapping_sub(1), cy), (cx + 1, cy), (cx, cy.wrapping_sub(1)), (cx, cy + 1)];
                for (nx, ny) in nbrs {
                    if nx < w && ny < h && key[(nx, ny)] == k && comp[(nx, ny)] == u32::MAX {
                        comp[(nx, ny)] = id;
                        stack.push((nx, ny));
                    }
                }
            }
            comps.push((k, size));
        }
    }
    let mut keep: Vec<usize> = (0..comps.len()).filter(|&c| comps[c].1 >= min_px as usize).collect();
    if keep.len() > 246 {
        keep.sort_by(|&a, &b| comps[b].1.cmp(&comps[a].1).then(a.cmp(&b)));
        keep.truncate(246);
        keep.sort_unstable();
    }
    let mut label_of = vec![0u32; comps.len()];
    let mut groups = Vec::with_capacity(keep.len());
    for (j, &c) in keep.iter().enumerate() {
        label_of[c] = 10 + j as u32;
        groups.push(comps[c].0);
    }
    (comp.map(|&c| if c == u32::MAX { 0 } else { label_of[c as usize] }), groups)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slab_hits_unit_cube_front_face() {
        let planes: Vec<(V3, f64, u32)> = vec![
            ([1.0, 0.0, 0.0], -1.0, 0),
            ([-1.0, 0.0, 0.0], -1.0, 1),
            ([0.0, 1.0, 0.0], -1.0, 2),
            ([0.0, -1.0, 0.0], -1.0, 3),
            ([0.0, 0.0, 1.0], -1.0, 4),
            ([0.0, 0.0, -1.0], -1.0, 5),
        ];
        let (t0, t1, f) = slab(&planes, [0.0, 0.0, 5.0], [0.0, 0.0, -1.0]).unwrap();
        assert_eq!((t0, t1, f), (4.0, 6.0, 4));
        assert!(slab(&planes, [3.0, 0.0, 5.0], [0.0, 0.0, -1.0]).is_none());
    }

    #[test]
    fn components_are_numbered_in_raster_order() {
        let m = u32::MAX;
        let key = Grid::from_rows(vec![vec![5, 5, m, 7], vec![5, m, 7, 7], vec![m, 5, 5, 7]]).unwrap();
        let (l, g) = label_components(&key, 2);
        // The lone 5 at (1, 2)-(2, 2) is a separate component of two pixels.
        assert_eq!(l.as_slice(), &[10, 10, 0, 11, 10, 0, 11, 11, 0, 12, 12, 11]);
        assert_eq!(g, vec![5, 7, 5]);
        let (l3, _) = label_components(&key, 4);
        assert_eq!(l3.as_slice(), &[0, 0, 0, 10, 0, 0, 10, 10, 0, 0, 0, 10]);
    }
}
