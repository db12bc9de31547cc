//! Step 1 of the final segmentation: 4-connected components of the core pixels, by two-pass
//! union-find labelling.

use rangeimage::union_find::find;

/// 4-connected components of the `core` pixels, two neighbours connected only if their
/// `guide` labels are equal: (component per pixel, 0 = none, numbered from 1 in raster order
/// of each component's first pixel; component sizes). Two-pass union-find labelling.
#[cfg(test)]
pub(crate) fn components(core: &[bool], guide: Option<&[u32]>, w: usize, h: usize) -> (Vec<u32>, Vec<u32>) {
    let (mut lab, mut sizes) = (Vec::new(), Vec::new());
    components_into(core, guide, (w, h), &mut lab, &mut sizes, &mut Buffers::default());
    (lab, sizes)
}

/// The union-find forest of [`components_into`], kept between frames.
#[derive(Debug, Default)]
pub(crate) struct Buffers {
    /// Parent of each provisional label.
    parent: Vec<u32>,
    /// Final component of each provisional label (0 for label 0).
    pub(crate) id: Vec<u32>,
    /// Pixels of each provisional label.
    count: Vec<u32>,
}

/// [`components`] into `lab` and `sizes`, whose memory is reused like that of `bufs`.
#[cfg(test)]
pub(crate) fn components_into(
    core: &[bool],
    guide: Option<&[u32]>,
    (w, h): (usize, usize),
    lab: &mut Vec<u32>,
    sizes: &mut Vec<u32>,
    bufs: &mut Buffers,
) {
    provisional_into(core, guide, (w, h), lab, sizes, bufs);
    for l in lab.iter_mut() {
        *l = bufs.id[*l as usize];
    }
}

/// [`components_into`] but with the provisional labels left in `lab`: the component of provisional label `l` is
/// `bufs.id[l]` (0 for 0); `sizes` are the components' sizes. The caller maps the labels in its own pass.
pub(crate) fn provisional_into(
    core: &[bool],
    guide: Option<&[u32]>,
    (w, h): (usize, usize),
    lab: &mut Vec<u32>,
    sizes: &mut Vec<u32>,
    bufs: &mut Buffers,
) {
    let n_px = w * h;
    lab.clear();
    lab.resize(n_px, 0);
    // Provisional labels from 1; parent[l] ≤ l, so roots are the smallest label of a set. There is at most one
    // per pixel (a run of one pixel each): the room is reserved once, and touched only as far as used.
    let Buffers { parent, id, count } = bufs;
    parent.clear();
    parent.reserve(n_px + 1);
    parent.push(0);
    count.clear();
    count.reserve(n_px + 1);
    count.push(0);
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
            // Eight pixels at a time while all of them extend the run (the test without branches), then one by one.
            const STEP: usize = 8;
            while e + STEP <= w {
                let c = &core[row + e..row + e + STEP];
                let same = match guide {
                    None => c.iter().fold(true, |a, &v| a & v),
                    Some(gg) => {
                        c.iter().zip(&gg[row + e..row + e + STEP]).fold(true, |a, (&v, &u)| a & v & (u == g))
                    }
                };
                if !same {
                    break;
                }
                e += STEP;
            }
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
                    let ru = find(parent, u);
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
                count.push(0);
                l = parent.len() as u32 - 1;
            }
            lab[row + x..row + e].fill(l);
            count[l as usize] += (e - x) as u32;
            x = e;
        }
    }
    // A set's root is its smallest provisional label, the one created at its first pixel in
    // raster order; so numbering the roots in label order numbers the components in raster
    // order of their first pixel. parent[l] < l for non-roots, so one ascending pass resolves
    // every label.
    id.clear();
    id.reserve(n_px + 1);
    id.resize(parent.len(), 0);
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
    sizes.clear();
    sizes.reserve(n_px);
    sizes.resize(n as usize, 0);
    for (&c, &k) in id.iter().zip(count.iter()).skip(1) {
        sizes[c as usize - 1] += k;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
