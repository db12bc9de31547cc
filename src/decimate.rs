//! Decimation (`pipeline.decimate = f`): the stages run on the frame averaged over blocks of f × f pixels, and the
//! final segmentation is carried back to every pixel of the frame by the planes it found.
//!
//! A depth camera's frame holds more pixels than its planes need. Averaged over 2 × 2 blocks, a 640 × 480 Kinect
//! frame keeps the surfaces of a room, with less noise, in a quarter of the pixels; the whole method then takes 40 %
//! of its time, and about a fifth over 3 × 3 blocks (`configs/fast.toml`; docs/speed.md). Faces under the smallest
//! region go (200 blocks: 800 pixels at f = 2, 1,800 at f = 3): the option is for real-time use, not for the ABW
//! benchmark, and it is off by default (docs/method.md §2.7).
//!
//! - **Camera.** A block's mean is the depth at the block's centre, pixel `f·i + (f − 1)/2` of the frame, which a
//!   pinhole of focal lengths `f` times shorter and principal point `(c − (f − 1)/2) / f` sees at the block's
//!   coordinate `i` ([`camera`]). Only a pinhole camera has such a twin: [`camera`] returns `None` for the others,
//!   and their frames run at full resolution.
//! - **Blocks.** The mean of a block's valid values (no data if it has none); the last `w mod f` columns and `h mod
//!   f` rows join no block, and come back as the nearest block's.
//! - **Blocks across a jump.** A block that straddles a depth jump (an object before a wall, a wall before
//!   another) would average the two surfaces into a ramp between them, over which region growing joins them. So a
//!   block whose `f²` values no plane explains, its plane-fit RMS above [`MIXED_BLOCK_SCALES`] times the median of
//!   the frame's blocks (at least the noise floor of a quantised or noise-free frame), is no data
//!   ([`downsample_across_jumps_into`], for `f ≥ 3`): the stages see a gap there, and its pixels come back to the
//!   regions on either side by their planes.
//! - **Back to full resolution.** Each valid pixel takes, among the final regions of the 3 × 3 blocks around its own,
//!   the one whose plane lies nearest to its 3D point, if that plane explains it within the final segmentation's fill
//!   limit, `max(segment.fill_max_residual, segment.fill_rms_ratio × RMS)`, times `f` (a block's mean of `f²` values
//!   has down to `1/f` of a pixel's noise, and the planes' RMS is the blocks'); else it stays unlabelled
//!   ([`labels_into`]). The labels are then renumbered in raster order of their first pixel, as the stages number
//!   them ([`renumber`]). Region growing's labels, and the edge maps C1 and C2 and their relaxed sets, come back by
//!   nearest neighbour ([`nearest_into`]): their lines are `f` pixels wide.

use rangeimage::{Camera, Grid, LabelImage, RangeImage, Region};

/// The camera that sees a frame decimated by `f` as `camera` sees the frame (module docs); `None` unless `camera` is a
/// pinhole.
#[must_use]
pub fn camera(camera: &Camera, f: u32) -> Option<Camera> {
    let (s, half) = (f64::from(f), f64::from(f.saturating_sub(1)) / 2.0);
    match *camera {
        Camera::Pinhole { fx, fy, cx, cy, depth_scale } => Some(Camera::Pinhole {
            fx: fx / s,
            fy: fy / s,
            cx: (cx - half) / s,
            cy: (cy - half) / s,
            depth_scale,
        }),
        Camera::Abw(_) | Camera::Grid => None,
    }
}

/// The inverse of [`camera`]: the camera that sees the full frame as `camera` sees the frame decimated by `f` (other
/// cameras unchanged).
#[must_use]
pub fn full_camera(camera: &Camera, f: u32) -> Camera {
    let (s, half) = (f64::from(f), f64::from(f.saturating_sub(1)) / 2.0);
    match *camera {
        Camera::Pinhole { fx, fy, cx, cy, depth_scale } => {
            Camera::Pinhole { fx: fx * s, fy: fy * s, cx: cx * s + half, cy: cy * s + half, depth_scale }
        }
        other => other,
    }
}

/// The size of `range` decimated by `f`: `(w / f, h / f)`, rounded down.
#[must_use]
pub fn size(range: &RangeImage, f: u32) -> (u32, u32) {
    (range.width() / f.max(1), range.height() / f.max(1))
}

/// `range` decimated by `f` into `out` (module docs: each block's mean of its valid values, NaN if it has none),
/// whose memory is reused.
///
/// # Panics
/// If `f` is 0 or larger than a side of `range`.
pub fn downsample_into(range: &RangeImage, f: u32, out: &mut RangeImage) {
    let (w2, h2) = size(range, f);
    assert!(f > 0 && w2 > 0 && h2 > 0, "cannot decimate a {}×{} frame by {f}", range.width(), range.height());
    let (w, f) = (range.width() as usize, f as usize);
    let v = range.as_slice();
    let mut data = std::mem::take(out).into_vec();
    data.clear();
    data.reserve(w2 as usize * h2 as usize);
    // Per block of the row: the sum of its valid values and their count.
    let mut sums = vec![(0.0f64, 0u32); w2 as usize];
    for by in 0..h2 as usize {
        sums.fill((0.0, 0));
        for row in v[by * f * w..(by + 1) * f * w].chunks_exact(w) {
            // A literal block width lets the compiler unroll each block's loop.
            match f {
                2 => add_blocks(row, 2, &mut sums),
                3 => add_blocks(row, 3, &mut sums),
                4 => add_blocks(row, 4, &mut sums),
                _ => add_blocks(row, f, &mut sums),
            }
        }
        data.extend(sums.iter().map(|&(s, n)| if n > 0 { (s / f64::from(n)) as f32 } else { f32::NAN }));
    }
    *out = RangeImage::from_vec(w2, h2, data).expect("one value per block");
}

/// How far above the frame's typical misfit a block's plane-fit RMS lies when [`downsample_across_jumps_into`] takes
/// it for a block across a depth jump: a multiple of the median RMS of the frame's blocks (their noise and rounding).
/// On the NYU frames 5–12 gave the same gains within the seeds' spread (docs/results.md).
pub const MIXED_BLOCK_SCALES: f64 = 8.0;

/// [`downsample_across_jumps_into`] reads the median misfit on every this-many-th block (a Kinect frame at `f` = 3:
/// about 4,300 of 34,000).
const MEDIAN_STRIDE: usize = 8;

/// [`downsample_across_jumps_into`] reads the smallest difference between neighbours on every this-many-th row.
const FLOOR_ROW_STRIDE: usize = 16;

/// [`downsample_into`], then the blocks whose values straddle a depth jump set to no data (module docs): those with
/// every value valid whose least-squares plane (depth as an affine function of the pixel, over the block) leaves an
/// RMS residual above [`MIXED_BLOCK_SCALES`] times the median of that RMS (read on every 8th such block), or times
/// the noise floor of `range` seen through `camera` if that is larger (the rounding error `q / √12` of its smallest
/// difference between neighbours `q`, or a tenth of its pixel pitch in its depth units, as `crate::units` floors σ).
/// Blocks with no data among their values keep their means. `scratch` holds the blocks' mean square residuals.
/// Returns the number of blocks set to no data: none for `f` < 3, since a 2 × 2 block's plane fits a jump between its
/// columns or rows exactly.
///
/// # Panics
/// If `f` is 0 or larger than a side of `range`.
pub fn downsample_across_jumps_into(
    range: &RangeImage,
    camera: &Camera,
    f: u32,
    out: &mut RangeImage,
    scratch: &mut Vec<f64>,
) -> usize {
    downsample_into(range, f, out);
    if f < 3 {
        return 0;
    }
    block_misfits(range, f as usize, scratch);
    let blocks = scratch.len();
    // The median RMS of the blocks with every value valid (the others' RMS is NaN), on every
    // MEDIAN_STRIDE-th block.
    for i in (0..blocks).step_by(MEDIAN_STRIDE) {
        if scratch[i].is_finite() {
            scratch.push(scratch[i]);
        }
    }
    let full = scratch.len() - blocks;
    if full == 0 {
        return 0;
    }
    // Compared as squares: the mean squares' median is the squared RMS's.
    let (_, &mut median, _) = scratch[blocks..].select_nth_unstable_by((full - 1) / 2, f64::total_cmp);
    let limit = MIXED_BLOCK_SCALES * median.max(0.0).sqrt().max(noise_floor(range, camera));
    if !(limit > 0.0 && limit.is_finite()) {
        return 0;
    }
    let limit2 = limit * limit;
    let mut dropped = 0;
    for (value, &ms) in out.as_mut_slice().iter_mut().zip(&scratch[..blocks]) {
        if ms > limit2 {
            *value = f32::NAN;
            dropped += 1;
        }
    }
    dropped
}

/// Adds each block of `f` values of `row` to its sum and count in `sums` (valid values only, left to right).
#[inline(always)]
fn add_blocks(row: &[f32], f: usize, sums: &mut [(f64, u32)]) {
    for (s, block) in sums.iter_mut().zip(row.chunks_exact(f)) {
        for &x in block {
            if x.is_finite() {
                *s = (s.0 + f64::from(x), s.1 + 1);
            }
        }
    }
}

/// Each `f × f` block's plane-fit mean square residual (depth as an affine function of the pixel; the squared
/// residuals over `f²` − 3 degrees of freedom) into `out` (cleared first), in the order of the blocks; NaN where a
/// value of the block is missing.
fn block_misfits(range: &RangeImage, f: usize, out: &mut Vec<f64>) {
    // A literal block width lets the compiler unroll the loops over a block.
    match f {
        3 => block_misfits_of(range, 3, out),
        4 => block_misfits_of(range, 4, out),
        _ => block_misfits_of(range, f, out),
    }
}

/// [`block_misfits`]' body. Per block row, the values less their block's centre value, `d`, are summed down each
/// column (`Σd`, `Σd²`, `Σy·d`, in `f32`: the differences within a block are small), then across each block.
#[inline(always)]
fn block_misfits_of(range: &RangeImage, f: usize, out: &mut Vec<f64>) {
    let (w2, h2) = size(range, f as u32);
    let (w, cols, h2) = (range.width() as usize, w2 as usize * f, h2 as usize);
    let v = range.as_slice();
    let (n, centre) = ((f * f) as f64, (f as f64 - 1.0) / 2.0);
    // Σx² = Σy² over a block in centred pixel coordinates (Σx = Σy = Σxy = 0).
    let (inv_n, inv_sxx, inv_dof) = (1.0 / n, 12.0 / (n * (n - 1.0)), 1.0 / (n - 3.0));
    // Per column of the whole blocks: its block's centre value, then Σd, Σd² and Σy·d down the block row.
    let mut reference = vec![0.0f32; cols];
    let (mut s, mut ss, mut sy) = (vec![0.0f32; cols], vec![0.0f32; cols], vec![0.0f32; cols]);
    out.clear();
    out.reserve(w2 as usize * h2);
    for by in 0..h2 {
        let rows = &v[by * f * w..(by + 1) * f * w];
        for (r, m) in reference.chunks_exact_mut(f).zip(rows[(f / 2) * w..][..cols].chunks_exact(f)) {
            r.fill(m[f / 2]);
        }
        for dy in 0..f {
            let (row, y) = (&rows[dy * w..][..cols], (dy as f64 - centre) as f32);
            let (s, ss, sy, reference) =
                (&mut s[..cols], &mut ss[..cols], &mut sy[..cols], &reference[..cols]);
            for x in 0..cols {
                let d = row[x] - reference[x];
                (s[x], ss[x], sy[x]) =
                    if dy == 0 { (d, d * d, y * d) } else { (s[x] + d, ss[x] + d * d, sy[x] + y * d) };
            }
        }
        for ((s, ss), sy) in s.chunks_exact(f).zip(ss.chunks_exact(f)).zip(sy.chunks_exact(f)) {
            let (mut sum, mut sum2, mut sumx, mut sumy) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
            for dx in 0..f {
                let x = dx as f64 - centre;
                sum += f64::from(s[dx]);
                sum2 += f64::from(ss[dx]);
                sumx += x * f64::from(s[dx]);
                sumy += f64::from(sy[dx]);
            }
            out.push((sum2 - sum * sum * inv_n - (sumx * sumx + sumy * sumy) * inv_sxx) * inv_dof);
        }
    }
}

/// The smallest σ `range` seen through `camera` has in its own depth units, as `crate::units` floors it: the rounding
/// error `q / √12` of its smallest difference between neighbours `q` (its step, if it has one), or a tenth of its pixel
/// pitch, whichever is larger (0 without either).
fn noise_floor(range: &RangeImage, camera: &Camera) -> f64 {
    let rounding =
        planefit::noise::smallest_difference(range, FLOOR_ROW_STRIDE).map_or(0.0, |q| q / 12f64.sqrt());
    // The pitch in depth units: the 3D pitch over the 3D length of one unit of depth.
    let pitch = planefit::noise::step_geometry(range, camera, 1.0)
        .map_or(0.0, |(unit, pitch)| crate::units::PINHOLE_PITCH_SHARE * pitch / unit);
    rounding.max(pitch)
}

/// `coarse` (a map of the frame decimated by `f`) back at the frame's size `(w, h)` into `out`: each pixel takes
/// the value of its block, the nearest block beyond the last whole one.
///
/// # Panics
/// If `coarse` is empty and `(w, h)` is not.
pub fn nearest_into<T: Copy + Default>(coarse: &Grid<T>, f: u32, (w, h): (u32, u32), out: &mut Grid<T>) {
    let (cw, ch) = (coarse.width() as usize, coarse.height() as usize);
    let (w, f) = (w as usize, f.max(1) as usize);
    let mut data = std::mem::take(out).into_vec();
    data.clear();
    data.reserve(w * h as usize);
    for y in 0..h as usize {
        if y % f != 0 {
            // The same blocks as the row above (the last ones, beyond the last whole block row).
            data.extend_from_within(data.len() - w..);
            continue;
        }
        let row = &coarse.as_slice()[(y / f).min(ch - 1) * cw..][..cw];
        // Each block's value f times, then the last block's to the end of the row.
        let start = data.len();
        data.resize(start + w, row[cw - 1]);
        let blocks = &mut data[start..start + cw * f];
        match f {
            2 => expand::<T, 2>(row, blocks),
            3 => expand::<T, 3>(row, blocks),
            4 => expand::<T, 4>(row, blocks),
            _ => {
                for (run, &v) in blocks.chunks_exact_mut(f).zip(row) {
                    run.fill(v);
                }
            }
        }
    }
    *out = Grid::from_vec(w as u32, h, data).expect("one value per pixel");
}

/// Each value of `row` `F` times into `out` (`F` values of `out` per value of `row`).
#[inline(always)]
fn expand<T: Copy, const F: usize>(row: &[T], out: &mut [T]) {
    for (run, &v) in out.chunks_exact_mut(F).zip(row) {
        run.copy_from_slice(&[v; F]);
    }
}

/// The limits [`labels_into`] accepts a pixel within: `factor × max(max_residual, rms_ratio × RMS)` of a region's
/// plane (module docs).
#[derive(Debug, Clone, Copy)]
pub struct Limit {
    /// The least distance accepted, in working units.
    pub max_residual: f64,
    /// The distance accepted, in multiples of the region's RMS.
    pub rms_ratio: f64,
    /// The factor on both (the decimation).
    pub factor: f64,
}

/// The final labels `coarse` (of the frame decimated by `f`; `regions[l − 1]` the region of label `l`, its plane in
/// the geometry of `camera` and `range`) back at the size of `range`, the full frame as `camera` sees it, into
/// `out` (module docs). `valid` is `range`'s valid mask. The labels are those of `coarse`: [`renumber`] them
/// after.
///
/// # Panics
/// If `coarse` is empty, or one of its labels has no region in `regions`.
pub fn labels_into(
    (range, camera, valid): (&RangeImage, &Camera, &Grid<bool>),
    coarse: &LabelImage,
    regions: &[Region],
    f: u32,
    limit: Limit,
    out: &mut LabelImage,
) {
    let (w, h) = (range.width() as usize, range.height() as usize);
    let (cw, ch) = (coarse.width() as usize, coarse.height() as usize);
    assert!(cw > 0 && ch > 0, "decimate::labels_into: no blocks");
    let f = f.max(1) as usize;
    let c = coarse.as_slice();
    // Per region: its plane and the farthest distance it accepts.
    let planes: Vec<PlaneReach> = regions
        .iter()
        .map(|r| {
            let reach = limit.factor * limit.max_residual.max(limit.rms_ratio * f64::from(r.rms_residual));
            (r.normal.map(f64::from), f64::from(r.offset), reach)
        })
        .collect();
    let mut data = std::mem::take(out).into_vec();
    data.clear();
    data.resize(w * h, 0);
    let (vals, ok) = (range.as_slice(), valid.as_slice());
    // Per block of a block row: the distinct labels of the 3 × 3 blocks around it (`n` of them), found once for the
    // f rows of pixels the block row holds.
    let mut around: Vec<Around> = vec![([0; 9], 0); cw];
    // The 3D points of a row (meaningless at invalid pixels, which are skipped), or per region the terms of its
    // distance along the row.
    let mut points = vec![[0.0; 3]; w];
    let mut rows_of = vec![(0.0, 0.0, 0.0); planes.len()];
    for y in 0..h {
        let by = (y / f).min(ch - 1);
        if y % f == 0 && y / f < ch {
            let rows = [by.saturating_sub(1), by, (by + 1).min(ch - 1)];
            for (bx, (seen, n)) in around.iter_mut().enumerate() {
                let cols = [bx.saturating_sub(1), bx, (bx + 1).min(cw - 1)];
                *n = 0;
                for &ry in &rows {
                    for &rx in &cols {
                        let l = c[ry * cw + rx];
                        if l != 0 && !seen[..*n].contains(&l) {
                            seen[*n] = l;
                            *n += 1;
                        }
                    }
                }
            }
        }
        let (row_vals, row_ok, row_out) = (&vals[y * w..][..w], &ok[y * w..][..w], &mut data[y * w..][..w]);
        let row = (&around[..], row_ok, row_out, &planes[..], f);
        match *camera {
            // Per region: the distance of a point of this row at column x and depth z from its plane is
            // `|z·(a·x + b) + offset|` (no division per pixel).
            Camera::Pinhole { fx, fy, cx, cy, depth_scale } => {
                for (terms, &(n, offset, _)) in rows_of.iter_mut().zip(&planes) {
                    let b = n[1] * (y as f64 - cy) / fy + n[2] - n[0] * cx / fx;
                    *terms = (n[0] / fx, b, offset);
                }
                label_row(row, |l, x| {
                    let (a, b, offset) = rows_of[l];
                    (f64::from(row_vals[x]) * depth_scale * (a * x as f64 + b) + offset).abs()
                });
            }
            Camera::Abw(_) | Camera::Grid => {
                camera.row_points(y as u32, row_vals, &mut points);
                label_row(row, |l, x| {
                    let (normal, offset, _) = planes[l];
                    (planefit::dot(normal, points[x]) + offset).abs()
                });
            }
        }
    }
    *out = LabelImage::from_vec(range.width(), range.height(), data).expect("one label per pixel");
}

/// The distinct labels of the 3 × 3 blocks around a block (the first `n` of the array), and `n`.
type Around = ([u32; 9], usize);

/// A region's plane as [`labels_into`] tests it: its normal, its offset and the farthest distance it accepts.
type PlaneReach = ([f64; 3], f64, f64);

/// One row of [`labels_into`]: each valid pixel (`ok`) of the row gets, among the labels `around` its block (`f`
/// pixels a block, the last block to the end of the row), the one whose plane (`planes[l − 1]`: normal, offset,
/// reach) lies nearest by `distance(l − 1, x)`, if within its reach; else 0.
#[inline(always)]
fn label_row(
    (around, ok, out, planes, f): (&[Around], &[bool], &mut [u32], &[PlaneReach], usize),
    distance: impl Fn(usize, usize) -> f64,
) {
    let w = out.len();
    let mut bx = 0;
    while bx < around.len() {
        let (seen, n) = &around[bx];
        match &seen[..*n] {
            [] => bx += 1,
            // Most blocks: one region around, the same for a run of blocks; tested without a branch per pixel.
            &[l] => {
                let run = around[bx..].iter().take_while(|(s, n)| *n == 1 && s[0] == l).count();
                let x1 = if bx + run == around.len() { w } else { (bx + run) * f };
                let (k, reach) = (l as usize - 1, planes[l as usize - 1].2);
                for x in bx * f..x1 {
                    out[x] = if ok[x] & (distance(k, x) <= reach) { l } else { 0 };
                }
                bx += run;
            }
            labels => {
                let x1 = if bx + 1 == around.len() { w } else { (bx + 1) * f };
                for x in (bx * f..x1).filter(|&x| ok[x]) {
                    let mut best = (f64::INFINITY, 0);
                    for &l in labels {
                        let d = distance(l as usize - 1, x);
                        if d <= planes[l as usize - 1].2 && d < best.0 {
                            best = (d, l);
                        }
                    }
                    out[x] = best.1;
                }
                bx += 1;
            }
        }
    }
}

/// Renumbers `labels` (0 = none; `regions[l − 1]` the region of label `l`) 1, 2, … in raster order of each label's
/// first pixel, as the stages number them, and `regions` to match, with `size_px` counted on `labels`; a region
/// without pixels is dropped. `map` is working memory.
pub fn renumber(labels: &mut LabelImage, regions: &mut Vec<Region>, map: &mut Vec<u32>) {
    map.clear();
    map.resize(regions.len() + 1, 0);
    let mut sizes = vec![0u32; regions.len() + 1];
    let mut order = Vec::with_capacity(regions.len());
    // Run by run of one label (most rows are a few long runs).
    let mut rest = labels.as_mut_slice();
    while let Some(&first) = rest.first() {
        let n = rest.iter().position(|&l| l != first).unwrap_or(rest.len());
        let (run, tail) = rest.split_at_mut(n);
        rest = tail;
        if first == 0 {
            continue;
        }
        let old = first as usize;
        if map[old] == 0 {
            order.push(old);
            map[old] = order.len() as u32;
        }
        run.fill(map[old]);
        sizes[old] += n as u32;
    }
    let mut kept: Vec<Region> = order
        .iter()
        .enumerate()
        .map(|(k, &old)| Region { label: k as u32 + 1, size_px: sizes[old], ..regions[old - 1].clone() })
        .collect();
    std::mem::swap(regions, &mut kept);
}

#[cfg(test)]
mod tests {
    use super::*;

    const PINHOLE: Camera =
        Camera::Pinhole { fx: 500.0, fy: 480.0, cx: 319.5, cy: 239.5, depth_scale: 0.001 };

    /// The depth (stored units of [`PINHOLE`]) at which the ray of pixel `(x, y)` meets the plane `n · p = d`.
    fn plane_depth(n: [f64; 3], d: f64, x: f64, y: f64) -> f64 {
        let Camera::Pinhole { fx, fy, cx, cy, depth_scale } = PINHOLE else { unreachable!() };
        let ray = [(x - cx) / fx, (y - cy) / fy, 1.0];
        d / planefit::dot(n, ray) / depth_scale
    }

    #[test]
    fn a_block_mean_lies_where_the_decimated_camera_sees_it() {
        // A slanted plane: each block's mean depth, seen by the decimated camera at the block's coordinates, lies on
        // the plane (to the curvature of depth across a block, well under a millimetre here), for f = 2 and 3.
        let (n, d) = ([0.3, -0.2, 0.9327379], 2.0);
        let range = Grid::from_fn(64, 48, |x, y| plane_depth(n, d, f64::from(x), f64::from(y)) as f32);
        for f in [2, 3] {
            let coarse_camera = camera(&PINHOLE, f).expect("a pinhole has a decimated twin");
            assert_eq!(full_camera(&coarse_camera, f), PINHOLE);
            let mut small = RangeImage::default();
            downsample_into(&range, f, &mut small);
            assert_eq!(small.dimensions(), (64 / f, 48 / f));
            for (i, j, &v) in small.enumerate() {
                let p = coarse_camera.point(f64::from(i), f64::from(j), f64::from(v)).expect("a point");
                let off = planefit::dot(n, p) - d;
                assert!(off.abs() < 1e-4, "f {f}, block ({i}, {j}): {off} m off the plane");
            }
        }
        assert_eq!(camera(&Camera::Grid, 2), None);
        assert_eq!(camera(&Camera::ABW0, 2), None);
    }

    #[test]
    fn blocks_average_their_valid_values_and_the_rest_join_none() {
        let nan = f32::NAN;
        let range = Grid::from_rows(vec![
            vec![1.0, 3.0, nan, nan, 9.0],
            vec![5.0, 7.0, nan, nan, 9.0],
            vec![2.0, nan, 4.0, 6.0, 9.0],
        ])
        .expect("rows");
        let mut small = RangeImage::default();
        downsample_into(&range, 2, &mut small);
        assert_eq!(small.dimensions(), (2, 1));
        assert_eq!(small[(0, 0)], 4.0);
        assert!(small[(1, 0)].is_nan(), "a block without data has none");
    }

    /// [`PINHOLE`]'s view of a slanted plane 1.5–2.5 m away, in millimetres, with a step of `jump` mm toward the
    /// sensor from column `edge` on and uniform noise of ±`noise` mm (seeded).
    fn stepped_plane(edge: u32, jump: f64, noise: f64) -> RangeImage {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(7);
        let (n, d) = ([0.3, -0.2, 0.9327379], 2.0);
        Grid::from_fn(96, 72, |x, y| {
            let z = plane_depth(n, d, f64::from(x), f64::from(y)) - if x >= edge { jump } else { 0.0 };
            (z + noise * (2.0 * rng.random::<f64>() - 1.0)) as f32
        })
    }

    #[test]
    fn blocks_across_a_jump_are_no_data_and_the_others_keep_their_means() {
        let mut misfits = Vec::new();
        // A jump of 40 mm (the noise ±1 mm) inside the blocks of columns 30–32: each of them is no data, and every
        // other block keeps its mean bit for bit.
        let range = stepped_plane(31, 40.0, 1.0);
        let (mut means, mut split) = (RangeImage::default(), RangeImage::default());
        downsample_into(&range, 3, &mut means);
        let dropped = downsample_across_jumps_into(&range, &PINHOLE, 3, &mut split, &mut misfits);
        assert_eq!(dropped, 72 / 3);
        for (i, j, &v) in split.enumerate() {
            if i == 10 {
                assert!(v.is_nan(), "block ({i}, {j}) straddles the jump");
            } else {
                assert_eq!(v.to_bits(), means[(i, j)].to_bits(), "block ({i}, {j})");
            }
        }
        // The same jump between two columns of blocks, a jump of 2 mm inside them, or blocks of 2 × 2 pixels (whose
        // plane fits a jump between their columns): no block is dropped.
        for (edge, jump, f) in [(30, 40.0, 3), (31, 2.0, 3), (31, 40.0, 2)] {
            let range = stepped_plane(edge, jump, 1.0);
            downsample_into(&range, f, &mut means);
            assert_eq!(downsample_across_jumps_into(&range, &PINHOLE, f, &mut split, &mut misfits), 0);
            assert!(split.as_slice().iter().zip(means.as_slice()).all(|(a, b)| a.to_bits() == b.to_bits()));
        }
    }

    #[test]
    fn the_noise_floor_keeps_creases_and_risers_of_noise_free_depth() {
        let (mut split, mut misfits) = (RangeImage::default(), Vec::new());
        // Noise-free depth creased along column 31 (the slanted plane, 1 mm more a column away from it): the blocks
        // fit their planes to the curvature of perspective depth, well under a micrometre, and only the floor (a
        // tenth of the 4 mm pitch) keeps the crease's blocks, which no jump crosses.
        let plane = stepped_plane(96, 0.0, 0.0);
        let crease = Grid::from_fn(96, 72, |x, y| plane[(x, y)] + (x as f32 - 31.0).abs());
        assert_eq!(downsample_across_jumps_into(&crease, &PINHOLE, 3, &mut split, &mut misfits), 0);
        // Whole millimetres: a level wall, then from column 31 on, 40 mm nearer, a floor rising 1 mm every 10
        // columns. Most blocks hold one value (a median misfit of 0); the rounding error of 1 mm keeps the risers'
        // blocks, and the jump's go.
        let depth = |x: u32| if x < 31 { 2000.0 } else { (1960.0 - 0.1 * (x as f32 - 31.0)).round() };
        let rounded = Grid::from_fn(96, 72, |x, _| depth(x));
        assert_eq!(downsample_across_jumps_into(&rounded, &PINHOLE, 3, &mut split, &mut misfits), 72 / 3);
        assert!(split.enumerate().all(|(i, _, v)| v.is_nan() == (i == 10)));
    }

    #[test]
    fn nearest_gives_each_pixel_its_block_and_the_leftovers_the_last_block() {
        let coarse = Grid::from_rows(vec![vec![1u32, 2], vec![3, 4]]).expect("rows");
        let mut out = Grid::default();
        nearest_into(&coarse, 2, (5, 5), &mut out);
        let rows: Vec<Vec<u32>> = out.rows().map(<[u32]>::to_vec).collect();
        let (top, bottom) = (vec![1, 1, 2, 2, 2], vec![3, 3, 4, 4, 4]);
        assert_eq!(rows, [top.clone(), top, bottom.clone(), bottom.clone(), bottom]);
    }

    /// A region of label `label` on the plane `n · p = d` (the form [`Region`] stores: `n · p + offset = 0`).
    fn region(label: u32, n: [f64; 3], d: f64, rms: f32) -> Region {
        Region {
            label,
            size_px: 0,
            mean_k: 0.0,
            normal: n.map(|v| v as f32),
            offset: -d as f32,
            rms_residual: rms,
        }
    }

    #[test]
    fn pixels_go_to_the_nearest_plane_of_the_blocks_around_within_the_limit() {
        // A floor and a wall that meet at column 33, an odd column, so that blocks 16 hold both; block labels put the
        // border on the wrong side (every block of columns 32–33 is the floor's). Each pixel goes to its own plane
        // by its depth; a pixel off both planes (an object) stays unlabelled, and so do the pixels of a block whose
        // 3 × 3 blocks hold no label.
        let (wall, floor) = (([0.0, 0.0, 1.0], 3.0), ([0.6, 0.0, 0.8], 2.0));
        let depth = |x: u32, y: u32| {
            let (n, d) = if x < 33 { floor } else { wall };
            plane_depth(n, d, f64::from(x), f64::from(y)) as f32
        };
        let mut range = Grid::from_fn(64, 48, depth);
        range[(10, 10)] += 500.0;
        let valid = range.map(|v| v.is_finite());
        let coarse = Grid::from_fn(32, 24, |i, j| {
            if j >= 20 {
                0
            } else if i <= 16 {
                1
            } else {
                2
            }
        });
        let regions = [region(1, floor.0, floor.1, 0.001), region(2, wall.0, wall.1, 0.001)];
        let limit = Limit { max_residual: 0.01, rms_ratio: 2.0, factor: 2.0 };
        let mut out = Grid::default();
        labels_into((&range, &PINHOLE, &valid), &coarse, &regions, 2, limit, &mut out);
        assert_eq!(out.dimensions(), (64, 48));
        for (x, y, &l) in out.enumerate() {
            let expected = if y >= 42 || (x, y) == (10, 10) {
                0
            } else if x < 33 {
                1
            } else {
                2
            };
            assert_eq!(l, expected, "pixel ({x}, {y})");
        }
    }

    #[test]
    fn other_cameras_go_through_their_points() {
        // Two level planes of the grid camera, v = 10 left of column 7 and v = 20 from it: block 3 (columns 6–7)
        // holds both and is labelled as the left one.
        let range: RangeImage = Grid::from_fn(16, 8, |x, _| if x < 7 { 10.0 } else { 20.0 });
        let valid = range.map(|v| v.is_finite());
        let coarse = Grid::from_fn(8, 4, |i, _| if i <= 3 { 1 } else { 2 });
        let regions = [region(1, [0.0, 0.0, 1.0], 10.0, 0.0), region(2, [0.0, 0.0, 1.0], 20.0, 0.0)];
        let limit = Limit { max_residual: 1.0, rms_ratio: 2.0, factor: 2.0 };
        let mut out = Grid::default();
        labels_into((&range, &Camera::Grid, &valid), &coarse, &regions, 2, limit, &mut out);
        for (x, y, &l) in out.enumerate() {
            assert_eq!(l, if x < 7 { 1 } else { 2 }, "pixel ({x}, {y})");
        }
    }

    #[test]
    fn renumbering_follows_the_first_pixels_and_drops_empty_regions() {
        let mut labels = Grid::from_rows(vec![vec![0, 3, 3], vec![1, 1, 0]]).expect("rows");
        let mut regions = vec![region(1, [0.0, 0.0, 1.0], 1.0, 0.1), region(2, [0.0, 0.0, 1.0], 2.0, 0.2)];
        regions.push(region(3, [0.0, 0.0, 1.0], 3.0, 0.3));
        renumber(&mut labels, &mut regions, &mut Vec::new());
        assert_eq!(labels.as_slice(), [0, 1, 1, 2, 2, 0]);
        let summary: Vec<(u32, u32, f32)> = regions.iter().map(|r| (r.label, r.size_px, r.offset)).collect();
        assert_eq!(summary, [(1, 2, -3.0), (2, 2, -1.0)]);
    }
}
