//! Step 7 of the final segmentation: pixels their region's plane does not explain are left unlabelled.
//!
//! Region growing, the fill and the merges give a region some pixels that lie well off its plane: a small face
//! seen edge-on that no region of its own holds (a few pixels wide beside a crease), an object standing on a wall,
//! the mixed pixels of a jump edge. Such a pixel claims a surface it is not on. Leaving it unlabelled says what the
//! method knows: that no plane of the segmentation explains it.

use crate::Scene;
use crate::plane::Plane;
use crate::refine::SIGMA_FLOOR;

/// The working memory of [`release`], kept from one frame to the next.
#[derive(Debug, Default)]
pub(crate) struct Buffers {
    /// Per pixel: 0 = explained by its plane (or unlabelled), 1 = an outlier not yet grouped, 2 = grouped.
    state: Vec<u8>,
    /// The outlier pixels in raster order.
    outliers: Vec<u32>,
    /// The flood fill's stack and the group it gathers.
    stack: Vec<u32>,
    group: Vec<u32>,
    /// The pixels the last call released, each with the label it had.
    released: Vec<(u32, u32)>,
}

impl Buffers {
    /// The pixels the last [`release`] left unlabelled, each with the label it had, in the order released.
    pub(crate) fn released(&self) -> &[(u32, u32)] {
        &self.released
    }
}

/// Leaves unlabelled (0) the pixels of `groups` (a label per pixel, 0 = none; `planes[l − 1]` is the plane of
/// label `l`) that lie farther than `scales` noise scales from their region's plane (the noise scale: the plane's
/// RMS, at least [`SIGMA_FLOOR`]) and form, with their 4-neighbours of the same label that do too, a group of at
/// least `min_px` pixels; a lone outlier is noise and stays. Returns the number of pixels released. The groups do not
/// depend on the order of the scan, so neither does the result.
pub(crate) fn release(
    scene: &Scene<'_>,
    groups: &mut [u32],
    planes: &[Plane],
    (scales, min_px): (f64, usize),
    bufs: &mut Buffers,
) -> usize {
    let (w, h) = (scene.w, scene.h);
    let Buffers { state, outliers, stack, group, released: freed } = bufs;
    state.clear();
    state.resize(w * h, 0);
    // Room for every pixel once, reserved once, so later frames reuse the memory.
    for v in [&mut *outliers, &mut *stack, &mut *group] {
        v.clear();
        v.reserve(w * h);
    }
    freed.clear();
    freed.reserve(w * h);
    // Compiled for the best instruction set of this CPU (the same bits on every one).
    isa::dispatch(
        #[inline(always)]
        || {
            for (y, labels) in groups.chunks_exact(w.max(1)).enumerate() {
                if labels.iter().all(|&l| l == 0) {
                    continue;
                }
                let (vals, row) = scene.row(y);
                for (x, &l) in labels.iter().enumerate() {
                    if l == 0 || !vals[x].is_finite() {
                        continue;
                    }
                    let plane = &planes[l as usize - 1];
                    if plane.residual(row[x]) > scales * plane.rms.max(SIGMA_FLOOR) {
                        let i = y * w + x;
                        state[i] = 1;
                        outliers.push(i as u32);
                    }
                }
            }
        },
    );
    let mut released = 0;
    for &s in outliers.iter() {
        if state[s as usize] != 1 {
            continue;
        }
        let l = groups[s as usize];
        group.clear();
        stack.push(s);
        state[s as usize] = 2;
        while let Some(i) = stack.pop() {
            group.push(i);
            let i = i as usize;
            let (x, y) = (i % w, i / w);
            let mut visit = |j: usize| {
                if state[j] == 1 && groups[j] == l {
                    state[j] = 2;
                    stack.push(j as u32);
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
        if group.len() >= min_px {
            released += group.len();
            for &i in group.iter() {
                groups[i as usize] = 0;
                freed.push((i, l));
            }
        }
    }
    released
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plane::fit_plane;
    use planefit::Moments;
    use rangeimage::Camera;

    /// 40×30 grid image of the plane v = 100 with ±0.2 of checkerboard noise, raised by 3 units on the pixels
    /// `bump` picks; every pixel labelled `label(x, y)`. Returns the labels after [`release`] with the planes fitted
    /// to each label's pixels (bumps included) and the number released.
    fn released(
        bump: impl Fn(usize, usize) -> bool,
        label: impl Fn(usize, usize) -> u32,
    ) -> (Vec<u32>, usize) {
        let (w, h) = (40usize, 30usize);
        let range: Vec<f32> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let noise = if (x + y) % 2 == 0 { 0.2 } else { -0.2 };
                100.0 + noise + if bump(x, y) { 3.0 } else { 0.0 }
            })
            .collect();
        let camera = Camera::Grid;
        let mut points = Vec::new();
        let scene = Scene::new(&range, (w, h), &camera, &mut points);
        let mut groups: Vec<u32> = (0..w * h).map(|i| label(i % w, i / w)).collect();
        let mut moments = [Moments::default(); 2];
        for (i, &l) in groups.iter().enumerate() {
            moments[l as usize - 1].add(scene.point(i % w, i / w).unwrap());
        }
        let planes = moments.map(|m| fit_plane(&m, &camera));
        let before = groups.clone();
        let mut bufs = Buffers::default();
        let n = release(&scene, &mut groups, &planes, (2.5, 10), &mut bufs);
        // The released list names exactly the pixels left unlabelled, each with the label it had.
        let mut freed: Vec<(u32, u32)> =
            (0..w * h).filter(|&i| groups[i] == 0 && before[i] != 0).map(|i| (i as u32, before[i])).collect();
        let mut listed = bufs.released().to_vec();
        freed.sort_unstable();
        listed.sort_unstable();
        assert_eq!(listed, freed);
        (groups, n)
    }

    #[test]
    fn groups_of_outliers_are_released_and_noise_stays() {
        // A 4 × 4 bump (16 px), a 3 × 3 bump (9 px, under the 10 px limit) and a lone pixel.
        let big = |x: usize, y: usize| (5..9).contains(&x) && (5..9).contains(&y);
        let small = |x: usize, y: usize| (20..23).contains(&x) && (20..23).contains(&y);
        let lone = |x: usize, y: usize| (x, y) == (30, 5);
        let (groups, n) = released(|x, y| big(x, y) || small(x, y) || lone(x, y), |_, _| 1);
        assert_eq!(n, 16);
        for y in 0..30 {
            for x in 0..40 {
                assert_eq!(groups[y * 40 + x], if big(x, y) { 0 } else { 1 }, "({x}, {y})");
            }
        }
    }

    #[test]
    fn a_group_never_spans_two_labels() {
        // A 4 × 4 bump astride the border of two regions (x < 20 and x ≥ 20) is two groups of 8 px: both stay.
        let bump = |x: usize, y: usize| (18..22).contains(&x) && (5..9).contains(&y);
        let label = |x: usize, _: usize| if x < 20 { 1 } else { 2 };
        let (groups, n) = released(bump, label);
        assert_eq!(n, 0);
        assert!(groups.iter().enumerate().all(|(i, &l)| l == label(i % 40, i / 40)));
        // Within one region the same bump goes.
        let (_, n) = released(bump, |_, _| 1);
        assert_eq!(n, 16);
    }
}
