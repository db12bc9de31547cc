//! Plane equations of a segmentation's regions: a least-squares fit to each region's 3D points.

use rangeimage::{Camera, LabelImage, RangeImage};
use serde::Serialize;

/// One labelled region as a plane `normal · X = d` in the camera's frame (metres for a metric pinhole camera,
/// the calibration's units for ABW, the image's own units `(x, y, value)` for the grid camera).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Plane {
    /// The region's label in the label image (never 0).
    pub label: u32,
    /// Unit normal, oriented toward the sensor; NaN when the region has fewer than 3 points.
    pub normal: [f64; 3],
    /// Offset: `normal · X = d` for the points X of the plane; NaN when `normal` is.
    pub d: f64,
    /// Mean of the region's 3D points.
    pub centroid: [f64; 3],
    /// Number of pixels carrying the label.
    pub pixels: u64,
    /// Root-mean-square point-to-plane distance of the region's 3D points.
    pub rms: f64,
    /// Bounding box in pixels, inclusive: `[x_min, y_min, x_max, y_max]`.
    pub bbox: [u32; 4],
}

/// Per-label sums gathered over the image, about the label's first point (`origin`): shifted sums keep the
/// one-pass covariance accurate when the points lie far from the camera's origin.
#[derive(Clone)]
struct Acc {
    pixels: u64,
    points: u64,
    origin: [f64; 3],
    sum: [f64; 3],
    cross: [[f64; 3]; 3],
    bbox: [u32; 4],
}

/// Fits a plane to every region of `labels` (label 0 = none) from the 3D points the camera gives the pixels'
/// range values; sorted by label.
///
/// The normal is the eigenvector of the smallest eigenvalue of the points' covariance (total least squares,
/// in f64), flipped to face the sensor; the RMS is the square root of that covariance's value along the normal.
/// One pass over the image: the sums are taken about each region's first point and centred afterwards. Pixels
/// without a range value count in `pixels` and `bbox` but not in the fit. Deterministic: the sums run in pixel
/// order.
///
/// # Panics
/// If `labels` and `range` differ in size.
pub fn planes(range: &RangeImage, labels: &LabelImage, camera: &Camera) -> Vec<Plane> {
    assert_eq!(range.dimensions(), labels.dimensions(), "range and labels differ in size");
    // Compiled for the best instruction set of this CPU (bit-identical on every one).
    isa::dispatch(
        #[inline(always)]
        || fit_regions(range, labels, camera),
    )
}

/// [`planes`] once the sizes are checked.
#[inline(always)] // into `isa::dispatch` in `planes`: compiled for each instruction set
fn fit_regions(range: &RangeImage, labels: &LabelImage, camera: &Camera) -> Vec<Plane> {
    // Sums indexed by the label itself when the largest label is small against the pixel count (a segmentation's
    // 1..n; the sums then take at most about 4 bytes a pixel, and no table of the labels present is built), else by
    // the label's rank among the sorted distinct labels.
    let max = labels.as_slice().iter().copied().max().unwrap_or(0) as usize;
    let dense = max <= labels.len() / 32;
    let sparse: Vec<u32> = if dense {
        Vec::new()
    } else {
        let mut ids: Vec<u32> = labels.as_slice().iter().copied().filter(|&l| l != 0).collect();
        ids.sort_unstable();
        ids.dedup();
        ids
    };
    let empty = Acc {
        pixels: 0,
        points: 0,
        origin: [0.0; 3],
        sum: [0.0; 3],
        cross: [[0.0; 3]; 3],
        bbox: [u32::MAX, u32::MAX, 0, 0],
    };
    let mut acc = vec![empty; if dense { max + 1 } else { sparse.len() }];
    let index = |l: u32| {
        if dense { l as usize } else { sparse.binary_search(&l).expect("every label was collected") }
    };
    // The 3D points of one row at a time.
    let mut row = vec![[0.0f64; 3]; range.width() as usize];

    for_runs(
        range,
        labels,
        camera,
        &mut row,
        // Inlined, so that it is compiled for the dispatched instruction set too.
        #[inline(always)]
        |(x0, y): (u32, u32), vals: &[f32], pts: &[[f64; 3]], l: u32| {
            let a = &mut acc[index(l)];
            let x1 = x0 + vals.len() as u32 - 1;
            a.pixels += vals.len() as u64;
            a.bbox = [a.bbox[0].min(x0), a.bbox[1].min(y), a.bbox[2].max(x1), a.bbox[3].max(y)];
            // Summed in a local copy, in pixel order.
            let (mut points, mut origin, mut sum, mut cross) = (a.points, a.origin, a.sum, a.cross);
            for (v, &p) in vals.iter().zip(pts) {
                if v.is_finite() {
                    if points == 0 {
                        origin = p;
                    }
                    points += 1;
                    let q = sub(p, origin);
                    for r in 0..3 {
                        sum[r] += q[r];
                        for c in r..3 {
                            cross[r][c] += q[r] * q[c];
                        }
                    }
                }
            }
            (a.points, a.origin, a.sum, a.cross) = (points, origin, sum, cross);
        },
    );

    acc.into_iter()
        .enumerate()
        .map(|(j, a)| (if dense { j as u32 } else { sparse[j] }, a))
        .filter(|(label, a)| *label != 0 && a.pixels > 0)
        .map(|(label, a)| {
            let n = a.points as f64;
            let mean = a.sum.map(|s| s / n);
            let centroid = [a.origin[0] + mean[0], a.origin[1] + mean[1], a.origin[2] + mean[2]];
            // Σ (q − mean)(q − mean)ᵀ = Σ q qᵀ − mean (Σ q)ᵀ.
            let mut cov = [[0.0; 3]; 3];
            for r in 0..3 {
                for c in r..3 {
                    cov[r][c] = a.cross[r][c] - mean[r] * a.sum[c];
                }
            }
            let normal = if a.points < 3 {
                [f64::NAN; 3]
            } else {
                let n = smallest_eigenvector(cov);
                if dot(n, camera.toward_sensor(centroid)) < 0.0 { n.map(|v| -v) } else { n }
            };
            // The residuals' sum of squares is the covariance along the normal (never below 0 in exact terms).
            let sq = along(cov, normal).max(0.0);
            Plane {
                label,
                normal,
                d: dot(normal, centroid),
                centroid,
                pixels: a.pixels,
                rms: if a.points < 3 { f64::NAN } else { (sq / n).sqrt() },
                bbox: a.bbox,
            }
        })
        .collect()
}

/// `nᵀ M n` for a symmetric 3×3 matrix `M` given by its upper triangle.
fn along(upper: [[f64; 3]; 3], n: [f64; 3]) -> f64 {
    let mut s = 0.0;
    for r in 0..3 {
        s += upper[r][r] * n[r] * n[r];
        for c in r + 1..3 {
            s += 2.0 * upper[r][c] * n[r] * n[c];
        }
    }
    s
}

/// Calls `f((x0, y), values, points, label)` for every run of equal non-zero labels of a row, in raster order,
/// with the run's range values and their 3D points (meaningful where the value is finite). `row` holds one row
/// of points.
#[inline(always)]
fn for_runs(
    range: &RangeImage,
    labels: &LabelImage,
    camera: &Camera,
    row: &mut [[f64; 3]],
    mut f: impl FnMut((u32, u32), &[f32], &[[f64; 3]], u32),
) {
    let w = (labels.width() as usize).max(1);
    for ((rrow, lrow), y) in
        range.as_slice().chunks_exact(w).zip(labels.as_slice().chunks_exact(w)).zip(0u32..)
    {
        if lrow.iter().all(|&l| l == 0) {
            continue;
        }
        camera.row_points(y, rrow, row);
        let mut x = 0;
        while x < w {
            let l = lrow[x];
            let start = x;
            x += 1;
            while x < w && lrow[x] == l {
                x += 1;
            }
            if l != 0 {
                f((start as u32, y), &rrow[start..x], &row[start..x], l);
            }
        }
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The unit eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix given by its upper triangle,
/// by cyclic Jacobi rotations (deterministic, accurate for the tiny eigenvalues of near-planar point sets).
fn smallest_eigenvector(upper: [[f64; 3]; 3]) -> [f64; 3] {
    let mut a = upper;
    for r in 0..3 {
        for c in 0..r {
            a[r][c] = a[c][r];
        }
    }
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _sweep in 0..50 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        let diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if off <= diag * 1e-32 || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            // Rotation that zeroes a[p][q] (Numerical Recipes' form, stable for small angles).
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let k = (0..3).fold(0, |best, k| if a[k][k] < a[best][best] { k } else { best });
    let n = [v[0][k], v[1][k], v[2][k]];
    let len = dot(n, n).sqrt();
    n.map(|x| x / len)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rangeimage::Grid;

    /// Depth image of the plane `n · X = d` seen by a pinhole camera: Z where each pixel's ray meets it.
    fn pinhole_plane(cam: Camera, n: [f64; 3], d: f64, w: u32, h: u32) -> RangeImage {
        let Camera::Pinhole { fx, fy, cx, cy, .. } = cam else { unreachable!() };
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = (f64::from(i % w), f64::from(i / w));
                let ray = [(x - cx) / fx, (y - cy) / fy, 1.0];
                (d / dot(n, ray)) as f32
            })
            .collect();
        Grid::from_vec(w, h, data).unwrap()
    }

    /// The distinct non-zero labels of `labels`, sorted: marked in a table up to the largest label when that is
    /// at most the pixel count (a segmentation's 1..n: one pass, no sort of the pixels), else sorted.
    fn label_ids(labels: &LabelImage) -> Vec<u32> {
        let max = labels.as_slice().iter().copied().max().unwrap_or(0) as usize;
        if max > labels.len() {
            let mut ids: Vec<u32> = labels.as_slice().iter().copied().filter(|&l| l != 0).collect();
            ids.sort_unstable();
            ids.dedup();
            return ids;
        }
        let mut seen = vec![false; max + 1];
        for &l in labels.as_slice() {
            seen[l as usize] = true;
        }
        (1..=max).filter(|&l| seen[l]).map(|l| l as u32).collect()
    }

    /// Per-label sums of the reference fit.
    #[derive(Clone)]
    struct Acc {
        pixels: u64,
        points: u64,
        sum: [f64; 3],
        cov: [[f64; 3]; 3],
        sq_residual: f64,
        bbox: [u32; 4],
    }

    /// The textbook fit [`planes`] must agree with: every pixel's point from [`Camera::point`], added into its
    /// label's sums one at a time, in three passes (the centroid, the covariance about it, the residuals about
    /// the plane).
    fn planes_pixelwise(range: &RangeImage, labels: &LabelImage, camera: &Camera) -> Vec<Plane> {
        assert_eq!(range.dimensions(), labels.dimensions(), "range and labels differ in size");
        let ids = label_ids(labels);
        let empty = Acc {
            pixels: 0,
            points: 0,
            sum: [0.0; 3],
            cov: [[0.0; 3]; 3],
            sq_residual: 0.0,
            bbox: [u32::MAX, u32::MAX, 0, 0],
        };
        let mut acc = vec![empty; ids.len()];
        // Label → index into `ids`: a table when the labels are at most as many as the pixels (a segmentation's
        // 1..n), else a binary search.
        let max = ids.last().copied().unwrap_or(0) as usize;
        let table: Vec<u32> = if max <= labels.len() {
            let mut t = vec![u32::MAX; max + 1];
            for (j, &l) in ids.iter().enumerate() {
                t[l as usize] = j as u32;
            }
            t
        } else {
            Vec::new()
        };
        let index = |l: u32| match table.get(l as usize) {
            Some(&j) if !table.is_empty() => j as usize,
            _ => ids.binary_search(&l).expect("every label was collected"),
        };
        let point = |x: u32, y: u32, v: f32| camera.point(f64::from(x), f64::from(y), f64::from(v));

        for_labelled_pixelwise(range, labels, |x, y, v, l| {
            let a = &mut acc[index(l)];
            a.pixels += 1;
            a.bbox = [a.bbox[0].min(x), a.bbox[1].min(y), a.bbox[2].max(x), a.bbox[3].max(y)];
            if let Some(p) = point(x, y, v) {
                a.points += 1;
                for k in 0..3 {
                    a.sum[k] += p[k];
                }
            }
        });
        let centroids: Vec<[f64; 3]> = acc.iter().map(|a| a.sum.map(|s| s / a.points as f64)).collect();
        for_labelled_pixelwise(range, labels, |x, y, v, l| {
            let j = index(l);
            if let Some(p) = point(x, y, v) {
                let q = sub(p, centroids[j]);
                for r in 0..3 {
                    for c in r..3 {
                        acc[j].cov[r][c] += q[r] * q[c];
                    }
                }
            }
        });
        let normals: Vec<[f64; 3]> = acc
            .iter()
            .zip(&centroids)
            .map(|(a, &c)| {
                if a.points < 3 {
                    return [f64::NAN; 3];
                }
                let n = smallest_eigenvector(a.cov);
                if dot(n, camera.toward_sensor(c)) < 0.0 { n.map(|v| -v) } else { n }
            })
            .collect();
        for_labelled_pixelwise(range, labels, |x, y, v, l| {
            let j = index(l);
            if let Some(p) = point(x, y, v) {
                let r = dot(normals[j], sub(p, centroids[j]));
                acc[j].sq_residual += r * r;
            }
        });

        ids.iter()
            .zip(acc)
            .zip(centroids.iter().zip(&normals))
            .map(|((&label, a), (&centroid, &normal))| Plane {
                label,
                normal,
                d: dot(normal, centroid),
                centroid,
                pixels: a.pixels,
                rms: (a.sq_residual / a.points as f64).sqrt(),
                bbox: a.bbox,
            })
            .collect()
    }

    /// Calls `f(x, y, range value, label)` for every labelled pixel in raster order.
    #[inline(always)]
    fn for_labelled_pixelwise(
        range: &RangeImage,
        labels: &LabelImage,
        mut f: impl FnMut(u32, u32, f32, u32),
    ) {
        let w = (labels.width() as usize).max(1);
        for ((rrow, lrow), y) in
            range.as_slice().chunks_exact(w).zip(labels.as_slice().chunks_exact(w)).zip(0u32..)
        {
            for ((&v, &l), x) in rrow.iter().zip(lrow).zip(0u32..) {
                if l != 0 {
                    f(x, y, v, l);
                }
            }
        }
    }

    /// Random label images (runs, holes, labels beyond the pixel count) on noisy slanted depths with NaN and
    /// infinite values, on the three camera models: every instruction-set path gives the same bits, and the
    /// one-pass fit agrees with the three-pass reference to rounding (pixels, boxes and labels exactly).
    #[test]
    fn one_pass_fit_agrees_with_the_three_pass_reference() {
        // A seeded xorshift64*: deterministic and dependency-free.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            state.wrapping_mul(0x2545_f491_4f6c_dd1d)
        };
        let cams = [
            Camera::ABW0,
            Camera::ABW1,
            Camera::Pinhole { fx: 525.0, fy: 520.5, cx: 319.5, cy: 239.5, depth_scale: 0.001 },
            Camera::Grid,
        ];
        let bits = |p: &Plane| {
            let f = [p.normal, p.centroid].concat().into_iter().chain([p.d, p.rms]).map(f64::to_bits);
            (p.label, p.pixels, p.bbox, f.collect::<Vec<_>>())
        };
        // Relative difference, on the scale of the larger value or 1 (NaN equal to NaN).
        let close = |a: f64, b: f64, tol: f64| {
            (a.is_nan() && b.is_nan()) || (a - b).abs() <= tol * a.abs().max(b.abs()).max(1.0)
        };
        let mut compared = 0;
        for round in 0..48 {
            let (w, h) = (1 + (next() % 70) as u32, 1 + (next() % 50) as u32);
            let n_labels = 1 + next() % 12;
            let big = round % 4 == 3;
            let (mut vals, mut labs) = (Vec::new(), Vec::new());
            while labs.len() < (w * h) as usize {
                // Runs of one label, some of them 0; beyond the pixel count in some rounds (the binary search).
                let k = next() % (n_labels + 1);
                let l = if k == 0 {
                    0
                } else if big {
                    1_000_000 + k as u32 * 7919
                } else {
                    k as u32
                };
                for _ in 0..1 + next() % 9 {
                    labs.push(l);
                }
            }
            labs.truncate((w * h) as usize);
            for i in 0..w * h {
                let r = next();
                vals.push(match r % 23 {
                    0 => f32::NAN,
                    1 => f32::INFINITY,
                    _ => {
                        200.0 + (i % w) as f32 * 3.7 - (i / w) as f32 * 1.1
                            + (r >> 40) as f32 / 16_777_216.0 * 2.0
                    }
                });
            }
            let range = Grid::from_vec(w, h, vals).unwrap();
            let labels = Grid::from_vec(w, h, labs).unwrap();
            let cam = cams[round % cams.len()];
            let reference = planes_pixelwise(&range, &labels, &cam);
            let first = planes(&range, &labels, &cam);
            for path in isa::Isa::available() {
                let a = isa::with_isa(path, || planes(&range, &labels, &cam)).expect("available");
                assert_eq!(
                    a.iter().map(bits).collect::<Vec<_>>(),
                    first.iter().map(bits).collect::<Vec<_>>(),
                    "round {round}, {}",
                    path.name()
                );
            }
            assert_eq!(first.len(), reference.len());
            for (a, b) in first.iter().zip(&reference) {
                assert_eq!((a.label, a.pixels, a.bbox), (b.label, b.pixels, b.bbox), "round {round}");
                let pairs = a.normal.iter().zip(&b.normal).chain(a.centroid.iter().zip(&b.centroid));
                for (x, y) in pairs.chain([(&a.d, &b.d)]) {
                    assert!(close(*x, *y, 1e-9), "round {round}, label {}: {a:?} vs {b:?}", a.label);
                }
                // The one-pass residual is a difference of sums: exact to rounding of the squared coordinates.
                let scale = 1.0 + dot(b.centroid, b.centroid);
                let sq = (a.rms * a.rms - b.rms * b.rms).abs() / scale;
                let agree = if a.rms.is_nan() { b.rms.is_nan() } else { sq <= 1e-12 };
                assert!(agree, "round {round}: {a:?} vs {b:?}");
                compared += usize::from(a.normal[0].is_finite());
            }
        }
        assert!(compared > 100, "{compared} planes compared");
    }

    #[test]
    fn recovers_a_known_pinhole_plane() {
        let cam = Camera::Pinhole { fx: 500.0, fy: 480.0, cx: 31.5, cy: 23.5, depth_scale: 1.0 };
        let len = (0.2f64 * 0.2 + 0.3 * 0.3 + 1.0).sqrt();
        // Facing the camera: n points from the plane toward the origin, so n · X = d < 0.
        let n = [0.2 / len, -0.3 / len, -1.0 / len];
        let d = -2.5;
        let range = pinhole_plane(cam, n, d, 64, 48);
        let mut labels = Grid::from_vec(64, 48, vec![1u32; 64 * 48]).unwrap();
        labels[(0, 0)] = 0;
        let p = planes(&range, &labels, &cam);
        assert_eq!(p.len(), 1);
        let p = &p[0];
        assert_eq!((p.label, p.pixels, p.bbox), (1, 64 * 48 - 1, [0, 0, 63, 47]));
        for k in 0..3 {
            assert!((p.normal[k] - n[k]).abs() < 1e-6, "{:?} vs {n:?}", p.normal);
        }
        assert!((p.d - d).abs() < 1e-5, "{}", p.d);
        // f32 depths: residuals are the rounding of Z (about 1e-7 m).
        assert!(p.rms < 1e-6, "{}", p.rms);
        assert!((dot(p.normal, p.centroid) - p.d).abs() < 1e-12);
    }

    #[test]
    fn grid_plane_with_known_residual_and_several_regions() {
        // Two regions: v = 0.5x − 0.25y + 10 (one pixel without data) on the left, v = 40 ± e (a checkerboard of
        // offsets) on the right.
        let (w, h, e) = (20u32, 10u32, 0.125f32);
        let mut data = Vec::new();
        let mut lab = Vec::new();
        for y in 0..h {
            for x in 0..w {
                if x < 10 {
                    data.push(if x == 5 && y == 5 {
                        f32::NAN
                    } else {
                        0.5 * x as f32 - 0.25 * y as f32 + 10.0
                    });
                    lab.push(7);
                } else {
                    data.push(if (x + y) % 2 == 0 { 40.0 + e } else { 40.0 - e });
                    lab.push(3);
                }
            }
        }
        let range = Grid::from_vec(w, h, data).unwrap();
        let labels = Grid::from_vec(w, h, lab).unwrap();
        let p = planes(&range, &labels, &Camera::Grid);
        assert_eq!(p.iter().map(|p| p.label).collect::<Vec<_>>(), [3, 7]);
        // The flat region: normal (0, 0, −1) faces the grid's sensor direction, d = −40, residuals ±e.
        assert_eq!(p[0].normal, [0.0, 0.0, -1.0]);
        assert_eq!((p[0].d, p[0].rms, p[0].pixels, p[0].bbox), (-40.0, f64::from(e), 100, [10, 0, 19, 9]));
        // The tilted one: 0.5x − 0.25y − v = −10, normalised; the pixel without data counts as a pixel only.
        let len = (0.25f64 + 0.0625 + 1.0).sqrt();
        let n = [0.5 / len, -0.25 / len, -1.0 / len];
        for k in 0..3 {
            assert!((p[1].normal[k] - n[k]).abs() < 1e-12, "{:?}", p[1].normal);
        }
        assert!(p[1].rms < 1e-12, "{}", p[1].rms);
        assert!((p[1].d - (-10.0 / len)).abs() < 1e-12, "{}", p[1].d);
        assert_eq!((p[1].pixels, p[1].bbox), (100, [0, 0, 9, 9]));
    }

    #[test]
    fn tiny_regions_have_no_plane() {
        let range = Grid::from_vec(3, 1, vec![1.0, 2.0, f32::NAN]).unwrap();
        let labels = Grid::from_vec(3, 1, vec![0, 5, 5]).unwrap();
        let p = planes(&range, &labels, &Camera::Grid);
        assert_eq!((p.len(), p[0].pixels, p[0].bbox), (1, 2, [1, 0, 2, 0]));
        assert!(p[0].normal[0].is_nan() && p[0].d.is_nan());
        assert_eq!(p[0].centroid, [1.0, 0.0, 2.0]);
    }

    #[test]
    fn eigenvector_of_a_diagonal_and_a_rotated_matrix() {
        assert_eq!(
            smallest_eigenvector([[3.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 2.0]]),
            [0.0, 1.0, 0.0]
        );
        // Eigenvalues 1, 2, 3 with the smallest along (1, 1, 0)/√2.
        let m = [[1.5, -0.5, 0.0], [0.0, 1.5, 0.0], [0.0, 0.0, 3.0]];
        let n = smallest_eigenvector(m);
        let r = std::f64::consts::FRAC_1_SQRT_2;
        assert!((n[0].abs() - r).abs() < 1e-12 && (n[1].abs() - r).abs() < 1e-12 && n[2].abs() < 1e-12);
    }
}
