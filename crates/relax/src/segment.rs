//! The final segmentation from the relaxed edge map (docs/method.md §3.4 step 4), optionally guided by
//! the region-growing labels and merged where the relaxed edges do not support a border.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rangeimage::{Camera, EdgeMap, Grid, LabelImage, RangeImage, Region};
use std::collections::BTreeMap;

/// How [`final_segmentation`] forms its regions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SegmentMode {
    /// The specification taken literally: connected components of valid non-edge pixels, filled by best plane.
    Components,
    /// Components that also never cross a region-growing border, then adjacent regions merged
    /// where the relaxed edges do not support their border and their planes agree.
    Regions,
}

/// The `[segment]` parameters of [`final_segmentation`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SegmentParams {
    /// Region formation (`regions` needs the region-growing labels; without them it falls back
    /// to `components`).
    pub mode: SegmentMode,
    /// Connected components (of core pixels) smaller than this are dropped (their pixels are
    /// then filled from adjacent regions like edge pixels). The default equals region growing's
    /// `min_region_px`: a piece cut off by edges needs the support a grown region needs.
    pub min_region_px: u32,
    /// Core pixels, whose components seed the regions, are the valid pixels farther than this
    /// from every edge pixel (Euclidean); 0 = every non-edge pixel. A positive value closes gaps
    /// up to about twice as wide in the edge contours, which Canny edges and pruned borders have,
    /// but also drops the thin strips between parallel C1 and C2 lines and leaves every pixel of the
    /// margin to the plane-residual fill; in `regions` mode the region-growing borders already
    /// close the contours, and 0 scores better on the synthetic, real ABW and NYU images.
    pub gap_close_px: f64,
    /// `regions` mode: pixels that region growing left unlabelled (0) may be core pixels too,
    /// connected only among themselves (so faces region growing missed can still be found);
    /// `false` = they are only filled from adjacent regions.
    pub unlabelled_core: bool,
    /// `regions` mode: two adjacent regions may merge only if less than this fraction of their
    /// border pixels lie within 1 px (8-neighbourhood) of an edge pixel. In 0..=1.
    pub min_border_support: f64,
    /// `regions` mode: two adjacent pieces of one region-growing region merge when their planes
    /// agree, however strongly the edges support the border between them (edges inside a face
    /// must not split it; a split needs a change of plane). `false` = only weakly supported
    /// borders are merge candidates.
    pub merge_within_region: bool,
    /// `regions` mode, `merge_within_region`: two pieces of one region-growing region over a
    /// supported border merge only if the RMS distance of each one's core points to the other's
    /// plane is at most this multiple of its RMS distance to its own plane (they lie on one plane
    /// within noise; a small step between parallel faces is a real border). ≥ 1.
    pub within_max_rms_ratio: f64,
    /// `regions` mode: largest angle between the two regions' 3D plane normals for a merge.
    pub merge_max_angle_deg: f64,
    /// `regions` mode: largest RMS distance of each region's core points to the other region's
    /// plane for a merge, in sensor units (ABW: about 1.3 units per range step).
    pub merge_max_residual: f64,
    /// Largest 3D distance of a filled pixel to the plane of the region it joins, in sensor units
    /// (0 = no limit, the specification taken literally). Farther pixels stay 0, so a small face that region growing
    /// dropped is not swallowed by its neighbour (which would make that neighbour an
    /// under-segmentation of both).
    pub fill_max_residual: f64,
    /// With `fill_max_residual` > 0, the limit of a region is the larger of `fill_max_residual` and this
    /// multiple of the RMS distance of its core points to its plane (0 = `fill_max_residual` alone): a surface
    /// a plane fits only roughly (8-bit staircases, depth encodings that bend planes) keeps its pixels.
    pub fill_rms_ratio: f64,
}

impl Default for SegmentParams {
    fn default() -> Self {
        Self {
            mode: SegmentMode::Regions,
            min_region_px: 200,
            gap_close_px: 0.0,
            unlabelled_core: true,
            min_border_support: 0.3,
            merge_within_region: true,
            within_max_rms_ratio: 1.5,
            merge_max_angle_deg: 10.0,
            merge_max_residual: 2.0,
            fill_max_residual: 3.0,
            fill_rms_ratio: 3.0,
        }
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
        if !(0.0..=1.0).contains(&self.min_border_support) {
            return Err(format!(
                "segment.min_border_support must be in 0..=1, got {}",
                self.min_border_support
            ));
        }
        if !(self.within_max_rms_ratio.is_finite() && self.within_max_rms_ratio >= 1.0) {
            return Err(format!(
                "segment.within_max_rms_ratio must be finite and ≥ 1, got {}",
                self.within_max_rms_ratio
            ));
        }
        if !(0.0..=90.0).contains(&self.merge_max_angle_deg) {
            return Err(format!(
                "segment.merge_max_angle_deg must be in 0..=90, got {}",
                self.merge_max_angle_deg
            ));
        }
        if !(self.fill_rms_ratio.is_finite() && self.fill_rms_ratio >= 0.0) {
            return Err(format!(
                "segment.fill_rms_ratio must be finite and ≥ 0, got {}",
                self.fill_rms_ratio
            ));
        }
        if !(self.fill_max_residual.is_finite() && self.fill_max_residual >= 0.0) {
            return Err(format!(
                "segment.fill_max_residual must be finite and ≥ 0, got {}",
                self.fill_max_residual
            ));
        }
        if !(self.merge_max_residual.is_finite() && self.merge_max_residual >= 0.0) {
            return Err(format!(
                "segment.merge_max_residual must be finite and ≥ 0, got {}",
                self.merge_max_residual
            ));
        }
        Ok(())
    }
}

/// First and second moments of a 3D point set.
#[derive(Debug, Clone, Copy, Default)]
struct Moments {
    n: f64,
    s: [f64; 3],
    /// xx, xy, xz, yy, yz, zz.
    ss: [f64; 6],
}

impl Moments {
    fn add(&mut self, p: [f64; 3]) {
        self.n += 1.0;
        for k in 0..3 {
            self.s[k] += p[k];
        }
        let [x, y, z] = p;
        for (acc, v) in self.ss.iter_mut().zip([x * x, x * y, x * z, y * y, y * z, z * z]) {
            *acc += v;
        }
    }

    fn merge(&mut self, o: &Moments) {
        self.n += o.n;
        for k in 0..3 {
            self.s[k] += o.s[k];
        }
        for k in 0..6 {
            self.ss[k] += o.ss[k];
        }
    }

    fn mean(&self) -> [f64; 3] {
        let n = self.n.max(1.0);
        self.s.map(|v| v / n)
    }

    /// Covariance matrix (divided by n).
    fn cov(&self) -> Matrix3<f64> {
        let n = self.n.max(1.0);
        let c = self.mean();
        let e = |k: usize, a: usize, b: usize| self.ss[k] / n - c[a] * c[b];
        let (xx, xy, xz, yy, yz, zz) =
            (e(0, 0, 0), e(1, 0, 1), e(2, 0, 2), e(3, 1, 1), e(4, 1, 2), e(5, 2, 2));
        Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
    }

    /// Mean squared distance of the points to `plane`.
    fn mean_sq_residual(&self, plane: &Plane) -> f64 {
        let nv = Vector3::from(plane.normal);
        let c = self.mean();
        let along = plane.normal[0] * c[0] + plane.normal[1] * c[1] + plane.normal[2] * c[2] + plane.offset;
        ((nv.transpose() * self.cov() * nv)[0]).max(0.0) + along * along
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

/// Least-squares plane of the points summarised by `m` (smallest eigenvector of the
/// covariance), with the normal oriented toward the sensor.
fn fit_plane(m: &Moments, camera: &Camera) -> Plane {
    let c = m.mean();
    let eig = SymmetricEigen::new(m.cov());
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
    plane.rms = m.mean_sq_residual(&plane).sqrt();
    plane
}

fn find(parent: &mut [u32], mut a: u32) -> u32 {
    while parent[a as usize] != a {
        parent[a as usize] = parent[parent[a as usize] as usize];
        a = parent[a as usize];
    }
    a
}

const NBR8: [(i64, i64); 8] = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)];

/// Labels the image from the final edge map `edges` (C = C1 ∪ C2).
///
/// 1. Core pixels: valid pixels farther than `gap_close_px` from every edge pixel (with 0, all
///    non-edge valid pixels); in `regions` mode with `unlabelled_core = false` also labelled
///    (≠ 0) in `regions`.
/// 2. 4-connected components of core pixels; in `regions` mode two neighbours connect only if
///    their region-growing labels are equal, so no component crosses a region-growing border
///    (but edges inside a region may split it). Components under `min_region_px` are dropped.
/// 3. Every remaining valid unlabelled pixel (edge pixels, the margin around them, dropped
///    components, pixels region growing left unlabelled) is given to the 8-adjacent region
///    whose plane fits its 3D point best, ring by ring outward from the regions (each ring
///    decided from the previous rings only, ties to the smaller label, so the result does not
///    depend on visiting order). A pixel farther than `fill_max_residual` (if > 0) from that
///    best plane when its ring comes stays 0 and passes the fill on no further. Valid pixels not
///    connected to any region stay 0; NaN pixels always stay 0.
/// 4. `regions` mode only: adjacent regions whose border is supported by C on less than
///    `min_border_support` of its pixels (a border pixel is supported if it is within 1 px,
///    8-neighbourhood, of an edge pixel) and whose planes agree (normal angle ≤
///    `merge_max_angle_deg`, RMS distance of each one's core points to the other's plane ≤
///    `merge_max_residual`) are merged: union-find over the adjacent pairs in sorted order,
///    planes refitted on merge, passes repeated until none merges (support is per original
///    pair; the plane test uses the current merged groups). With `merge_within_region`, two
///    adjacent pieces of one region-growing region (label ≠ 0) are candidates whatever the
///    support, if their planes agree as above and, for a supported border, each piece's RMS
///    distance to the other's plane is at most `within_max_rms_ratio` times its own RMS: edges
///    inside a face split it only where the geometry changes.
///
/// `regions = None` makes `regions` mode behave as `components`.
///
/// Labels are consecutive from 1 in raster order of first appearance. Each [`Region`] carries
/// its final size, and the plane (unit normal toward the sensor, offset, RMS residual) fitted in
/// 3D through `camera.point` on its core pixels only (edge pixels include mixed pixels at jumps,
/// which would bias the fit). `mean_k` is `NaN`: curvature is not an input here.
///
/// # Panics
/// If `range`, `edges` and `regions` differ in size.
pub fn final_segmentation(
    range: &RangeImage,
    camera: &Camera,
    edges: &EdgeMap,
    regions: Option<&LabelImage>,
    params: &SegmentParams,
) -> (LabelImage, Vec<Region>) {
    let _s = tracing::info_span!("final_segmentation", w = range.width(), h = range.height()).entered();
    assert!(range.same_size(edges), "relax::final_segmentation: range and edges differ in size");
    if let Some(l) = regions {
        assert!(range.same_size(l), "relax::final_segmentation: range and regions differ in size");
    }
    let guide = match params.mode {
        SegmentMode::Regions => regions.map(|l| l.as_slice()),
        SegmentMode::Components => None,
    };
    let (w, h) = (range.width() as usize, range.height() as usize);
    let r = range.as_slice();
    // Core pixels: valid, not an edge pixel and not within gap_close_px of one.
    let mut core: Vec<bool> = if params.gap_close_px > 0.0 {
        rangeimage::distance::within(edges, params.gap_close_px).into_vec()
    } else {
        edges.as_slice().to_vec()
    };
    for (c, &v) in core.iter_mut().zip(r) {
        *c = !*c & v.is_finite();
    }
    if let (Some(g), false) = (guide, params.unlabelled_core) {
        for (c, &l) in core.iter_mut().zip(g) {
            *c &= l != 0;
        }
    }
    let point = |x: usize, y: usize| camera.point(x as f64, y as f64, f64::from(r[y * w + x]));

    // 1. 4-connected components of core pixels (two neighbours connect only if their guide
    //    labels agree), numbered in raster order of their first pixel.
    let (mut comp, sizes) = components(&core, guide, w, h);
    drop(core);

    // 2. Drop small components; fit a plane to every kept one (moments summed in raster order).
    let keep: Vec<bool> = sizes.iter().map(|&n| u64::from(n) >= u64::from(params.min_region_px)).collect();
    // The region-growing label of each component (all its pixels share one; 0 without a guide).
    let mut comp_guide = vec![0u32; sizes.len()];
    if let Some(g) = guide {
        for (&c, &l) in comp.iter().zip(g) {
            if c != 0 {
                comp_guide[c as usize - 1] = l;
            }
        }
    }
    let mut moments: Vec<Moments> = vec![Moments::default(); sizes.len()];
    // Runs of one component are summed in a local copy of its moments (the same additions in
    // the same order, but in registers).
    let mut cur = 0u32;
    let mut acc = Moments::default();
    for y in 0..h {
        for (x, c) in comp[y * w..(y + 1) * w].iter_mut().enumerate() {
            if *c == 0 {
                continue;
            }
            if !keep[*c as usize - 1] {
                *c = 0;
            } else if let Some(p) = point(x, y) {
                if *c != cur {
                    if cur != 0 {
                        moments[cur as usize - 1] = acc;
                    }
                    cur = *c;
                    acc = moments[cur as usize - 1];
                }
                acc.add(p);
            }
        }
    }
    if cur != 0 {
        moments[cur as usize - 1] = acc;
    }
    let mut planes: Vec<Option<Plane>> =
        moments.iter().zip(&keep).map(|(m, &k)| k.then(|| fit_plane(m, camera))).collect();

    // 3. Fill unlabelled valid pixels ring by ring. Each ring is decided from the labels of the
    //    previous rings only, so the order of pixels within a ring does not matter.
    let mut in_ring = vec![false; w * h];
    let mut ring: Vec<(u32, u32)> = Vec::new();
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
    let fill_limit = params.fill_max_residual;
    let mut assign = Vec::new();
    let mut next = Vec::new();
    let mut rings = 0u32;
    while !ring.is_empty() {
        rings += 1;
        assign.clear();
        for &(x, y) in &ring {
            let (x, y) = (x as usize, y as usize);
            let p = point(x, y).expect("ring pixels are valid");
            let mut best: Option<(f64, u32, f64)> = None;
            let mut last = 0u32;
            for_neighbours(x, y, w, h, |j, _, _| {
                let l = comp[j];
                if l == 0 || l == last {
                    return;
                }
                last = l;
                let plane = planes[l as usize - 1].as_ref().expect("labelled pixels belong to kept regions");
                let res = plane.residual(p);
                if best.is_none_or(|(br, bl, _)| res < br || (res == br && l < bl)) {
                    best = Some((res, l, fill_limit.max(params.fill_rms_ratio * plane.rms)));
                }
            });
            let (res, l, limit) = best.expect("ring pixels touch a region");
            // A pixel too far from every adjacent plane stays 0 (and grows no further ring).
            assign.push(if fill_limit > 0.0 && res > limit { 0 } else { l });
        }
        for (&(x, y), &l) in ring.iter().zip(&assign) {
            comp[y as usize * w + x as usize] = l;
        }
        next.clear();
        for (&(x, y), _) in ring.iter().zip(&assign).filter(|&(_, &l)| l != 0) {
            for_neighbours(x as usize, y as usize, w, h, |j, nx, ny| {
                if comp[j] == 0 && !in_ring[j] && r[j].is_finite() {
                    in_ring[j] = true;
                    next.push((nx as u32, ny as u32));
                }
            });
        }
        std::mem::swap(&mut ring, &mut next);
    }
    tracing::debug!(components = planes.len(), rings, "filled");

    // 4. Merge adjacent regions over unsupported borders with agreeing planes.
    let mut parent: Vec<u32> = (0..=planes.len() as u32).collect();
    if guide.is_some() {
        merge_unsupported(
            &comp,
            &comp_guide,
            edges,
            w,
            h,
            &mut parent,
            &mut moments,
            &mut planes,
            camera,
            params,
        );
    }

    // 5. Consecutive labels in raster order; region statistics.
    let root: Vec<u32> = (0..=planes.len() as u32).map(|c| find(&mut parent, c)).collect();
    let mut map = vec![0u32; planes.len() + 1];
    let mut order: Vec<u32> = Vec::new();
    let mut labels = comp;
    for l in &mut labels {
        if *l == 0 {
            continue;
        }
        let c = root[*l as usize] as usize;
        if map[c] == 0 {
            order.push(c as u32);
            map[c] = order.len() as u32;
        }
        *l = map[c];
    }
    let mut sizes = vec![0u32; order.len()];
    count_labels(&labels, &mut sizes);
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

/// Calls `f(index, x, y)` for every in-image 8-neighbour of (x, y).
#[inline(always)]
fn for_neighbours(x: usize, y: usize, w: usize, h: usize, mut f: impl FnMut(usize, usize, usize)) {
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

/// 4-connected components of the `core` pixels, two neighbours connected only if their
/// `guide` labels are equal: (component per pixel, 0 = none, numbered from 1 in raster order
/// of each component's first pixel; component sizes). Two-pass union-find labelling.
fn components(core: &[bool], guide: Option<&[u32]>, w: usize, h: usize) -> (Vec<u32>, Vec<u32>) {
    let mut lab = vec![0u32; w * h];
    // Provisional labels from 1; parent[l] ≤ l, so roots are the smallest label of a set.
    let mut parent: Vec<u32> = vec![0];
    // Runs of core pixels with one guide label; a run connects to the labels right above it.
    for y in 0..h {
        let row = y * w;
        let mut x = 0;
        while x < w {
            if !core[row + x] {
                x += 1;
                continue;
            }
            let g = guide.map_or(0, |g| g[row + x]);
            let mut e = x + 1;
            while e < w && core[row + e] && guide.is_none_or(|gg| gg[row + e] == g) {
                e += 1;
            }
            let mut l = 0u32;
            if y > 0 {
                let mut last = 0u32;
                for (k, &u) in lab[row - w + x..row - w + e].iter().enumerate() {
                    // All pixels of a label share one guide label, so skipping repeats is exact.
                    if u == 0 || u == last {
                        continue;
                    }
                    last = u;
                    if guide.is_some_and(|gg| gg[row - w + x + k] != g) {
                        continue;
                    }
                    let ru = find(&mut parent, u);
                    l = if l == 0 || l == ru {
                        ru
                    } else {
                        let (lo, hi) = (l.min(ru), l.max(ru));
                        parent[hi as usize] = lo;
                        lo
                    };
                }
            }
            if l == 0 {
                parent.push(parent.len() as u32);
                l = parent.len() as u32 - 1;
            }
            lab[row + x..row + e].fill(l);
            x = e;
        }
    }
    // A set's root is its smallest provisional label, the one created at its first pixel in
    // raster order; so numbering the roots in label order numbers the components in raster
    // order of their first pixel. parent[l] < l for non-roots, so one ascending pass resolves
    // every label.
    let mut id = vec![0u32; parent.len()];
    let mut n = 0u32;
    for l in 1..parent.len() {
        let p = parent[l] as usize;
        id[l] = if p == l {
            n += 1;
            n
        } else {
            id[p]
        };
    }
    for l in &mut lab {
        *l = id[*l as usize];
    }
    let mut sizes = vec![0u32; n as usize];
    count_labels(&lab, &mut sizes);
    (lab, sizes)
}

/// Adds the number of pixels of each label `l ≥ 1` to `sizes[l − 1]` (run by run, so that a
/// long run costs no chain of increments through memory).
fn count_labels(labels: &[u32], sizes: &mut [u32]) {
    let (mut cur, mut n) = (0u32, 0u32);
    for &l in labels {
        if l != cur {
            if cur != 0 {
                sizes[cur as usize - 1] += n;
            }
            (cur, n) = (l, 0);
        }
        n += 1;
    }
    if cur != 0 {
        sizes[cur as usize - 1] += n;
    }
}

/// Step 4 of [`final_segmentation`]: union-find merging of adjacent components (labels in
/// `comp`, 1-based into `moments`/`planes`, region-growing label of each in `comp_guide`) over
/// borders weakly supported by `edges` or, with `merge_within_region`, inside one
/// region-growing region. Roots are
/// the smaller label; the root's moments and plane become the merged group's.
#[allow(clippy::too_many_arguments)]
fn merge_unsupported(
    comp: &[u32],
    comp_guide: &[u32],
    edges: &EdgeMap,
    w: usize,
    h: usize,
    parent: &mut [u32],
    moments: &mut [Moments],
    planes: &mut [Option<Plane>],
    camera: &Camera,
    params: &SegmentParams,
) {
    let ed = edges.as_slice();
    // Within 1 px (8-neighbourhood) of an edge pixel.
    // Horizontal 3-wide OR per row, then vertical 3-high OR of those rows.
    let mut hor = ed.to_vec();
    for (hrow, erow) in hor.chunks_exact_mut(w.max(1)).zip(ed.chunks_exact(w.max(1))) {
        for x in 1..w {
            hrow[x] |= erow[x - 1];
            hrow[x - 1] |= erow[x];
        }
    }
    let mut near = vec![false; w * h];
    for (y, nrow) in near.chunks_exact_mut(w.max(1)).enumerate() {
        for yy in y.saturating_sub(1)..(y + 2).min(h) {
            for (n, &v) in nrow.iter_mut().zip(&hor[yy * w..(yy + 1) * w]) {
                *n |= v;
            }
        }
    }
    // (smaller label, larger label) → (border pixel count, supported count), over 4-adjacencies.
    let mut pairs: BTreeMap<(u32, u32), (u32, u32)> = BTreeMap::new();
    let mut add = |i: usize, j: usize| {
        let (a, b) = (comp[i], comp[j]);
        if a != 0 && b != 0 && a != b {
            let entry = pairs.entry((a.min(b), a.max(b))).or_insert((0, 0));
            entry.0 += 2;
            entry.1 += u32::from(near[i]) + u32::from(near[j]);
        }
    };
    for y in 0..h {
        let row = y * w;
        for x in 1..w {
            if comp[row + x - 1] != comp[row + x] {
                add(row + x - 1, row + x);
            }
        }
        if y + 1 < h {
            for x in 0..w {
                if comp[row + x] != comp[row + w + x] {
                    add(row + x, row + w + x);
                }
            }
        }
    }
    // Candidates: weakly supported borders, and (with merge_within_region) any border between
    // two pieces of one region-growing region; `weak` tells which.
    let (candidates, weak): (Vec<(u32, u32)>, Vec<bool>) = pairs
        .iter()
        .filter_map(|(&(a, b), &(n, s))| {
            let weak = f64::from(s) < params.min_border_support * f64::from(n);
            let same_region = params.merge_within_region && {
                let g = comp_guide[a as usize - 1];
                g != 0 && g == comp_guide[b as usize - 1]
            };
            (weak || same_region).then_some(((a, b), weak))
        })
        .unzip();
    let k2 = params.within_max_rms_ratio * params.within_max_rms_ratio;
    let cos_max = params.merge_max_angle_deg.to_radians().cos();
    let r2 = params.merge_max_residual * params.merge_max_residual;
    let mut merges = 0u32;
    loop {
        let mut changed = false;
        for (k, &(a, b)) in candidates.iter().enumerate() {
            let (ra, rb) = (find(parent, a), find(parent, b));
            if ra == rb {
                continue;
            }
            let (ia, ib) = (ra as usize - 1, rb as usize - 1);
            let (pa, pb) = (planes[ia].expect("kept region"), planes[ib].expect("kept region"));
            let dot: f64 = (0..3).map(|k| pa.normal[k] * pb.normal[k]).sum();
            let (ea, eb) = (moments[ia].mean_sq_residual(&pb), moments[ib].mean_sq_residual(&pa));
            if dot.abs() < cos_max || ea > r2 || eb > r2 {
                continue;
            }
            // (+1e-12: noise-free pieces of one plane have RMS 0 and rounding-level residuals.)
            if !weak[k] && (ea > k2 * pa.rms * pa.rms + 1e-12 || eb > k2 * pb.rms * pb.rms + 1e-12) {
                // Within one region-growing region over a supported border: merge only pieces
                // that lie on one plane within their own noise.
                continue;
            }
            let (root, other) = (ra.min(rb), ra.max(rb));
            parent[other as usize] = root;
            let m = moments[other as usize - 1];
            moments[root as usize - 1].merge(&m);
            planes[root as usize - 1] = Some(fit_plane(&moments[root as usize - 1], camera));
            changed = true;
            merges += 1;
        }
        if !changed {
            break;
        }
    }
    tracing::debug!(pairs = pairs.len(), candidates = candidates.len(), merges, "merged");
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

    /// A 4×4 patch 20 units in front of a flat 40×30 plane, all of it edge pixels: without a fill
    /// limit the plane's region swallows it, with `fill_max_residual = 3` it stays 0.
    #[test]
    fn fill_limit_leaves_off_plane_pixels_unlabelled() {
        let patch = |x: u32, y: u32| (5..9).contains(&x) && (5..9).contains(&y);
        let range = Grid::from_fn(40, 30, |x, y| if patch(x, y) { 80.0 } else { 100.0 });
        let edges = Grid::from_fn(40, 30, patch);
        let params = SegmentParams { min_region_px: 10, gap_close_px: 0.0, ..SegmentParams::default() };
        for (limit, want) in [(0.0, 1u32), (3.0, 0)] {
            let p = SegmentParams { fill_max_residual: limit, ..params.clone() };
            let (labels, regions) = final_segmentation(&range, &Camera::Grid, &edges, None, &p);
            assert_eq!(regions.len(), 1);
            assert_eq!(labels[(6, 6)], want, "limit {limit}");
            assert_eq!(labels[(20, 20)], 1);
        }
    }

    /// `fill_rms_ratio`: a rough plane (a ±2-unit checker ripple, RMS 2) keeps a pixel 4 units off it that the
    /// absolute limit of 3 alone would leave unlabelled; a pixel 20 units off stays 0 either way.
    #[test]
    fn fill_limit_follows_the_region_scatter() {
        let hole = |x: u32, y: u32| (5..7).contains(&x) && (5..7).contains(&y);
        let far = |x: u32, y: u32| (30..32).contains(&x) && (20..22).contains(&y);
        let range = Grid::from_fn(40, 30, |x, y| {
            let ripple = if (x + y) % 2 == 0 { 2.0 } else { -2.0 };
            if hole(x, y) {
                104.0
            } else if far(x, y) {
                120.0
            } else {
                100.0 + ripple
            }
        });
        let edges = Grid::from_fn(40, 30, |x, y| hole(x, y) || far(x, y));
        let base = SegmentParams { min_region_px: 10, fill_max_residual: 3.0, ..SegmentParams::default() };
        for (ratio, want) in [(0.0, 0u32), (3.0, 1)] {
            let p = SegmentParams { fill_rms_ratio: ratio, ..base.clone() };
            let (labels, _) = final_segmentation(&range, &Camera::Grid, &edges, None, &p);
            assert_eq!(labels[(5, 5)], want, "ratio {ratio}");
            assert_eq!(labels[(30, 20)], 0, "ratio {ratio}");
        }
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
        let (_, regions) = final_segmentation(&range, &Camera::Grid, &edges, None, &open);
        assert_eq!(regions.len(), 1, "without gap closing the two faces leak into one component");
        let closing = SegmentParams { gap_close_px: 2.0, ..SegmentParams::default() };
        let (labels, regions) = final_segmentation(&range, &Camera::Grid, &edges, None, &closing);
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
        let (labels, regions) = final_segmentation(&range, &Camera::Grid, &edges, None, &params);
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
            None,
            &SegmentParams { min_region_px: 10, gap_close_px: 0.0, ..SegmentParams::default() },
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
        let (labels, regions) = final_segmentation(
            &range,
            &Camera::ABW0,
            &Grid::new(10, 10, true),
            None,
            &SegmentParams::default(),
        );
        assert!(regions.is_empty());
        assert!(labels.as_slice().iter().all(|&l| l == 0));
        // An all-NaN image.
        let nan = Grid::new(6, 5, f32::NAN);
        let (labels, regions) =
            final_segmentation(&nan, &Camera::ABW0, &Grid::new(6, 5, false), None, &SegmentParams::default());
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
            None,
            &SegmentParams { min_region_px: 5, gap_close_px: 0.0, ..SegmentParams::default() },
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

    /// Region-growing labels: 1 for x < 20, 2 for x ≥ 20 (0 on NaN pixels).
    fn rg_split(range: &RangeImage) -> LabelImage {
        Grid::from_fn(range.width(), range.height(), |x, y| {
            if range[(x, y)].is_nan() {
                0
            } else if x < 20 {
                1
            } else {
                2
            }
        })
    }

    fn regions_mode() -> SegmentParams {
        SegmentParams { mode: SegmentMode::Regions, ..SegmentParams::default() }
    }

    #[test]
    fn regions_mode_splits_a_region_along_an_edge_line_inside_it() {
        // Region growing merged both planes into one region; C separates them.
        let (range, edges) = two_planes();
        let rg = range.map(|v| u32::from(v.is_finite()));
        let (labels, regions) = final_segmentation(&range, &Camera::Grid, &edges, Some(&rg), &regions_mode());
        assert_eq!(regions.len(), 2);
        assert_eq!(labels[(5, 20)], 1);
        assert_eq!(labels[(35, 20)], 2);
        assert_eq!(labels[(0, 0)], 0, "NaN stays unlabelled");
    }

    #[test]
    fn regions_mode_never_leaks_across_a_region_growing_border_of_different_planes() {
        // No edges at all: Components mode gives one region, Regions mode keeps the two
        // region-growing regions (the border is unsupported, but the planes differ).
        let (range, _) = two_planes();
        let none = Grid::new(40, 30, false);
        let rg = rg_split(&range);
        let comps = SegmentParams { mode: SegmentMode::Components, ..SegmentParams::default() };
        assert_eq!(final_segmentation(&range, &Camera::Grid, &none, Some(&rg), &comps).1.len(), 1);
        // Without region-growing labels, Regions mode falls back to Components.
        assert_eq!(final_segmentation(&range, &Camera::Grid, &none, None, &regions_mode()).1.len(), 1);
        let (labels, regions) = final_segmentation(&range, &Camera::Grid, &none, Some(&rg), &regions_mode());
        assert_eq!(regions.len(), 2);
        for (x, y, &l) in labels.enumerate() {
            let want = if range[(x, y)].is_nan() { 0 } else { rg[(x, y)] };
            assert_eq!(l, want, "pixel ({x}, {y})");
        }
    }

    #[test]
    fn regions_mode_merges_coplanar_regions_over_an_unsupported_border_only() {
        // One plane, split in two by region growing.
        let range = Grid::from_fn(40, 30, |x, y| 100.0 + 0.5 * x as f32 + 0.25 * y as f32);
        let rg = rg_split(&range);
        let none = Grid::new(40, 30, false);
        let (labels, regions) = final_segmentation(&range, &Camera::Grid, &none, Some(&rg), &regions_mode());
        assert_eq!(regions.len(), 1, "unsupported border, same plane: merged");
        assert_eq!(regions[0].size_px, 40 * 30);
        assert!(labels.as_slice().iter().all(|&l| l == 1));
        assert!(regions[0].rms_residual < 1e-3);
        // The same border with edge support stays.
        let edges = Grid::from_fn(40, 30, |x, _| x == 19 || x == 20);
        let (labels, regions) = final_segmentation(&range, &Camera::Grid, &edges, Some(&rg), &regions_mode());
        assert_eq!(regions.len(), 2, "supported border: kept");
        assert_ne!(labels[(5, 5)], labels[(35, 5)]);
        // An edge along a tenth of the border (support ≈ 0.15 < min_border_support = 0.3): merged.
        let partial = Grid::from_fn(40, 30, |x, y| (x == 19 || x == 20) && y < 3);
        let (_, regions) = final_segmentation(&range, &Camera::Grid, &partial, Some(&rg), &regions_mode());
        assert_eq!(regions.len(), 1);
        // A tilt of 1.0 vs 0.5 per pixel (about 18° apart in Grid units) is not merged.
        let tilted =
            Grid::from_fn(
                40,
                30,
                |x, _| if x < 20 { 100.0 + 0.5 * x as f32 } else { 110.0 + (x as f32 - 20.0) },
            );
        let (_, regions) = final_segmentation(&tilted, &Camera::Grid, &none, Some(&rg), &regions_mode());
        assert_eq!(regions.len(), 2);
    }

    #[test]
    fn regions_mode_rejoins_pieces_of_one_region_split_by_interior_edges_on_one_plane_only() {
        // Region growing found one region; an edge line inside it splits it in two.
        let edges = Grid::from_fn(40, 30, |x, _| x == 19 || x == 20);
        let one = |range: &RangeImage| range.map(|v| u32::from(v.is_finite()));
        let count = |range: &RangeImage, sp: &SegmentParams| {
            final_segmentation(range, &Camera::Grid, &edges, Some(&one(range)), sp).1.len()
        };
        let plane = |x: u32, y: u32| 100.0 + 0.5 * x as f32 + 0.25 * y as f32;
        let image = |f: &dyn Fn(u32, u32) -> f32| Grid::from_fn(40, 30, f);
        let plane_img = image(&plane);
        assert_eq!(count(&plane_img, &regions_mode()), 1, "one plane: the pieces rejoin");
        let split = SegmentParams { merge_within_region: false, ..regions_mode() };
        assert_eq!(count(&plane_img, &split), 2, "without merge_within_region the edges split it");
        // Parallel planes one unit apart (within merge_max_residual = 2, far above their RMS of
        // 0): a real step, kept.
        let step = image(&|x, y| plane(x, y) + if x < 20 { 0.0 } else { 1.0 });
        assert_eq!(count(&step, &regions_mode()), 2, "a step between parallel pieces stays");
        // Two pieces of one noisy plane rejoin, a step of twice the noise does not.
        let noise = |x: u32, y: u32| ((x * 7 + y * 13) % 5) as f32 * 0.25 - 0.5;
        let noisy = image(&|x, y| plane(x, y) + noise(x, y));
        assert_eq!(count(&noisy, &regions_mode()), 1);
        let noisy_step = image(&|x, y| plane(x, y) + noise(x, y) + if x < 20 { 0.0 } else { 0.7 });
        assert_eq!(count(&noisy_step, &regions_mode()), 2);
    }

    /// Reference labelling: flood fill from every unlabelled core pixel in raster order.
    fn components_by_flood_fill(core: &[bool], guide: Option<&[u32]>, w: usize, h: usize) -> Vec<u32> {
        let mut lab = vec![0u32; w * h];
        let mut next = 0;
        for s in 0..w * h {
            if !core[s] || lab[s] != 0 {
                continue;
            }
            next += 1;
            lab[s] = next;
            let mut stack = vec![s];
            while let Some(i) = stack.pop() {
                let (x, y) = (i % w, i / w);
                let mut nb = Vec::new();
                if x > 0 {
                    nb.push(i - 1);
                }
                if x + 1 < w {
                    nb.push(i + 1);
                }
                if y > 0 {
                    nb.push(i - w);
                }
                if y + 1 < h {
                    nb.push(i + w);
                }
                for j in nb {
                    if core[j] && lab[j] == 0 && guide.is_none_or(|g| g[i] == g[j]) {
                        lab[j] = next;
                        stack.push(j);
                    }
                }
            }
        }
        lab
    }

    #[test]
    fn union_find_components_match_flood_fill() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(12);
        for case in 0..60 {
            let (w, h) = (rng.random_range(1..40usize), rng.random_range(1..30usize));
            let p = [0.3, 0.55, 0.7, 0.9][case % 4];
            let core: Vec<bool> = (0..w * h).map(|_| rng.random_bool(p)).collect();
            let guide: Vec<u32> = (0..w * h).map(|i| ((i % w) / 7 + (i / w) / 5) as u32 % 3).collect();
            for g in [None, Some(guide.as_slice())] {
                let (lab, sizes) = components(&core, g, w, h);
                assert_eq!(lab, components_by_flood_fill(&core, g, w, h), "case {case}");
                for (k, &n) in sizes.iter().enumerate() {
                    assert_eq!(n as usize, lab.iter().filter(|&&l| l == k as u32 + 1).count(), "case {case}");
                }
            }
        }
    }

    #[test]
    fn segment_params_default_validates_and_round_trips() {
        let p = SegmentParams::default();
        assert_eq!(p.validate(), Ok(()));
        assert_eq!(p.mode, SegmentMode::Regions);
        let json = serde_json::to_string(&p).unwrap();
        assert!(json.contains(r#""mode":"regions""#), "{json}");
        let back: SegmentParams = serde_json::from_str(&json).unwrap();
        assert_eq!(back, p);
        let c: SegmentParams = serde_json::from_str(r#"{"mode": "components"}"#).unwrap();
        assert_eq!(c.mode, SegmentMode::Components);
        assert!(SegmentParams { min_border_support: 1.5, ..p.clone() }.validate().is_err());
        assert!(SegmentParams { within_max_rms_ratio: 0.5, ..p.clone() }.validate().is_err());
        assert!(SegmentParams { merge_max_angle_deg: -1.0, ..p.clone() }.validate().is_err());
        assert!(SegmentParams { merge_max_residual: f64::NAN, ..p }.validate().is_err());
    }
}
