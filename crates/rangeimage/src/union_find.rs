//! Union-find over labels `0..n` stored as a parent array (`parent[l] == l` for a root), shared by
//! the stages that merge regions or connect components.

/// The root of `a`'s set in the forest `parent`, halving the path on the way (every visited label
/// is pointed at its grandparent), so repeated queries stay near O(1).
///
/// # Panics
/// If a label on the path is out of `parent`'s range.
#[inline]
pub fn find(parent: &mut [u32], mut a: u32) -> u32 {
    while parent[a as usize] != a {
        let g = parent[parent[a as usize] as usize];
        parent[a as usize] = g;
        a = g;
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn find_returns_the_root_and_halves_the_path() {
        // The chain 4 → 3 → 2 → 1 → 0, and 5 alone.
        let mut parent = vec![0, 0, 1, 2, 3, 5];
        assert_eq!(find(&mut parent, 4), 0);
        // Path halving: 4 now points at 2, 2 at 0.
        assert_eq!(parent, vec![0, 0, 0, 2, 2, 5]);
        assert_eq!(find(&mut parent, 5), 5);
        assert!((0..5).all(|l| find(&mut parent, l) == 0));
    }
}
