//! Region boundaries of a label image, the one rule the final edge map and the evaluation share.

use crate::{EdgeMap, Grid, LabelImage};

/// Borders between regions: region pixels (`is_region(label)`) with a 4-neighbour in a different
/// region. Both sides of a border are marked; region-to-non-region transitions are not borders.
#[must_use]
pub fn region_borders(labels: &LabelImage, is_region: impl Fn(u32) -> bool) -> EdgeMap {
    boundaries(labels, is_region, false)
}

/// Boundaries of a segmentation: [`region_borders`], plus the non-region pixels whose 4-neighbours
/// include two different regions, so a one-pixel-wide unlabelled line between two regions (as
/// edge-based segmenters leave) counts as their boundary. Region-to-unlabelled transitions are not
/// boundaries.
#[must_use]
pub fn label_boundaries(labels: &LabelImage, is_region: impl Fn(u32) -> bool) -> EdgeMap {
    boundaries(labels, is_region, true)
}

fn boundaries(labels: &LabelImage, is_region: impl Fn(u32) -> bool, separators: bool) -> EdgeMap {
    let (w, h) = labels.dimensions();
    let at = |x: i64, y: i64| labels.get_signed(x, y).copied().filter(|&l| is_region(l));
    Grid::from_fn(w, h, |x, y| {
        let (x, y) = (i64::from(x), i64::from(y));
        let nb = [at(x - 1, y), at(x + 1, y), at(x, y - 1), at(x, y + 1)];
        match at(x, y) {
            Some(l) => nb.iter().any(|n| n.is_some_and(|m| m != l)),
            None if separators => {
                let mut it = nb.iter().flatten();
                it.next().is_some_and(|&first| it.any(|&m| m != first))
            }
            None => false,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn borders_are_two_sided_and_separators_join_only_label_boundaries() {
        let labels = Grid::from_rows(vec![vec![10, 10, 11, 11, 0, 12], vec![10, 10, 11, 11, 0, 12]]).unwrap();
        let b = region_borders(&labels, |l| l != 0);
        assert_eq!(b.rows().next().unwrap().to_vec(), vec![false, true, true, false, false, false]);
        // The unlabelled column separates 11 and 12: a segmentation boundary, not a region border.
        let s = label_boundaries(&labels, |l| l != 0);
        assert_eq!(s.rows().next().unwrap().to_vec(), vec![false, true, true, false, true, false]);
        // Which labels are regions is the caller's: with 11 not a region, nothing borders 10.
        let b = region_borders(&labels, |l| l == 10 || l == 12);
        assert!(b.as_slice().iter().all(|&e| !e));
    }
}
