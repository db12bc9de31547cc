//! The final segmentation from the relaxed edge map (SPEC §3.4 step 4).

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rangeimage::{Camera, EdgeMap, Grid, LabelImage, RangeImage, Region};

/// The `[segment]` parameters of [`final_segmentation`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SegmentParams {
    /// Connected components (of core pixels) smaller than this are dropped (their pixels are
    /// then filled from adjacent regions like edge pixels).
    pub min_region_px: u32,
    /// Core pixels, whose components seed the regions, are the valid pixels farther than this
    /// from every edge pixel (Euclidean); 0 = every non-edge pixel. A positive value closes gaps
    /// up to about twice as wide in the edge contours, which Canny edges and pruned borders have.
    pub gap_close_px: f64,
}

impl Default for SegmentParams {
    fn default() -> Self {
        Self { min_region_px: 50, gap_close_px: 2.0 }
    }
}

impl SegmentParams {
    /// Checks the values; the error names the offending field.
    pub fn validate(&self) -> Result<(), String> {
        if self.min_region_px == 0 {
            return Err("segment.min_region_px must be ≥ 1".to_owned());
        }
        if !(self.gap_close_px.is_finite() && (0.0..=64.0).contains(&self.gap_close_px)) {
            return Err(format!("segment.gap_close_px must be in 0..=64, got {}", self.gap_close_px));
        }
        Ok(())
    }
}

/// A fitted 3D plane `normal · p + offset = 0` with the statistics of its support.
#[derive(Debug, Clone, Copy)]
struct Plane {
    normal: [f64; 3],
    offset: f64,
    rms: f64,
}

impl Plane {
    fn residual(&self, p: [f64; 3]) -> f64 {
        (self.normal[0] * p[0] + self.normal[1] * p[1] + self.normal[2] * p[2] + self.offset).abs()
    }
}

/// Least-squares plane through `pts` (smallest eigenvector of the scatter matrix), with the
/// normal oriented toward the sensor.
fn fit_plane(pts: &[[f64; 3]], camera: &Camera) -> Plane {
    let n = pts.len().max(1) as f64;
    let mut c = [0.0f64; 3];
    for p in pts {
        for i in 0..3 {
            c[i] += p[i];
        }
    }
    c = c.map(|v| v / n);
    let mut m = Matrix3::<f64>::zeros();
    for p in pts {
        let d = Vector3::new(p[0] - c[0], p[1] - c[1], p[2] - c[2]);
        m += d * d.transpose();
    }
    let eig = SymmetricEigen::new(m);
    let mut k = 0;
    for i in 1..3 {
        if eig.eigenvalues[i] < eig.eigenvalues[k] {
            k = i;
        }
    }
    let v = eig.eigenvectors.column(k);
    let len = v.norm();
    let mut normal = if len > 0.0 { [v[0] / len, v[1] / len, v[2] / len] } else { [0.0, 0.0, 1.0] };
    let toward = camera.toward_sensor(c);
    if normal[0] * toward[0] + normal[1] * toward[1] + normal[2] * toward[2] < 0.0 {
        normal = normal.map(|x| -x);
    }
    let offset = -(normal[0] * c[0] + normal[1] * c[1] + normal[2] * c[2]);
    let mut plane = Plane { normal, offset, rms: 0.0 };
    let ss: f64 = pts.iter().map(|&p| plane.residual(p).powi(2)).sum();
    plane.rms = (ss / n).sqrt();
    plane
}

const NBR8: [(i64, i64); 8] = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)];

/// Labels the image from the final edge map: 4-connected components of valid core pixels
/// (non-edge pixels farther than `gap_close_px` from every edge pixel; with 0, all non-edge
/// pixels), components under `min_region_px` dropped, then every remaining valid unlabelled pixel
/// (edge pixels, the margin around them, dropped components) given to the 8-adjacent region whose plane fits its 3D point
/// best, ring by ring outward from the regions (each ring decided from the previous rings only,
/// ties to the smaller label, so the result does not depend on visiting order). Valid pixels
/// not connected to any region stay 0; NaN pixels always stay 0.
///
/// Labels are consecutive from 1 in raster order of first appearance. Each [`Region`] carries
/// its final size, and the plane (unit normal toward the sensor, offset, RMS residual) fitted in
/// 3D through `camera.point` on its component's core pixels only (edge pixels include mixed
/// pixels at jumps, which would bias the fit). `mean_k` is `NaN`: curvature is not an input here.
///
/// # Panics
/// If `range` and `edges` differ in size.
pub fn final_segmentation(
    range: &RangeImage,
    camera: &Camera,
    edges: &EdgeMap,
    params: &SegmentParams,
) -> (LabelImage, Vec<Region>) {
    let _s = tracing::info_span!("final_segmentation", w = range.width(), h = range.height()).entered();
    assert!(range.same_size(edges), "relax::final_segmentation: range and edges differ in size");
    let (w, h) = (range.width() as usize, range.height() as usize);
    let r = range.as_slice();
    let e = edges.as_slice();
    let valid: Vec<bool> = r.iter().map(|v| v.is_finite()).collect();
    // "Edge" below means "not a core pixel": an edge pixel or within gap_close_px of one.
    let e: Vec<bool> = if params.gap_close_px > 0.0 {
        let g2 = params.gap_close_px * params.gap_close_px;
        crate::edt::squared_edt(edges).as_slice().iter().map(|&d| d <= g2).collect()
    } else {
        e.to_vec()
    };
    let point = |i: usize| camera.point((i % w) as f64, (i / w) as f64, f64::from(r[i]));

    // 1. 4-connected components of valid non-edge pixels, in raster order of their first pixel.
    let mut comp = vec![0u32; w * h];
    let mut members: Vec<Vec<usize>> = Vec::new();
    let mut stack = Vec::new();
    for s in 0..w * h {
        if !valid[s] || e[s] || comp[s] != 0 {
            continue;
        }
        let id = members.len() as u32 + 1;
        let mut list = Vec::new();
        comp[s] = id;
        stack.push(s);
        while let Some(i) = stack.pop() {
            list.push(i);
            let (x, y) = (i % w, i / w);
            let mut visit = |j: usize| {
                if valid[j] && !e[j] && comp[j] == 0 {
                    comp[j] = id;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        list.sort_unstable();
        members.push(list);
    }

    // 2. Drop small components; fit a plane to every kept one.
    let mut planes: Vec<Option<Plane>> = Vec::with_capacity(members.len());
    for list in &members {
        if (list.len() as u64) < u64::from(params.min_region_px) {
            planes.push(None);
            for &i in list {
                comp[i] = 0;
            }
        } else {
            let pts: Vec<[f64; 3]> = list.iter().filter_map(|&i| point(i)).collect();
            planes.push(Some(fit_plane(&pts, camera)));
        }
    }

    // 3. Fill unlabelled valid pixels ring by ring.
    let mut in_ring = vec![false; w * h];
    let mut ring: Vec<usize> = Vec::new();
    let neighbours = |i: usize| {
        let (x, y) = ((i % w) as i64, (i / w) as i64);
        NBR8.iter().filter_map(move |&(dx, dy)| {
            let (nx, ny) = (x + dx, y + dy);
            (nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64).then(|| ny as usize * w + nx as usize)
        })
    };
    for i in 0..w * h {
        if valid[i] && comp[i] == 0 && neighbours(i).any(|j| comp[j] != 0) {
            in_ring[i] = true;
            ring.push(i);
        }
    }
    let mut assign = Vec::new();
    let mut rings = 0u32;
    while !ring.is_empty() {
        rings += 1;
        assign.clear();
        for &i in &ring {
            let p = point(i).expect("ring pixels are valid");
            let mut best: Option<(f64, u32)> = None;
            for j in neighbours(i) {
                let l = comp[j];
                if l == 0 {
                    continue;
                }
                let plane = planes[l as usize - 1].as_ref().expect("labelled pixels belong to kept regions");
                let res = plane.residual(p);
                if best.is_none_or(|(br, bl)| res < br || (res == br && l < bl)) {
                    best = Some((res, l));
                }
            }
            assign.push(best.expect("ring pixels touch a region").1);
        }
        for (&i, &l) in ring.iter().zip(&assign) {
            comp[i] = l;
        }
        let mut next = Vec::new();
        for &i in &ring {
            for j in neighbours(i) {
                if valid[j] && comp[j] == 0 && !in_ring[j] {
                    in_ring[j] = true;
                    next.push(j);
                }
            }
        }
        next.sort_unstable();
        ring = next;
    }
    tracing::debug!(components = members.len(), rings, "filled");

    // 4. Consecutive labels in raster order; region statistics.
    let mut map = vec![0u32; members.len() + 1];
    let mut sizes: Vec<u32> = Vec::new();
    let mut order: Vec<u32> = Vec::new();
    let mut labels = vec![0u32; w * h];
    for i in 0..w * h {
        let c = comp[i] as usize;
        if c == 0 {
            continue;
        }
        if map[c] == 0 {
            order.push(c as u32);
            sizes.push(0);
            map[c] = order.len() as u32;
        }
        labels[i] = map[c];
        sizes[map[c] as usize - 1] += 1;
    }
    let regions = order
        .iter()
        .zip(&sizes)
        .enumerate()
        .map(|(k, (&c, &size_px))| {
            let plane = planes[c as usize - 1].expect("kept region");
            Region {
                label: k as u32 + 1,
                size_px,
                mean_k: f32::NAN,
                normal: plane.normal.map(|v| v as f32),
                offset: plane.offset as f32,
                rms_residual: plane.rms as f32,
            }
        })
        .collect();
    let labels = Grid::from_vec(w as u32, h as u32, labels).expect("size matches");
    (labels, regions)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// 40×30: left plane v = 100 + 0.5x (x ≤ 19), right plane v = 200 − 2x (x ≥ 20), a two-pixel
    /// edge line at x = 19, 20, and a NaN block in the top-left corner.
    fn two_planes() -> (RangeImage, EdgeMap) {
        let range = Grid::from_fn(40, 30, |x, y| {
            if x < 3 && y < 4 {
                f32::NAN
            } else if x <= 19 {
                100.0 + 0.5 * x as f32
            } else {
                200.0 - 2.0 * x as f32
            }
        });
        let edges = Grid::from_fn(40, 30, |x, _| x == 19 || x == 20);
        (range, edges)
    }

    #[test]
    fn two_planes_split_at_the_edge_line() {
        for gap_close_px in [0.0, 2.0] {
            two_planes_split(gap_close_px);
        }
    }

    #[test]
    fn gap_closing_separates_regions_across_a_broken_contour() {
        let (range, mut edges) = two_planes();
        for y in 10..12 {
            edges[(19, y)] = false;
            edges[(20, y)] = false;
        }
        let open = SegmentParams { gap_close_px: 0.0, ..SegmentParams::default() };
        let (_, regions) = final_segmentation(&range, &Camera::Grid, &edges, &open);
        assert_eq!(regions.len(), 1, "without gap closing the two faces leak into one component");
        let (labels, regions) = final_segmentation(&range, &Camera::Grid, &edges, &SegmentParams::default());
        assert_eq!(regions.len(), 2);
        for y in 0..30 {
            assert_eq!(labels[(10, y)], 1);
            assert_eq!(labels[(30, y)], 2);
            assert_eq!(labels[(19, y)], 1, "gap pixel (19, {y}) fits the left plane");
            assert_eq!(labels[(20, y)], 2, "gap pixel (20, {y}) fits the right plane");
        }
    }

    fn two_planes_split(gap_close_px: f64) {
        let (range, edges) = two_planes();
        let params = SegmentParams { gap_close_px, ..SegmentParams::default() };
        let (labels, regions) = final_segmentation(&range, &Camera::Grid, &edges, &params);
        assert_eq!(regions.len(), 2);
        for (x, y, &l) in labels.enumerate() {
            let want = if range[(x, y)].is_nan() {
                0
            } else if x <= 19 {
                1
            } else {
                2
            };
            assert_eq!(l, want, "pixel ({x}, {y})");
        }
        assert_eq!(regions[0].label, 1);
        assert_eq!(regions[0].size_px, 20 * 30 - 12);
        assert_eq!(regions[1].size_px, 20 * 30);
        for r in &regions {
            let n = r.normal;
            assert_relative_eq!((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt(), 1.0, epsilon = 1e-5);
            // Camera::Grid looks along −z: normals point toward the sensor.
            assert!(n[2] < 0.0, "{r:?}");
            assert!(r.rms_residual < 1e-3, "{r:?}");
            assert!(r.mean_k.is_nan());
        }
        // Left plane: v − 0.5x − 100 = 0 → normal ∝ (−0.5, 0, 1), flipped toward −z.
        let n = regions[0].normal;
        assert_relative_eq!(n[0] / n[2], -0.5, epsilon = 1e-4);
    }

    #[test]
    fn thick_edges_fill_by_best_plane_and_small_components_are_dropped() {
        // Edge band x = 16..=23 (8 px), an isolated 2×2 non-edge hole in it at (18..20, 10..12).
        let range =
            Grid::from_fn(
                40,
                30,
                |x, _| if x <= 19 { 100.0 + 0.5 * x as f32 } else { 200.0 - 2.0 * x as f32 },
            );
        let edges = Grid::from_fn(40, 30, |x, y| {
            (16..=23).contains(&x) && !((18..20).contains(&x) && (10..12).contains(&y))
        });
        let (labels, regions) = final_segmentation(
            &range,
            &Camera::Grid,
            &edges,
            &SegmentParams { min_region_px: 10, gap_close_px: 0.0 },
        );
        assert_eq!(regions.len(), 2);
        for (x, y, &l) in labels.enumerate() {
            assert_eq!(l, if x <= 19 { 1 } else { 2 }, "pixel ({x}, {y})");
        }
        assert_eq!(regions.iter().map(|r| r.size_px).sum::<u32>(), 40 * 30);
    }

    #[test]
    fn isolated_and_invalid_pixels_stay_unlabelled() {
        // Everything is edge: no region at all.
        let range = Grid::new(10, 10, 50.0f32);
        let (labels, regions) =
            final_segmentation(&range, &Camera::ABW0, &Grid::new(10, 10, true), &SegmentParams::default());
        assert!(regions.is_empty());
        assert!(labels.as_slice().iter().all(|&l| l == 0));
        // An all-NaN image.
        let nan = Grid::new(6, 5, f32::NAN);
        let (labels, regions) =
            final_segmentation(&nan, &Camera::ABW0, &Grid::new(6, 5, false), &SegmentParams::default());
        assert!(regions.is_empty() && labels.as_slice().iter().all(|&l| l == 0));
    }

    #[test]
    fn labels_are_consecutive_in_raster_order() {
        // Three vertical stripes separated by edge columns; the middle one starts lower.
        let range = Grid::from_fn(30, 20, |x, _| 80.0 + x as f32);
        let edges = Grid::from_fn(30, 20, |x, y| x == 9 || x == 19 || ((10..19).contains(&x) && y < 5));
        let (labels, regions) = final_segmentation(
            &range,
            &Camera::ABW0,
            &edges,
            &SegmentParams { min_region_px: 5, gap_close_px: 0.0 },
        );
        assert_eq!(regions.iter().map(|r| r.label).collect::<Vec<_>>(), vec![1, 2, 3]);
        let mut first = Vec::new();
        for &l in labels.as_slice() {
            if l != 0 && !first.contains(&l) {
                first.push(l);
            }
        }
        assert_eq!(first, vec![1, 2, 3]);
        assert_eq!(regions.iter().map(|r| r.size_px).sum::<u32>(), 30 * 20);
        assert_ne!(labels[(0, 0)], labels[(25, 10)]);
        assert_ne!(labels[(12, 10)], labels[(25, 10)]);
        // ABW normals point toward the scanner (+z).
        assert!(regions.iter().all(|r| r.normal[2] > 0.0));
    }
}
