//! Hoover et al. (1996) region metrics, following the rules of the USF `compare` program.
//!
//! The rules below are docs/method.md §3.5 and reproduce `compare.c` of the USF SegComp tools
//! (`ClassifyRegions`, `ComputeTables`, `OutputTable`) step by step, quirks included.
//!
//! # Rules (tolerance `T`, `0.5 < T ≤ 1`)
//! - **Regions.** GT regions are the labels ≥ 10 (ABW convention: 0..=3 unlabelled, 4..=9
//!   illegal and ignored; `compare` refuses such files). Which labels of the machine segmentation
//!   (MS) are regions is set by [`Convention`]: ABW (≥ 10), any non-zero label, or auto-detected
//!   ([`Convention::Auto`]). Regions are visited in increasing label order, as `compare` visits
//!   its consecutive labels 10, 11, ….
//! - **Sizes and overlaps.** `|R|` is the number of pixels carrying the region's label in its own
//!   image, over all pixels (MS pixels on GT labels 0..=3 still count in `|m|`, GT pixels under
//!   unlabelled MS pixels in `|n|`). `O[m][n]` counts the pixels labelled MS `m` and GT `n`. A ratio
//!   "`O / |R| ≥ T`" is evaluated as `compare` does, as a floating-point quotient compared with `T`.
//! - **Step 1, correct detections.** Every pair with `O/|n| ≥ T` and `O/|m| ≥ T` is classified
//!   correct; `n` and `m` are mapped to each other, and both remember the pair's two ratios.
//! - **Step 2, over-segmentation**, for each GT `n`: the candidates are *all* MS regions `m`
//!   (classified or not) with `O[m][n]/|m| ≥ T`, and every candidate is re-mapped to `n` at once,
//!   whether or not an over-segmentation is then declared (a quirk of `compare`; with `T > 0.5` a
//!   region is a candidate of at most one other region, so the quirk shows in the mappings, never
//!   in a count). With ≥ 2 candidates, ratios `Σ O / |n| ≥ T` and `Σ O / Σ |m| ≥ T`, `n` and every
//!   MS region mapped to `n` become over-segmentation — **unless `n` is already classified and the
//!   mean of the two new ratios is ≤ the mean of its current two**. Only `n`'s current ratios are
//!   compared, as in `compare`.
//! - **Step 3, under-segmentation**, for each MS `m`: symmetric (candidates: all GT `n` with
//!   `O[m][n]/|n| ≥ T`, re-mapped to `m`; ≥ 2 of them; `Σ O / Σ |n| ≥ T` and `Σ O / |m| ≥ T`;
//!   replaces `m`'s current classification only if the new mean is higher; then every GT region
//!   mapped to `m` becomes under-segmentation). A replaced over-segmentation can leave MS pieces
//!   classified over-segmentation whose GT region no longer is, exactly as in `compare`.
//! - **Step 4.** GT regions left unclassified are **missed**, MS regions left are **noise**.
//! - **Counts.** `correct` = GT regions classified correct; `over` = GT regions classified
//!   over-segmentation; `under` = MS regions classified under-segmentation; `missed` = GT regions;
//!   `noise` = MS regions.
//! - **Angle error** (`compare`'s `OutputTable`). For each correctly detected GT region `a`, by
//!   increasing label, and each entry `(a, b, angle)` of the `.gt-ang` list (in list order) whose
//!   `b` is correctly detected too: the GT angle is folded to `|angle − 180|` when above 90°, the
//!   MS angle is `acos(|cos|)` of the two mapped regions' normals (so in 0..=90°), and the error is
//!   their absolute difference. Mean and population standard deviation over those pairs; `None`
//!   when the data are missing or no pair qualifies. Where `compare` would read an undefined
//!   normal (an MS region missing from the `.ms-nor` list, or a zero normal) the pair is skipped;
//!   if a label is listed twice, the last entry wins, as in `compare`.

use crate::boundary::FIRST_REGION_LABEL;
use rangeimage::LabelImage;
use std::collections::HashMap;

/// The values of T of Hoover et al.'s performance curves: 0.51 to 0.95 in steps of 0.02 (each
/// computed as `0.51 + 0.02·i`).
pub const CURVE_TS: [f64; 23] = {
    let mut ts = [0.0; 23];
    let mut i = 0;
    while i < 23 {
        ts[i] = 0.51 + 0.02 * i as f64;
        i += 1;
    }
    ts
};

/// Which labels of a label image name regions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Convention {
    /// ABW: labels ≥ 10 are regions, 0..=9 unlabelled.
    Abw,
    /// Every non-zero label is a region (in-memory segmentations from 1).
    NonZero,
    /// [`Convention::Abw`] unless some pixel carries a label in 4..=9, then [`Convention::NonZero`].
    ///
    /// Labels 4..=9 are illegal in the ABW convention (docs/method.md §2.1), so their presence means a
    /// segmentation numbered from 1. ABW files may hold 1..=3 (unlabelled: noise, too small), so
    /// those alone do not switch. A 1-based segmentation with at most 3 regions is therefore read
    /// as ABW (all unlabelled): pass [`Convention::NonZero`] explicitly for such inputs.
    #[default]
    Auto,
}

impl Convention {
    /// Resolves [`Convention::Auto`] for this image; the others are returned unchanged.
    pub fn resolve(self, labels: &LabelImage) -> Convention {
        match self {
            Convention::Auto => {
                if labels.as_slice().iter().any(|&l| (4..FIRST_REGION_LABEL).contains(&l)) {
                    Convention::NonZero
                } else {
                    Convention::Abw
                }
            }
            c => c,
        }
    }

    /// True if `label` names a region under this (resolved) convention; `Auto` acts as `Abw`.
    pub fn is_region(self, label: u32) -> bool {
        match self {
            Convention::NonZero => label != 0,
            Convention::Abw | Convention::Auto => label >= FIRST_REGION_LABEL,
        }
    }
}

/// What happened to one region.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Category {
    /// Part of a correct detection.
    Correct,
    /// Part of an over-segmentation instance (the GT region, or one of its pieces).
    Over,
    /// Part of an under-segmentation instance (the MS region, or one of the GT regions it covers).
    Under,
    /// GT region in no instance.
    Missed,
    /// MS region in no instance.
    Noise,
}

/// The category of every region at one tolerance.
#[derive(Debug, Clone, PartialEq)]
pub struct Classification {
    /// The tolerance T.
    pub t: f64,
    /// `(label, category)` of every GT region, by increasing label.
    pub gt: Vec<(u32, Category)>,
    /// `(label, category)` of every MS region, by increasing label.
    pub seg: Vec<(u32, Category)>,
    /// `(gt_label, seg_label)` of every correct detection, by increasing GT label.
    pub correct_pairs: Vec<(u32, u32)>,
    /// `(gt_label, seg_label)`: the MS region each GT region was last mapped to (`compare`'s
    /// `GTRegionMappings`), by increasing GT label; `None` if never mapped.
    pub gt_mapping: Vec<(u32, Option<u32>)>,
    /// `(seg_label, gt_label)`: the GT region each MS region was last mapped to (`compare`'s
    /// `MSRegionMappings`), by increasing MS label; `None` if never mapped.
    pub seg_mapping: Vec<(u32, Option<u32>)>,
}

/// The Hoover et al. scores of one segmentation at one tolerance.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct HooverScore {
    /// The tolerance T.
    pub t: f64,
    /// Number of GT regions.
    pub gt_regions: u32,
    /// Number of MS regions.
    pub seg_regions: u32,
    /// Correct detections.
    pub correct: u32,
    /// Over-segmented GT regions (instances).
    pub over: u32,
    /// Under-segmenting MS regions (instances).
    pub under: u32,
    /// Missed GT regions.
    pub missed: u32,
    /// Noise MS regions.
    pub noise: u32,
    /// MS regions taking part in over-segmentations.
    pub over_seg_regions: u32,
    /// GT regions taking part in under-segmentations.
    pub under_gt_regions: u32,
    /// Mean absolute angle error over qualifying adjacent pairs, in degrees.
    pub angle_error_deg: Option<f64>,
    /// Population standard deviation of the angle error, in degrees.
    pub angle_error_std_deg: Option<f64>,
    /// Number of adjacent pairs the angle error averages over.
    pub angle_pairs: u32,
}

/// The overlap table between a GT and an MS label image, computed once for any number of T.
#[derive(Debug, Clone, PartialEq)]
pub struct Overlap {
    gt_labels: Vec<u32>,
    gt_sizes: Vec<u64>,
    seg_labels: Vec<u32>,
    seg_sizes: Vec<u64>,
    /// Per GT region: `(seg index, overlap)`, by seg index.
    by_gt: Vec<Vec<(u32, u64)>>,
    /// Per MS region: `(gt index, overlap)`, by GT index.
    by_seg: Vec<Vec<(u32, u64)>>,
}

const NIL: u32 = u32::MAX;

/// Sorted region labels, their sizes, and each pixel's region index (`NIL` if unlabelled).
fn index_regions(labels: &LabelImage, is_region: impl Fn(u32) -> bool) -> (Vec<u32>, Vec<u64>, Vec<u32>) {
    let px = labels.as_slice();
    let max = px.iter().copied().filter(|&l| is_region(l)).max();
    let Some(max) = max else { return (Vec::new(), Vec::new(), vec![NIL; px.len()]) };
    let mut counts: HashMap<u32, u64> = HashMap::new();
    let dense = max as usize <= 4 * px.len().max(1 << 16);
    let mut dense_counts = if dense { vec![0u64; max as usize + 1] } else { Vec::new() };
    for &l in px {
        if is_region(l) {
            if dense {
                dense_counts[l as usize] += 1;
            } else {
                *counts.entry(l).or_default() += 1;
            }
        }
    }
    let mut pairs: Vec<(u32, u64)> = if dense {
        dense_counts.iter().enumerate().filter(|&(_, &c)| c > 0).map(|(l, &c)| (l as u32, c)).collect()
    } else {
        counts.into_iter().collect()
    };
    pairs.sort_unstable();
    let labels_sorted: Vec<u32> = pairs.iter().map(|p| p.0).collect();
    let sizes = pairs.iter().map(|p| p.1).collect();
    let index =
        if dense {
            let mut lut = vec![NIL; max as usize + 1];
            for (i, &l) in labels_sorted.iter().enumerate() {
                lut[l as usize] = i as u32;
            }
            px.iter().map(|&l| if is_region(l) { lut[l as usize] } else { NIL }).collect()
        } else {
            px.iter()
                .map(|&l| {
                    if is_region(l) { labels_sorted.binary_search(&l).map_or(NIL, |i| i as u32) } else { NIL }
                })
                .collect()
        };
    (labels_sorted, sizes, index)
}

impl Overlap {
    /// Builds the overlap table; GT regions are labels ≥ 10, MS regions follow `seg_convention`.
    ///
    /// # Panics
    /// If the images differ in size.
    pub fn new(gt: &LabelImage, seg: &LabelImage, seg_convention: Convention) -> Self {
        assert!(
            gt.same_size(seg),
            "GT {:?} and segmentation {:?} must have the same size",
            gt.dimensions(),
            seg.dimensions()
        );
        let conv = seg_convention.resolve(seg);
        let (gt_labels, gt_sizes, gi) = index_regions(gt, |l| l >= FIRST_REGION_LABEL);
        let (seg_labels, seg_sizes, si) = index_regions(seg, |l| conv.is_region(l));
        // Count overlaps run by run (labels come in long horizontal runs), then sort.
        let mut counts: HashMap<(u32, u32), u64> = HashMap::new();
        let mut run: Option<((u32, u32), u64)> = None;
        for (&g, &s) in gi.iter().zip(&si) {
            let key = (g, s);
            match &mut run {
                Some((k, n)) if *k == key => *n += 1,
                _ => {
                    if let Some((k, n)) = run.take()
                        && k.0 != NIL
                        && k.1 != NIL
                    {
                        *counts.entry(k).or_default() += n;
                    }
                    run = Some((key, 1));
                }
            }
        }
        if let Some((k, n)) = run
            && k.0 != NIL
            && k.1 != NIL
        {
            *counts.entry(k).or_default() += n;
        }
        let mut triples: Vec<(u32, u32, u64)> = counts.into_iter().map(|((g, s), n)| (g, s, n)).collect();
        triples.sort_unstable();
        let mut by_gt = vec![Vec::new(); gt_labels.len()];
        let mut by_seg = vec![Vec::new(); seg_labels.len()];
        for &(g, s, n) in &triples {
            by_gt[g as usize].push((s, n));
            by_seg[s as usize].push((g, n));
        }
        Overlap { gt_labels, gt_sizes, seg_labels, seg_sizes, by_gt, by_seg }
    }

    /// GT region labels, increasing.
    pub fn gt_labels(&self) -> &[u32] {
        &self.gt_labels
    }

    /// MS region labels, increasing.
    pub fn seg_labels(&self) -> &[u32] {
        &self.seg_labels
    }

    /// Overlap in pixels between GT region `gt_label` and MS region `seg_label` (0 if either is absent).
    pub fn overlap(&self, gt_label: u32, seg_label: u32) -> u64 {
        let (Ok(g), Ok(s)) =
            (self.gt_labels.binary_search(&gt_label), self.seg_labels.binary_search(&seg_label))
        else {
            return 0;
        };
        self.by_gt[g].iter().find(|e| e.0 as usize == s).map_or(0, |e| e.1)
    }

    /// Classifies every region at tolerance `t` (see the module rules).
    ///
    /// # Panics
    /// If `t` is not in `(0.5, 1]`.
    pub fn classify(&self, t: f64) -> Classification {
        assert!(t > 0.5 && t <= 1.0, "Hoover tolerance T must be in (0.5, 1], got {t}");
        // `compare` divides and compares the quotient with T (`Measure >= T_SEG`); so do we, so
        // that ties at the threshold fall the same way.
        let ratio = |o: u64, size: u64| o as f64 / size as f64;
        let (n_gt, n_seg) = (self.gt_labels.len(), self.seg_labels.len());
        let mut gt_cat: Vec<Option<Category>> = vec![None; n_gt];
        let mut seg_cat: Vec<Option<Category>> = vec![None; n_seg];
        let mut gt_map: Vec<Option<usize>> = vec![None; n_gt];
        let mut seg_map: Vec<Option<usize>> = vec![None; n_seg];
        // The two ratios of each region's current classification (`*MappingMeasures`).
        let mut gt_measures = vec![[0.0f64; 2]; n_gt];
        let mut seg_measures = vec![[0.0f64; 2]; n_seg];
        let mean = |m: [f64; 2]| (m[0] + m[1]) / 2.0;
        // Step 1: correct detections. With T > 0.5 a region passes with at most one partner.
        for (g, row) in self.by_gt.iter().enumerate() {
            for &(s, o) in row {
                let s = s as usize;
                let m = [ratio(o, self.gt_sizes[g]), ratio(o, self.seg_sizes[s])];
                if m[0] >= t && m[1] >= t {
                    gt_cat[g] = Some(Category::Correct);
                    seg_cat[s] = Some(Category::Correct);
                    gt_map[g] = Some(s);
                    seg_map[s] = Some(g);
                    gt_measures[g] = m;
                    seg_measures[s] = m;
                }
            }
        }
        // Step 2: over-segmentation of each GT region, replacing a worse classification.
        for (g, row) in self.by_gt.iter().enumerate() {
            let (mut count, mut total_overlap, mut total_area) = (0usize, 0u64, 0u64);
            for &(s, o) in row {
                let s = s as usize;
                if ratio(o, self.seg_sizes[s]) >= t {
                    count += 1;
                    total_overlap += o;
                    total_area += self.seg_sizes[s];
                    // The quirk: re-mapped whether or not an over-segmentation is declared.
                    seg_map[s] = Some(g);
                }
            }
            if count < 2 {
                continue;
            }
            let m = [ratio(total_overlap, self.gt_sizes[g]), ratio(total_overlap, total_area)];
            if m[0] >= t && m[1] >= t && (gt_cat[g].is_none() || mean(m) > mean(gt_measures[g])) {
                gt_cat[g] = Some(Category::Over);
                gt_measures[g] = m;
                for s in (0..n_seg).filter(|&s| seg_map[s] == Some(g)) {
                    seg_cat[s] = Some(Category::Over);
                    seg_measures[s] = m;
                }
            }
        }
        // Step 3: under-segmentation by each MS region, replacing a worse classification of it.
        for (s, col) in self.by_seg.iter().enumerate() {
            let (mut count, mut total_overlap, mut total_area) = (0usize, 0u64, 0u64);
            for &(g, o) in col {
                let g = g as usize;
                if ratio(o, self.gt_sizes[g]) >= t {
                    count += 1;
                    total_overlap += o;
                    total_area += self.gt_sizes[g];
                    gt_map[g] = Some(s);
                }
            }
            if count < 2 {
                continue;
            }
            let m = [ratio(total_overlap, total_area), ratio(total_overlap, self.seg_sizes[s])];
            if m[0] >= t && m[1] >= t && (seg_cat[s].is_none() || mean(m) > mean(seg_measures[s])) {
                seg_cat[s] = Some(Category::Under);
                seg_measures[s] = m;
                for g in (0..n_gt).filter(|&g| gt_map[g] == Some(s)) {
                    gt_cat[g] = Some(Category::Under);
                    gt_measures[g] = m;
                }
            }
        }
        // Step 4: the rest.
        let correct_pairs = (0..n_gt)
            .filter(|&g| gt_cat[g] == Some(Category::Correct))
            .map(|g| {
                let s = gt_map[g].expect("a correct GT region is mapped to its MS region");
                (self.gt_labels[g], self.seg_labels[s])
            })
            .collect();
        let gt =
            self.gt_labels.iter().zip(&gt_cat).map(|(&l, c)| (l, c.unwrap_or(Category::Missed))).collect();
        let seg =
            self.seg_labels.iter().zip(&seg_cat).map(|(&l, c)| (l, c.unwrap_or(Category::Noise))).collect();
        let gt_mapping =
            self.gt_labels.iter().zip(&gt_map).map(|(&l, m)| (l, m.map(|s| self.seg_labels[s]))).collect();
        let seg_mapping =
            self.seg_labels.iter().zip(&seg_map).map(|(&l, m)| (l, m.map(|g| self.gt_labels[g]))).collect();
        Classification { t, gt, seg, correct_pairs, gt_mapping, seg_mapping }
    }

    /// Scores at tolerance `t`, with the angle error when both angle lists are given.
    ///
    /// # Panics
    /// If `t` is not in `(0.5, 1]`.
    pub fn score(
        &self,
        t: f64,
        gt_angles: Option<&[(u32, u32, f64)]>,
        seg_normals: Option<&[(u32, [f32; 3])]>,
    ) -> HooverScore {
        let c = self.classify(t);
        let count = |v: &[(u32, Category)], cat: Category| v.iter().filter(|e| e.1 == cat).count() as u32;
        let mut errors = Vec::new();
        if let (Some(angles), Some(normals)) = (gt_angles, seg_normals) {
            // As `compare` reads `.ms-nor`: a later entry of a label overwrites an earlier one.
            let normal_of: HashMap<u32, [f32; 3]> = normals.iter().copied().collect();
            // `correct_pairs` is sorted by GT label.
            let seg_of =
                |g: u32| c.correct_pairs.binary_search_by_key(&g, |p| p.0).ok().map(|i| c.correct_pairs[i].1);
            for &(a, ma) in &c.correct_pairs {
                for &(_, b, gt_angle) in angles.iter().filter(|e| e.0 == a) {
                    let Some(mb) = seg_of(b) else { continue };
                    let (Some(na), Some(nb)) = (normal_of.get(&ma), normal_of.get(&mb)) else { continue };
                    if !gt_angle.is_finite() {
                        continue;
                    }
                    let gt_angle = if gt_angle > 90.0 { (gt_angle - 180.0).abs() } else { gt_angle };
                    if let Some(ms_angle) = ms_angle_deg(*na, *nb) {
                        errors.push((gt_angle - ms_angle).abs());
                    }
                }
            }
        }
        let (mean, std) = if errors.is_empty() {
            (None, None)
        } else {
            let n = errors.len() as f64;
            let mean = errors.iter().sum::<f64>() / n;
            let var = errors.iter().map(|e| (e - mean) * (e - mean)).sum::<f64>() / n;
            (Some(mean), Some(var.sqrt()))
        };
        HooverScore {
            t,
            gt_regions: self.gt_labels.len() as u32,
            seg_regions: self.seg_labels.len() as u32,
            correct: count(&c.gt, Category::Correct),
            over: count(&c.gt, Category::Over),
            under: count(&c.seg, Category::Under),
            missed: count(&c.gt, Category::Missed),
            noise: count(&c.seg, Category::Noise),
            over_seg_regions: count(&c.seg, Category::Over),
            under_gt_regions: count(&c.gt, Category::Under),
            angle_error_deg: mean,
            angle_error_std_deg: std,
            angle_pairs: errors.len() as u32,
        }
    }
}

/// Angle between two MS normals in degrees, as `compare` computes it: each normal is flipped to
/// `z ≥ 0` when read, then `acos(|cos|)` if `|cos| < 1`, 0° if `cos ≥ 1`, 180° if `cos ≤ −1` (so
/// 0..=90° except for exactly opposite normals with `z = 0`). `None` if either is zero or not finite.
fn ms_angle_deg(a: [f32; 3], b: [f32; 3]) -> Option<f64> {
    let flip = |v: [f32; 3]| {
        let v = v.map(f64::from);
        if v[2] < 0.0 { v.map(|x| -x) } else { v }
    };
    let (a, b) = (flip(a), flip(b));
    let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let na = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    let nb = (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt();
    let c = dot / (na * nb);
    if !(c.is_finite() && na > 0.0 && nb > 0.0) {
        return None;
    }
    let angle = if c.abs() < 1.0 {
        c.abs().acos()
    } else if c >= 1.0 {
        0.0
    } else {
        std::f64::consts::PI
    };
    Some(angle.to_degrees())
}

/// Hoover scores of `seg` against `gt` at tolerance `t` (MS convention auto-detected).
///
/// # Panics
/// If the images differ in size or `t` is not in `(0.5, 1]`.
pub fn compare(
    gt: &LabelImage,
    seg: &LabelImage,
    t: f64,
    gt_angles: Option<&[(u32, u32, f64)]>,
    seg_normals: Option<&[(u32, [f32; 3])]>,
) -> HooverScore {
    compare_with(gt, seg, t, gt_angles, seg_normals, Convention::Auto)
}

/// [`compare`] with an explicit MS label convention.
///
/// # Panics
/// If the images differ in size or `t` is not in `(0.5, 1]`.
pub fn compare_with(
    gt: &LabelImage,
    seg: &LabelImage,
    t: f64,
    gt_angles: Option<&[(u32, u32, f64)]>,
    seg_normals: Option<&[(u32, [f32; 3])]>,
    seg_convention: Convention,
) -> HooverScore {
    let _s = tracing::info_span!("eval::hoover::compare").entered();
    let score = Overlap::new(gt, seg, seg_convention).score(t, gt_angles, seg_normals);
    tracing::debug!(?score, "hoover score");
    score
}

/// Hoover scores at each tolerance in `ts` (e.g. [`CURVE_TS`]), without angle errors.
///
/// # Panics
/// If the images differ in size or some `t` is not in `(0.5, 1]`.
pub fn curve(gt: &LabelImage, seg: &LabelImage, ts: &[f64]) -> Vec<HooverScore> {
    curve_with(gt, seg, ts, Convention::Auto)
}

/// [`curve`] with an explicit MS label convention.
///
/// # Panics
/// If the images differ in size or some `t` is not in `(0.5, 1]`.
pub fn curve_with(
    gt: &LabelImage,
    seg: &LabelImage,
    ts: &[f64],
    seg_convention: Convention,
) -> Vec<HooverScore> {
    let _s = tracing::info_span!("eval::hoover::curve").entered();
    let overlap = Overlap::new(gt, seg, seg_convention);
    ts.iter().map(|&t| overlap.score(t, None, None)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use rangeimage::Grid;

    fn img(rows: &[&[u32]]) -> LabelImage {
        Grid::from_rows(rows.iter().map(|r| r.to_vec()).collect()).unwrap()
    }

    /// Expand each label of a small layout to a `k × k` block.
    fn blocks(rows: &[&[u32]], k: u32) -> LabelImage {
        let small = img(rows);
        Grid::from_fn(small.width() * k, small.height() * k, |x, y| small[(x / k, y / k)])
    }

    fn counts(s: &HooverScore) -> [u32; 5] {
        [s.correct, s.over, s.under, s.missed, s.noise]
    }

    #[test]
    fn identical_is_all_correct() {
        let gt = blocks(&[&[10, 10, 11], &[12, 0, 11], &[12, 13, 13]], 4);
        let s = compare(&gt, &gt, 0.95, None, None);
        assert_eq!((s.gt_regions, s.seg_regions), (4, 4));
        assert_eq!(counts(&s), [4, 0, 0, 0, 0]);
        assert_eq!(s.angle_error_deg, None);
    }

    #[test]
    fn split_region_is_over_segmentation() {
        // GT: 10 | 11 (4×4 blocks). MS: 11's area split into 21 (top) and 22 (bottom).
        let gt = blocks(&[&[10, 11], &[10, 11]], 4);
        let seg = blocks(&[&[20, 21], &[20, 22]], 4);
        let s = compare(&gt, &seg, 0.8, None, None);
        assert_eq!(counts(&s), [1, 1, 0, 0, 0]);
        assert_eq!((s.over_seg_regions, s.under_gt_regions), (2, 0));
        let c = Overlap::new(&gt, &seg, Convention::Auto).classify(0.8);
        assert_eq!(c.gt, vec![(10, Category::Correct), (11, Category::Over)]);
        assert_eq!(c.correct_pairs, vec![(10, 20)]);
    }

    #[test]
    fn merged_regions_are_under_segmentation() {
        let gt = blocks(&[&[10, 11], &[12, 12]], 4);
        let seg = blocks(&[&[30, 30], &[31, 31]], 4);
        let s = compare(&gt, &seg, 0.8, None, None);
        assert_eq!(counts(&s), [1, 0, 1, 0, 0]);
        assert_eq!(s.under_gt_regions, 2);
    }

    /// One row: `(label, run length)` pairs laid end to end.
    fn runs(r: &[(u32, usize)]) -> LabelImage {
        img(&[&r.iter().flat_map(|&(l, n)| std::iter::repeat_n(l, n)).collect::<Vec<u32>>()])
    }

    fn category_of(v: &[(u32, Category)], label: u32) -> Category {
        v.iter().find(|e| e.0 == label).expect("label present").1
    }

    #[test]
    fn under_segmentation_replaces_a_worse_correct_detection() {
        // docs/method.md §3.5's example. GT A = 10 (90 px) and B = 11 (10 px), merged into MS M = 20
        // (100 px). Step 1: A–M correct (90/90 = 1, 90/100 = 0.9, mean 0.95). Step 3: M
        // under-segments A and B (100/100 and 100/100, mean 1.0 > 0.95) and replaces it.
        let gt = runs(&[(10, 90), (11, 10)]);
        let seg = runs(&[(20, 100)]);
        let s = compare(&gt, &seg, 0.8, None, None);
        assert_eq!(counts(&s), [0, 0, 1, 0, 0]);
        assert_eq!((s.under_gt_regions, s.over_seg_regions), (2, 0));
        let c = Overlap::new(&gt, &seg, Convention::Auto).classify(0.8);
        assert_eq!(c.gt, vec![(10, Category::Under), (11, Category::Under)]);
        assert_eq!(c.seg, vec![(20, Category::Under)]);
        assert!(c.correct_pairs.is_empty());
        assert_eq!(c.gt_mapping, vec![(10, Some(20)), (11, Some(20))]);
    }

    #[test]
    fn under_segmentation_does_not_replace_a_better_correct_detection() {
        // T = 0.51. GT A = 10 (100 px) lies in MS M = 20 (150 px), which also holds 11 of the
        // 20 px of GT B = 11 and 39 px of unlabelled GT; B's other 9 px are unlabelled in the MS.
        // Step 1: A–M correct (100/100, 100/150: mean 0.83333). Step 3: M under-segments A and B
        // (111/120, 111/150: mean 0.8325), lower → the correct detection stays and B is missed.
        let gt = runs(&[(10, 100), (11, 11), (0, 39), (11, 9)]);
        let seg = runs(&[(20, 150), (0, 9)]);
        let c = Overlap::new(&gt, &seg, Convention::Auto).classify(0.51);
        assert_eq!(c.gt, vec![(10, Category::Correct), (11, Category::Missed)]);
        assert_eq!(c.seg, vec![(20, Category::Correct)]);
        // B was still re-mapped to M in step 3.
        assert_eq!(c.gt_mapping, vec![(10, Some(20)), (11, Some(20))]);
        assert_eq!(counts(&compare(&gt, &seg, 0.51, None, None)), [1, 0, 0, 1, 0]);
        // With 6 more px of B inside M (17 of 20, M = 156): 117/120 and 117/156 (mean 0.8625)
        // beat 100/100 and 100/156 (mean 0.8205): the under-segmentation replaces it.
        let gt = runs(&[(10, 100), (11, 17), (0, 39), (11, 3)]);
        let seg = runs(&[(20, 156), (0, 3)]);
        assert_eq!(counts(&compare(&gt, &seg, 0.51, None, None)), [0, 0, 1, 0, 0]);
    }

    #[test]
    fn correct_detections_only() {
        // Two GT regions, each found by one MS region that spills 2 px over the border.
        let gt = runs(&[(10, 20), (11, 20)]);
        let seg = runs(&[(20, 22), (21, 18)]);
        let c = Overlap::new(&gt, &seg, Convention::Auto).classify(0.8);
        assert_eq!(c.correct_pairs, vec![(10, 20), (11, 21)]);
        assert_eq!(counts(&compare(&gt, &seg, 0.8, None, None)), [2, 0, 0, 0, 0]);
        // At T = 0.95: 20/22 < 0.95, so 10 and 20 fail; 11–21 (18/20 = 0.9) fails too.
        assert_eq!(counts(&compare(&gt, &seg, 0.95, None, None)), [0, 0, 0, 2, 2]);
    }

    #[test]
    fn over_segmentation_replaces_a_worse_correct_detection() {
        // GT 10 (100 px) = MS 20 (85 px) + MS 21 (15 px). Step 1: 10–20 correct (0.85 and 1.0,
        // mean 0.925). Step 2: over-segmentation with ratios 100/100 and 100/100 (mean 1.0).
        let gt = runs(&[(10, 100)]);
        let seg = runs(&[(20, 85), (21, 15)]);
        let s = compare(&gt, &seg, 0.8, None, None);
        assert_eq!(counts(&s), [0, 1, 0, 0, 0]);
        assert_eq!(s.over_seg_regions, 2);
        let c = Overlap::new(&gt, &seg, Convention::Auto).classify(0.8);
        assert_eq!(c.seg, vec![(20, Category::Over), (21, Category::Over)]);
        assert!(c.correct_pairs.is_empty());
    }

    #[test]
    fn over_segmentation_does_not_replace_an_equal_or_better_correct_detection() {
        // T = 0.51. GT 10 (32 px) = MS 20 (17 px) + MS 21 (4 of its 7 px) + 11 px unlabelled.
        // Correct 10–20: 17/32 and 17/17, mean 0.765625. Over-segmentation {20, 21}: 21/32 and
        // 21/24, mean 0.765625 — equal (all exact binary fractions), so the correct detection stays.
        let gt = runs(&[(10, 32), (0, 3)]);
        let seg = runs(&[(20, 17), (21, 4), (0, 11), (21, 3)]);
        let s = compare(&gt, &seg, 0.51, None, None);
        assert_eq!(counts(&s), [1, 0, 0, 0, 1]);
        let c = Overlap::new(&gt, &seg, Convention::Auto).classify(0.51);
        assert_eq!(c.correct_pairs, vec![(10, 20)]);
        // The re-mapping quirk: 21 was re-mapped to 10 in step 2 although it ends up noise.
        assert_eq!(c.seg_mapping, vec![(20, Some(10)), (21, Some(10))]);
        assert_eq!(category_of(&c.seg, 21), Category::Noise);
        // Lower: GT 10 (31 px) = 20 (16 px) + 21 (4 of 7) + 11 unlabelled. Correct: 16/31 and 1
        // (mean 0.75806); over: 20/31 and 20/23 (mean 0.75736) → the correct detection stays.
        let gt = runs(&[(10, 31), (0, 3)]);
        let seg = runs(&[(20, 16), (21, 4), (0, 11), (21, 3)]);
        assert_eq!(counts(&compare(&gt, &seg, 0.51, None, None)), [1, 0, 0, 0, 1]);
        // Higher: one unlabelled pixel of 10 given to 21 (GT 10 = 20 + 5 of 8 + 10 unlabelled).
        // Correct: 16/31, 1 (mean 0.75806); over: 21/31 and 21/24 (mean 0.77621) → replaced.
        let seg = runs(&[(20, 16), (21, 5), (0, 10), (21, 3)]);
        let s = compare(&gt, &seg, 0.51, None, None);
        assert_eq!(counts(&s), [0, 1, 0, 0, 0]);
        assert_eq!(s.over_seg_regions, 2);
    }

    #[test]
    fn remapping_quirk_without_any_instance() {
        // MS 21 lies inside GT 11 (30 of its 100 px; the rest is unlabelled in the MS): 21 is
        // re-mapped to 11 in step 2 although 11 has a single candidate, so no over-segmentation.
        let gt = runs(&[(10, 20), (11, 100)]);
        let seg = runs(&[(20, 20), (21, 30), (0, 70)]);
        let c = Overlap::new(&gt, &seg, Convention::Auto).classify(0.8);
        assert_eq!(c.gt, vec![(10, Category::Correct), (11, Category::Missed)]);
        assert_eq!(c.seg, vec![(20, Category::Correct), (21, Category::Noise)]);
        assert_eq!(c.seg_mapping, vec![(20, Some(10)), (21, Some(11))]);
        assert_eq!(c.gt_mapping, vec![(10, Some(20)), (11, None)]);
    }

    #[test]
    fn under_segmentation_replacing_an_over_segmentation_orphans_its_other_piece() {
        // GT 10 (90 px), GT 11 (15 px); MS 21 = 10 px of 10, MS 20 = 80 px of 10 + all of 11.
        // Step 1: 10–20 correct (80/90, 80/95: mean 0.865). Step 2: 10 over-segmented into
        // {20, 21} (90/90, 90/105: mean 0.929) replaces it. Step 3: 20 under-segments {10, 11}
        // (95/105, 95/95: mean 0.952 > 0.929) and replaces 20's over-segmentation; 10 and 11
        // become under-segmented, and 21 stays an over-segmentation piece of nothing counted.
        let gt = runs(&[(10, 90), (11, 15)]);
        let seg = runs(&[(21, 10), (20, 95)]);
        let c = Overlap::new(&gt, &seg, Convention::Auto).classify(0.8);
        assert_eq!(c.gt, vec![(10, Category::Under), (11, Category::Under)]);
        assert_eq!(c.seg, vec![(20, Category::Under), (21, Category::Over)]);
        let s = compare(&gt, &seg, 0.8, None, None);
        assert_eq!(counts(&s), [0, 0, 1, 0, 0]);
        assert_eq!((s.over_seg_regions, s.under_gt_regions), (1, 2));
    }

    #[test]
    fn missed_and_noise() {
        let gt = blocks(&[&[10, 10, 10, 10], &[10, 10, 10, 11], &[0, 0, 12, 12]], 4);
        let seg = blocks(&[&[30, 30, 30, 30], &[30, 30, 30, 30], &[31, 31, 32, 32]], 4);
        // |10| = 112, |11| = 16, |30| = 128: 30 is a correct detection of 10 (112/112, 112/128,
        // mean 0.9375), replaced in step 3 by its under-segmentation of 10 and 11 (128/128 and
        // 128/128). 31 lies on unlabelled GT → noise. (Before `compare`'s replacement rule was
        // followed, this test expected 10 correct and 11 missed.)
        let s = compare(&gt, &seg, 0.8, None, None);
        assert_eq!(counts(&s), [1, 0, 1, 0, 1]);
        // At T = 0.9, 30 is no longer a correct detection of 10 (112/128 < 0.9): the same.
        let s = compare(&gt, &seg, 0.9, None, None);
        assert_eq!(counts(&s), [1, 0, 1, 0, 1]);
        // A GT region under unlabelled MS pixels is missed; an MS region on unlabelled GT is noise.
        let gt = runs(&[(10, 10), (11, 10), (0, 10)]);
        let seg = runs(&[(20, 10), (0, 10), (21, 10)]);
        let c = Overlap::new(&gt, &seg, Convention::Auto).classify(0.8);
        assert_eq!(c.gt, vec![(10, Category::Correct), (11, Category::Missed)]);
        assert_eq!(c.seg, vec![(20, Category::Correct), (21, Category::Noise)]);
    }

    #[test]
    fn unlabelled_pixels_count_in_region_sizes() {
        // MS 20 covers GT 10 (10 px) and 3 px of GT label 0..=3: |20| = 13 counts them all,
        // so 10/13 = 0.769 < 0.8: not correct (10 missed, 20 noise); correct at T = 0.75.
        for unlabelled in 0..=3 {
            let gt = runs(&[(10, 10), (unlabelled, 3)]);
            let seg = runs(&[(20, 13)]);
            assert_eq!(counts(&compare(&gt, &seg, 0.8, None, None)), [0, 0, 0, 1, 1]);
            assert_eq!(counts(&compare(&gt, &seg, 0.75, None, None)), [1, 0, 0, 0, 0]);
        }
        // MS labels 1..=3 (ABW convention) are not regions but their pixels count in |GT 10|:
        // 20 covers 7 of its 10 px → 0.7.
        let gt = runs(&[(10, 10)]);
        let seg = runs(&[(20, 7), (1, 1), (2, 1), (3, 1)]);
        let s = compare(&gt, &seg, 0.7, None, None);
        assert_eq!((s.seg_regions, counts(&s)), (1, [1, 0, 0, 0, 0]));
        assert_eq!(counts(&compare(&gt, &seg, 0.71, None, None)), [0, 0, 0, 1, 1]);
    }

    #[test]
    fn thresholds_are_inclusive() {
        // GT 10 = 10 px; MS 20 covers 8 of them and nothing else; 2 px of 10 are in MS 21.
        let gt = img(&[&[10, 10, 10, 10, 10, 10, 10, 10, 10, 10, 11, 11]]);
        let seg = img(&[&[20, 20, 20, 20, 20, 20, 20, 20, 21, 21, 21, 21]]);
        // O(20,10) = 8 = 0.8·10 and = 1.0·|20| → correct at T = 0.8 exactly, not at 0.81.
        assert_eq!(compare(&gt, &seg, 0.8, None, None).correct, 1);
        assert_eq!(compare(&gt, &seg, 0.81, None, None).correct, 0);
    }

    #[test]
    fn auto_convention_detects_one_based_labels() {
        let gt = blocks(&[&[10, 11, 12]], 3);
        let seg_one = blocks(&[&[1, 2, 5]], 3);
        let seg_abw = blocks(&[&[40, 50, 60]], 3);
        assert_eq!(Convention::Auto.resolve(&seg_one), Convention::NonZero);
        assert_eq!(compare(&gt, &seg_one, 0.8, None, None).correct, 3);
        assert_eq!(compare(&gt, &seg_abw, 0.8, None, None).correct, 3);
        // Forced ABW convention: labels 1, 2 and 5 are unlabelled, so every GT region is missed.
        let s = compare_with(&gt, &seg_one, 0.8, None, None, Convention::Abw);
        assert_eq!((s.seg_regions, s.missed), (0, 3));
        // Only 1..=3: read as ABW unless told otherwise.
        let seg_123 = blocks(&[&[1, 2, 3]], 3);
        assert_eq!(compare(&gt, &seg_123, 0.8, None, None).seg_regions, 0);
        assert_eq!(compare_with(&gt, &seg_123, 0.8, None, None, Convention::NonZero).correct, 3);
    }

    #[test]
    fn angle_error_by_hand() {
        let gt = blocks(&[&[10, 11, 12]], 4);
        let seg = blocks(&[&[20, 21, 22]], 4);
        let angles = [(10, 11, 90.0), (11, 12, 45.0), (10, 99, 30.0)];
        // 20 ⟂ 21 exactly (error 0); 21 and 22 at 60° (error 15). The pair with 99 is skipped.
        let s60 = [0.5f32, 0.0, 3f32.sqrt() / 2.0];
        let normals = [(20, [0.0f32, 0.0, 1.0]), (21, [1.0, 0.0, 0.0]), (22, s60)];
        let s = compare(&gt, &seg, 0.8, Some(&angles), Some(&normals));
        assert_eq!(s.angle_pairs, 2);
        assert_relative_eq!(s.angle_error_deg.unwrap(), 7.5, epsilon = 1e-5);
        assert_relative_eq!(s.angle_error_std_deg.unwrap(), 7.5, epsilon = 1e-5);
        // Without normals there is no angle error.
        assert_eq!(compare(&gt, &seg, 0.8, Some(&angles), None).angle_error_deg, None);
        // A missing normal drops the pair.
        let s = compare(&gt, &seg, 0.8, Some(&angles), Some(&normals[..2]));
        assert_eq!(s.angle_pairs, 1);
        assert_relative_eq!(s.angle_error_deg.unwrap(), 0.0, epsilon = 1e-5);
    }

    #[test]
    fn angle_error_folds_like_compare() {
        let gt = blocks(&[&[10, 11]], 4);
        let seg = blocks(&[&[20, 21]], 4);
        // Normals 120° apart (one has z < 0, flipped on reading): `compare` measures 60°.
        let c120 = [-0.5f32, 0.0, -(3f32.sqrt()) / 2.0];
        let normals = [(20, [1.0f32, 0.0, 0.0]), (21, c120)];
        // A GT angle of 120° is folded to 60°: error 0. A GT angle of 50°: error 10.
        for (gt_angle, err) in [(120.0, 0.0), (60.0, 0.0), (50.0, 10.0), (130.0, 10.0)] {
            let s = compare(&gt, &seg, 0.8, Some(&[(10, 11, gt_angle)]), Some(&normals));
            assert_eq!(s.angle_pairs, 1);
            assert_relative_eq!(s.angle_error_deg.unwrap(), err, epsilon = 1e-4);
        }
        // A later normal of the same label replaces an earlier one; a zero normal drops the pair.
        let twice = [(20, [0.0f32, 1.0, 0.0]), (20, [1.0, 0.0, 0.0]), (21, c120)];
        let s = compare(&gt, &seg, 0.8, Some(&[(10, 11, 60.0)]), Some(&twice));
        assert_relative_eq!(s.angle_error_deg.unwrap(), 0.0, epsilon = 1e-4);
        let zero = [(20, [0.0f32; 3]), (21, c120)];
        assert_eq!(compare(&gt, &seg, 0.8, Some(&[(10, 11, 60.0)]), Some(&zero)).angle_pairs, 0);
    }

    #[test]
    fn curve_is_monotone_in_correct_detections_here() {
        let gt = blocks(&[&[10, 10, 11], &[12, 12, 11]], 5);
        let mut seg = gt.clone();
        // Move a few pixels of 11 into 12 so T decides.
        for y in 5..10 {
            seg[(10, y)] = 12;
        }
        let c = curve(&gt, &seg, &CURVE_TS);
        assert_eq!(c.len(), CURVE_TS.len());
        assert!(c.windows(2).all(|w| w[0].correct >= w[1].correct));
        assert_eq!(c[0].correct, 3);
        assert!(c.last().unwrap().correct < 3);
    }

    mod proptests {
        use super::*;
        use crate::testing::{abw_labels, relabel};
        use proptest::prelude::*;

        proptest! {
            #[test]
            fn proptest_gt_against_itself_is_all_correct(gt in abw_labels(1..24, 1..24, 8), t in 0.51f64..1.0) {
                let s = compare(&gt, &gt, t, None, None);
                prop_assert_eq!(s.correct, s.gt_regions);
                prop_assert_eq!(s.correct, s.seg_regions);
                prop_assert_eq!([s.over, s.under, s.missed, s.noise], [0, 0, 0, 0]);
            }

            #[test]
            fn proptest_every_region_in_one_category(
                gt in abw_labels(8..9, 8..9, 5),
                seg in abw_labels(8..9, 8..9, 5),
                t in 0.51f64..1.0,
            ) {
                let c = Overlap::new(&gt, &seg, Convention::Abw).classify(t);
                let s = Overlap::new(&gt, &seg, Convention::Abw).score(t, None, None);
                prop_assert_eq!(c.gt.len() as u32, s.gt_regions);
                prop_assert_eq!(s.correct + s.over + s.under_gt_regions + s.missed, s.gt_regions);
                prop_assert_eq!(s.correct + s.over_seg_regions + s.under + s.noise, s.seg_regions);
            }

            #[test]
            fn proptest_relabelling_changes_nothing(
                gt in abw_labels(6..12, 6..12, 4),
                seed in any::<u64>(),
                t in 0.51f64..1.0,
            ) {
                // A segmentation made from the GT by merging and shuffling, so all categories occur.
                let seg = gt.map(|&l| if l >= 10 { 10 + (l * 7 + (seed as u32 % 5)) % 4 } else { l });
                let normals: Vec<(u32, [f32; 3])> =
                    (10..14).map(|l| (l, [l as f32, 1.0, (l % 3) as f32])).collect();
                let angles = [(10, 11, 30.0), (11, 12, 80.0), (12, 13, 10.0)];
                let base = compare(&gt, &seg, t, Some(&angles), Some(&normals));
                let (seg2, map) = relabel(&seg, seed, |l| l >= 10, 10);
                let new_label = |l: u32| map.get(&l).copied().unwrap_or(100_000 + l);
                let normals2: Vec<(u32, [f32; 3])> = normals.iter().map(|&(l, n)| (new_label(l), n)).collect();
                let other = compare(&gt, &seg2, t, Some(&angles), Some(&normals2));
                prop_assert_eq!(&base, &other);
                // The same with 1-based labels and the non-zero convention.
                let seg0 = seg.map(|&l| if l >= 10 { l } else { 0 });
                let (seg3, _) = relabel(&seg0, seed ^ 0x5555, |l| l != 0, 1);
                let plain = compare_with(&gt, &seg0, t, None, None, Convention::NonZero);
                let third = compare_with(&gt, &seg3, t, None, None, Convention::NonZero);
                prop_assert_eq!(plain, third);
            }
        }
    }
}
