//! Scene layout: random polyhedral objects on a table in front of a wall, in world millimetres.
//!
//! World frame: x to the right, y forward along the table (away from the sensor), z up; the
//! table is the plane z = 0 and the wall the plane y = `wall_y_mm`. Every object is a union of
//! convex pieces, each given by its vertices and its faces (vertex index lists).

use crate::Params;
use crate::math::{V3, sin_cos};
use rand::RngExt;
use rand::rngs::Xoshiro256PlusPlus;
use std::f64::consts::{PI, TAU};

/// A convex polyhedron: vertices and faces (each a list of at least 3 coplanar vertex indices).
#[derive(Debug, Clone)]
pub(crate) struct Piece {
    pub(crate) verts: Vec<V3>,
    pub(crate) faces: Vec<Vec<usize>>,
}

/// A placed object: its convex pieces in world coordinates.
#[derive(Debug, Clone)]
struct Placed {
    pieces: Vec<Piece>,
    /// Convex hull of the footprint (all vertices projected on the table), counter-clockwise.
    footprint: Vec<[f64; 2]>,
    /// Highest z of any vertex.
    top_z: f64,
    /// Horizontal top face usable as a support: world polygon (CCW) and its height.
    support: Option<(Vec<[f64; 2]>, f64)>,
    /// Pose used to place neighbours flush against this object.
    yaw: f64,
    centre: [f64; 2],
    /// Local footprint bounds `[x0, x1, y0, y1]` before the yaw.
    local_box: [f64; 4],
    /// True if the object stands untilted on the table and may get a neighbour.
    on_table: bool,
    support_used: bool,
}

/// The world: camera pose, wall position and the objects' pieces.
#[derive(Debug, Clone)]
pub(crate) struct Layout {
    /// Elevation of the optical axis above the table plane, radians.
    pub(crate) elevation_rad: f64,
    /// Distance from the camera centre to the table along the optical axis, mm.
    pub(crate) table_distance_mm: f64,
    /// Wall plane y = wall_y_mm, or none.
    pub(crate) wall_y_mm: Option<f64>,
    /// All convex pieces of all objects.
    pub(crate) pieces: Vec<Piece>,
}

/// An object shape in local coordinates (base on z = 0, footprint around the origin).
struct Shape {
    pieces: Vec<Piece>,
    /// Local top polygon and height, if the shape has a horizontal top that can carry another object.
    support: Option<(Vec<[f64; 2]>, f64)>,
}

/// Extrudes a convex polygon; `along_y` puts the polygon in the x–z plane and extrudes along y,
/// otherwise the polygon is in x–y and is extruded along z.
fn prism(poly: &[[f64; 2]], w0: f64, w1: f64, along_y: bool) -> Piece {
    let n = poly.len();
    let map = |p: [f64; 2], w: f64| if along_y { [p[0], w, p[1]] } else { [p[0], p[1], w] };
    let mut verts: Vec<V3> = poly.iter().map(|&p| map(p, w0)).collect();
    verts.extend(poly.iter().map(|&p| map(p, w1)));
    let mut faces = vec![(0..n).collect::<Vec<_>>(), (n..2 * n).collect()];
    for i in 0..n {
        let j = (i + 1) % n;
        faces.push(vec![i, j, n + j, n + i]);
    }
    Piece { verts, faces }
}

fn rect(x0: f64, x1: f64, y0: f64, y1: f64) -> Vec<[f64; 2]> {
    vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
}

fn cuboid(x0: f64, x1: f64, y0: f64, y1: f64, z0: f64, z1: f64) -> Piece {
    prism(&rect(x0, x1, y0, y1), z0, z1, false)
}

/// A frustum over the rectangle `±ax × ±ay` with top scaled by `s` (0 = pyramid) and shifted.
fn frustum(ax: f64, ay: f64, s: f64, shift: [f64; 2], h: f64) -> Piece {
    let base = rect(-ax, ax, -ay, ay);
    let mut verts: Vec<V3> = base.iter().map(|p| [p[0], p[1], 0.0]).collect();
    let mut faces = vec![vec![0, 1, 2, 3]];
    if s > 0.0 {
        verts.extend(base.iter().map(|p| [p[0] * s + shift[0], p[1] * s + shift[1], h]));
        faces.push(vec![4, 5, 6, 7]);
        for i in 0..4 {
            let j = (i + 1) % 4;
            faces.push(vec![i, j, 4 + j, 4 + i]);
        }
    } else {
        verts.push([shift[0], shift[1], h]);
        for i in 0..4 {
            faces.push(vec![i, (i + 1) % 4, 4]);
        }
    }
    Piece { verts, faces }
}

/// A uniform draw in `[lo, hi)`.
pub(crate) fn uniform(rng: &mut Xoshiro256PlusPlus, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

/// Draws sizes (scaled) and plain ratios from the scene RNG.
struct Draw<'a> {
    rng: &'a mut Xoshiro256PlusPlus,
    scale: f64,
}

impl Draw<'_> {
    /// A uniform draw in `[0, 1)`.
    fn unit(&mut self) -> f64 {
        self.rng.random::<f64>()
    }

    /// A uniform ratio in `[lo, hi)` (not scaled).
    fn ratio(&mut self, lo: f64, hi: f64) -> f64 {
        uniform(self.rng, lo, hi)
    }

    /// A uniform size in `[lo, hi)` mm, times the shape scale.
    fn dim(&mut self, lo: f64, hi: f64) -> f64 {
        uniform(self.rng, lo, hi) * self.scale
    }
}

/// Draws one random shape.
fn random_shape(rng: &mut Xoshiro256PlusPlus, scale: f64) -> Shape {
    let mut d = Draw { rng, scale };
    let kind = rng_pick(d.unit());
    match kind {
        // Box.
        0 => {
            let (sx, sy, h) = (d.dim(35.0, 95.0), d.dim(35.0, 95.0), d.dim(20.0, 75.0));
            let top = rect(-sx / 2.0, sx / 2.0, -sy / 2.0, sy / 2.0);
            Shape { pieces: vec![prism(&top, 0.0, h, false)], support: Some((top, h)) }
        }
        // Wedge or ramp: trapezoid cross-section in x–z, extruded along y.
        1 => {
            let (sx, sy, h1) = (d.dim(45.0, 100.0), d.dim(35.0, 90.0), d.dim(25.0, 70.0));
            let h0 = if d.unit() < 0.5 { 0.0 } else { d.dim(8.0, 0.6 * h1 / scale) };
            let mut sec = vec![[-sx / 2.0, 0.0], [sx / 2.0, 0.0], [sx / 2.0, h1]];
            if h0 > 0.0 {
                sec.push([-sx / 2.0, h0]);
            }
            Shape { pieces: vec![prism(&sec, -sy / 2.0, sy / 2.0, true)], support: None }
        }
        // Triangular prism lying on a rectangular face (a roof).
        2 => {
            let (sx, sy, h) = (d.dim(40.0, 90.0), d.dim(45.0, 100.0), d.dim(25.0, 60.0));
            let apex = d.ratio(-0.25, 0.25) * sx;
            let sec = [[-sx / 2.0, 0.0], [sx / 2.0, 0.0], [apex, h]];
            Shape { pieces: vec![prism(&sec, -sy / 2.0, sy / 2.0, true)], support: None }
        }
        // Pyramid or frustum.
        3 => {
            let (ax, ay, h) = (d.dim(22.0, 45.0), d.dim(22.0, 45.0), d.dim(25.0, 65.0));
            let s = if d.unit() < 0.35 { 0.0 } else { d.ratio(0.35, 0.7) };
            let shift = [d.ratio(-0.15, 0.15) * ax, d.ratio(-0.15, 0.15) * ay];
            let support = (s > 0.0).then(|| {
                let t = rect(-ax * s, ax * s, -ay * s, ay * s);
                (t.iter().map(|p| [p[0] + shift[0], p[1] + shift[1]]).collect(), h)
            });
            Shape { pieces: vec![frustum(ax, ay, s, shift, h)], support }
        }
        // L-block: a low box with a tall box on one side.
        4 => {
            let (sx, sy, h1) = (d.dim(60.0, 110.0), d.dim(35.0, 80.0), d.dim(15.0, 35.0));
            let h2 = h1 + d.dim(20.0, 45.0);
            let xs = -sx / 2.0 + sx * d.ratio(0.35, 0.6);
            let pieces = vec![
                cuboid(-sx / 2.0, sx / 2.0, -sy / 2.0, sy / 2.0, 0.0, h1),
                cuboid(-sx / 2.0, xs, -sy / 2.0, sy / 2.0, 0.0, h2),
            ];
            Shape { pieces, support: Some((rect(-sx / 2.0, xs, -sy / 2.0, sy / 2.0), h2)) }
        }
        // Stairs: two or three steps.
        5 => {
            let steps = if d.unit() < 0.5 { 2 } else { 3 };
            let (sx, sy, h) = (d.dim(60.0, 110.0), d.dim(40.0, 85.0), d.dim(15.0, 28.0));
            let pieces = (0..steps)
                .map(|i| {
                    let x0 = -sx / 2.0 + sx * f64::from(i) / f64::from(steps);
                    cuboid(x0, sx / 2.0, -sy / 2.0, sy / 2.0, 0.0, h * f64::from(i + 1))
                })
                .collect();
            Shape { pieces, support: None }
        }
        // Regular prism standing on a polygonal base (5, 6 or 8 sides).
        6 => {
            let sides = [5, 6, 8][(3.0 * d.unit()) as usize];
            let (r, h) = (d.dim(22.0, 42.0), d.dim(20.0, 75.0));
            let phase = d.unit() * TAU;
            let poly: Vec<[f64; 2]> = (0..sides)
                .map(|i| {
                    let (s, c) = sin_cos(phase + TAU * f64::from(i) / f64::from(sides));
                    [r * c, r * s]
                })
                .collect();
            Shape { pieces: vec![prism(&poly, 0.0, h, false)], support: Some((poly, h)) }
        }
        // House: a box with a gable roof.
        _ => {
            let (sx, sy, hb, hr) =
                (d.dim(40.0, 80.0), d.dim(45.0, 95.0), d.dim(20.0, 45.0), d.dim(15.0, 35.0));
            let roof = [[-sx / 2.0, hb], [sx / 2.0, hb], [0.0, hb + hr]];
            let pieces = vec![
                cuboid(-sx / 2.0, sx / 2.0, -sy / 2.0, sy / 2.0, 0.0, hb),
                prism(&roof, -sy / 2.0, sy / 2.0, true),
            ];
            Shape { pieces, support: None }
        }
    }
}

/// Maps a uniform draw to a shape kind; boxes are the most common, as in ABW.
fn rng_pick(r: f64) -> u32 {
    const CUM: [f64; 8] = [0.30, 0.43, 0.53, 0.65, 0.77, 0.86, 0.94, 1.0];
    CUM.iter().position(|&c| r < c).unwrap_or(7) as u32
}

/// Counter-clockwise convex hull (Andrew's monotone chain).
fn hull(mut pts: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    pts.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let turn =
        |o: [f64; 2], a: [f64; 2], b: [f64; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let mut h: Vec<[f64; 2]> = Vec::with_capacity(2 * pts.len());
    for pass in 0..2 {
        let start = h.len();
        let it: Box<dyn Iterator<Item = &[f64; 2]>> =
            if pass == 0 { Box::new(pts.iter()) } else { Box::new(pts.iter().rev()) };
        for &p in it {
            while h.len() >= start + 2 && turn(h[h.len() - 2], h[h.len() - 1], p) <= 0.0 {
                h.pop();
            }
            h.push(p);
        }
        h.pop();
    }
    h
}

/// True if two convex CCW polygons overlap by more than `tol` mm (separating axis test).
fn overlap(a: &[[f64; 2]], b: &[[f64; 2]], tol: f64) -> bool {
    for poly in [a, b] {
        for i in 0..poly.len() {
            let p = poly[i];
            let q = poly[(i + 1) % poly.len()];
            let (nx, ny) = (q[1] - p[1], p[0] - q[0]);
            let len = (nx * nx + ny * ny).sqrt();
            if len == 0.0 {
                continue;
            }
            let proj = |s: &[[f64; 2]]| {
                s.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                    let d = (v[0] * nx + v[1] * ny) / len;
                    (lo.min(d), hi.max(d))
                })
            };
            let (alo, ahi) = proj(a);
            let (blo, bhi) = proj(b);
            if ahi - blo <= tol || bhi - alo <= tol {
                return false;
            }
        }
    }
    true
}

/// True if every point of `inner` lies inside the convex CCW polygon `outer`, `margin` mm from its edges.
fn inside(inner: &[[f64; 2]], outer: &[[f64; 2]], margin: f64) -> bool {
    inner.iter().all(|p| {
        (0..outer.len()).all(|i| {
            let a = outer[i];
            let b = outer[(i + 1) % outer.len()];
            let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
            let len = (ex * ex + ey * ey).sqrt();
            (ex * (p[1] - a[1]) - ey * (p[0] - a[0])) / len >= margin
        })
    })
}

/// Rotates about x by `tilt`, then about z by `yaw`, then translates.
fn pose(p: V3, tilt: (f64, f64), yaw: (f64, f64), t: V3) -> V3 {
    let (st, ct) = tilt;
    let q = [p[0], ct * p[1] - st * p[2], st * p[1] + ct * p[2]];
    let (sy, cy) = yaw;
    [cy * q[0] - sy * q[1] + t[0], sy * q[0] + cy * q[1] + t[1], q[2] + t[2]]
}

fn local_box(shape: &Shape) -> [f64; 4] {
    let mut b = [f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY];
    for v in shape.pieces.iter().flat_map(|p| &p.verts) {
        b = [b[0].min(v[0]), b[1].max(v[0]), b[2].min(v[1]), b[3].max(v[1])];
    }
    b
}

/// Places `shape` with the given pose and returns the placed object.
fn place(shape: &Shape, tilt: f64, yaw: f64, centre: [f64; 2], base_z: f64) -> Placed {
    let ts = sin_cos(tilt);
    let ys = sin_cos(yaw);
    // A tilted object rests with its lowest vertex on the base.
    let min_z = shape
        .pieces
        .iter()
        .flat_map(|p| &p.verts)
        .map(|&v| pose(v, ts, ys, [0.0; 3])[2])
        .fold(f64::INFINITY, f64::min);
    let t = [centre[0], centre[1], base_z - min_z];
    let pieces: Vec<Piece> = shape
        .pieces
        .iter()
        .map(|p| Piece {
            verts: p.verts.iter().map(|&v| pose(v, ts, ys, t)).collect(),
            faces: p.faces.clone(),
        })
        .collect();
    let footprint = hull(pieces.iter().flat_map(|p| &p.verts).map(|v| [v[0], v[1]]).collect());
    let top_z = pieces.iter().flat_map(|p| &p.verts).map(|v| v[2]).fold(f64::NEG_INFINITY, f64::max);
    let support = if tilt == 0.0 {
        shape.support.as_ref().map(|(poly, h)| {
            let w: Vec<[f64; 2]> = poly
                .iter()
                .map(|&q| {
                    let p = pose([q[0], q[1], 0.0], ts, ys, t);
                    [p[0], p[1]]
                })
                .collect();
            (hull(w), h + t[2])
        })
    } else {
        None
    };
    Placed {
        pieces,
        footprint,
        top_z,
        support,
        yaw,
        centre,
        local_box: local_box(shape),
        on_table: base_z == 0.0 && tilt == 0.0,
        support_used: false,
    }
}

/// Draws a random scene layout.
pub(crate) fn random_layout(params: &Params, rng: &mut Xoshiro256PlusPlus) -> Layout {
    let elevation_rad = uniform(rng, 33.0, 48.0) * PI / 180.0;
    let table_distance_mm = uniform(rng, 930.0, 975.0);
    let wall_y_mm = params.wall.then(|| uniform(rng, 75.0, 135.0));
    let wall_limit = wall_y_mm.unwrap_or(150.0) - 8.0;
    let n_objects = rng.random_range(params.min_objects..=params.max_objects);
    let mut objects: Vec<Placed> = Vec::new();
    for _ in 0..n_objects {
        for _attempt in 0..40 {
            let shape = random_shape(rng, 1.0);
            let yaw = uniform(rng, 0.0, TAU);
            let mode = rng.random::<f64>();
            let candidate = if mode < params.stack_prob
                && objects.iter().any(|o| o.support.is_some() && !o.support_used)
            {
                // Stack on a free support, keeping the footprint inside its top face.
                let free: Vec<usize> = (0..objects.len())
                    .filter(|&i| objects[i].support.is_some() && !objects[i].support_used)
                    .collect();
                let s = free[rng.random_range(0..free.len() as u32) as usize];
                let (poly, h) = objects[s].support.clone().expect("support checked above");
                let cx = poly.iter().map(|p| p[0]).sum::<f64>() / poly.len() as f64;
                let cy = poly.iter().map(|p| p[1]).sum::<f64>() / poly.len() as f64;
                let c = [cx + uniform(rng, -10.0, 10.0), cy + uniform(rng, -10.0, 10.0)];
                let small = random_shape(rng, 0.6);
                let p = place(&small, 0.0, yaw, c, h);
                inside(&p.footprint, &poly, 2.0).then_some((p, Some(s)))
            } else if mode < params.stack_prob + params.touch_prob && objects.iter().any(|o| o.on_table) {
                // Put the new object flush against the side of one standing on the table.
                let ground: Vec<usize> = (0..objects.len()).filter(|&i| objects[i].on_table).collect();
                let a = &objects[ground[rng.random_range(0..ground.len() as u32) as usize]];
                let ab = a.local_box;
                let bb = local_box(&shape);
                let side = rng.random_range(0..4u32);
                let along = rng.random::<f64>();
                let (tx, ty) = match side {
                    0 => {
                        (ab[1] - bb[0], ab[2] - bb[3] + 12.0 + along * (ab[3] - ab[2] + bb[3] - bb[2] - 24.0))
                    }
                    1 => {
                        (ab[0] - bb[1], ab[2] - bb[3] + 12.0 + along * (ab[3] - ab[2] + bb[3] - bb[2] - 24.0))
                    }
                    2 => {
                        (ab[0] - bb[1] + 12.0 + along * (ab[1] - ab[0] + bb[1] - bb[0] - 24.0), ab[3] - bb[2])
                    }
                    _ => {
                        (ab[0] - bb[1] + 12.0 + along * (ab[1] - ab[0] + bb[1] - bb[0] - 24.0), ab[2] - bb[3])
                    }
                };
                let (s, c) = sin_cos(a.yaw);
                let centre = [a.centre[0] + c * tx - s * ty, a.centre[1] + s * tx + c * ty];
                let p = place(&shape, 0.0, a.yaw, centre, 0.0);
                ((p.top_z - a.top_z).abs() > 10.0).then_some((p, None))
            } else {
                let tilt = if rng.random::<f64>() < params.tilt_prob {
                    uniform(rng, 8.0, 25.0) * PI / 180.0 * if rng.random::<bool>() { 1.0 } else { -1.0 }
                } else {
                    0.0
                };
                let centre = [uniform(rng, -95.0, 95.0), uniform(rng, -95.0, wall_limit - 30.0)];
                Some((place(&shape, tilt, yaw, centre, 0.0), None))
            };
            let Some((p, support)) = candidate else { continue };
            // Stay on the visible part of the table, in front of the wall, and clear of every
            // other object on the same level (a stacked object only meets its support).
            let fits_table =
                p.footprint.iter().all(|v| v[0].abs() < 125.0 && v[1] > -115.0 && v[1] < wall_limit);
            let clear = objects.iter().enumerate().all(|(i, o)| {
                if Some(i) == support {
                    return true;
                }
                let vertical_gap = match support {
                    Some(s) => o.top_z <= objects[s].support.as_ref().map_or(0.0, |x| x.1) + 1e-9,
                    None => false,
                };
                vertical_gap || !overlap(&p.footprint, &o.footprint, 0.5)
            });
            if fits_table && clear {
                if let Some(s) = support {
                    objects[s].support_used = true;
                }
                objects.push(p);
                break;
            }
        }
    }
    Layout {
        elevation_rad,
        table_distance_mm,
        wall_y_mm,
        pieces: objects.into_iter().flat_map(|o| o.pieces).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn hull_and_overlap() {
        let h = hull(vec![[0.0, 0.0], [1.0, 0.0], [0.5, 0.5], [1.0, 1.0], [0.0, 1.0]]);
        assert_eq!(h.len(), 4);
        let a = rect(0.0, 1.0, 0.0, 1.0);
        assert!(overlap(&a, &rect(0.5, 2.0, 0.5, 2.0), 0.0));
        assert!(!overlap(&a, &rect(1.0, 2.0, 0.0, 1.0), 1e-9));
        assert!(inside(&rect(0.2, 0.8, 0.2, 0.8), &a, 0.1));
        assert!(!inside(&rect(0.2, 1.8, 0.2, 0.8), &a, 0.1));
    }

    #[test]
    fn layout_objects_do_not_interpenetrate_on_the_table() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let l = random_layout(&Params::default(), &mut rng);
        assert!(!l.pieces.is_empty());
        for p in &l.pieces {
            assert!(p.verts.iter().all(|v| v[2] > -1e-9), "a piece reaches below the table");
        }
    }
}
