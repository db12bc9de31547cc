//! The dense row-major grid that every image in the workspace is.

use std::ops::{Index, IndexMut};

/// A dense `width × height` grid of `T`, row-major, top row first.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Default)]
pub struct Grid<T> {
    width: u32,
    height: u32,
    data: Vec<T>,
}

impl<T> Grid<T> {
    /// Wraps `data` as a `width × height` grid; `None` if the length does not match.
    pub fn from_vec(width: u32, height: u32, data: Vec<T>) -> Option<Self> {
        let n = (width as usize).checked_mul(height as usize)?;
        (data.len() == n).then_some(Self { width, height, data })
    }

    /// Builds a grid by calling `f(x, y)` for every pixel in row-major order.
    pub fn from_fn(width: u32, height: u32, mut f: impl FnMut(u32, u32) -> T) -> Self {
        let mut data = Vec::with_capacity(width as usize * height as usize);
        for y in 0..height {
            for x in 0..width {
                data.push(f(x, y));
            }
        }
        Self { width, height, data }
    }

    /// Builds a grid from rows of equal, non-zero length; `None` otherwise.
    pub fn from_rows(rows: Vec<Vec<T>>) -> Option<Self> {
        let height = u32::try_from(rows.len()).ok()?;
        let width = u32::try_from(rows.first()?.len()).ok()?;
        if width == 0 || rows.iter().any(|r| r.len() != width as usize) {
            return None;
        }
        Some(Self { width, height, data: rows.into_iter().flatten().collect() })
    }

    /// Width in pixels (number of columns).
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels (number of rows).
    pub fn height(&self) -> u32 {
        self.height
    }

    /// `(width, height)`.
    pub fn dimensions(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// True if the grid has no pixels.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// True if `(x, y)` lies inside the grid (signed, so neighbours can be tested directly).
    pub fn in_bounds(&self, x: i64, y: i64) -> bool {
        x >= 0 && y >= 0 && x < i64::from(self.width) && y < i64::from(self.height)
    }

    /// Linear index of `(x, y)` into [`Grid::as_slice`].
    ///
    /// # Panics
    /// In debug builds, if `(x, y)` is out of bounds.
    #[inline]
    pub fn index_of(&self, x: u32, y: u32) -> usize {
        debug_assert!(x < self.width && y < self.height, "({x}, {y}) outside {}×{}", self.width, self.height);
        y as usize * self.width as usize + x as usize
    }

    /// The pixel at `(x, y)`, or `None` outside the grid.
    pub fn get(&self, x: u32, y: u32) -> Option<&T> {
        (x < self.width && y < self.height).then(|| &self.data[self.index_of(x, y)])
    }

    /// The pixel at signed `(x, y)`, or `None` outside the grid.
    pub fn get_signed(&self, x: i64, y: i64) -> Option<&T> {
        self.in_bounds(x, y).then(|| &self.data[y as usize * self.width as usize + x as usize])
    }

    /// Mutable access to the pixel at `(x, y)`, or `None` outside the grid.
    pub fn get_mut(&mut self, x: u32, y: u32) -> Option<&mut T> {
        if x < self.width && y < self.height {
            let i = self.index_of(x, y);
            Some(&mut self.data[i])
        } else {
            None
        }
    }

    /// All pixels, row-major.
    pub fn as_slice(&self) -> &[T] {
        &self.data
    }

    /// All pixels, row-major, mutable.
    pub fn as_mut_slice(&mut self) -> &mut [T] {
        &mut self.data
    }

    /// Consumes the grid and returns its row-major pixels.
    pub fn into_vec(self) -> Vec<T> {
        self.data
    }

    /// Iterates over the rows, top first.
    pub fn rows(&self) -> std::slice::ChunksExact<'_, T> {
        self.data.chunks_exact(self.width.max(1) as usize)
    }

    /// Iterates over `(x, y, &pixel)` in row-major order.
    pub fn enumerate(&self) -> impl Iterator<Item = (u32, u32, &T)> {
        let w = self.width.max(1);
        self.data.iter().enumerate().map(move |(i, v)| ((i as u32) % w, (i as u32) / w, v))
    }

    /// A new grid of the same size with `f` applied to every pixel.
    pub fn map<U>(&self, f: impl FnMut(&T) -> U) -> Grid<U> {
        Grid { width: self.width, height: self.height, data: self.data.iter().map(f).collect() }
    }

    /// True if `other` has the same width and height.
    pub fn same_size<U>(&self, other: &Grid<U>) -> bool {
        self.width == other.width && self.height == other.height
    }
}

impl<T: Clone> Grid<T> {
    /// A `width × height` grid filled with `value`.
    pub fn new(width: u32, height: u32, value: T) -> Self {
        Self { width, height, data: vec![value; width as usize * height as usize] }
    }

    /// Makes this grid `width × height` and fills it with `value`, reusing its memory (no allocation when
    /// it already held as many pixels).
    pub fn reset(&mut self, width: u32, height: u32, value: T) {
        self.data.clear();
        self.data.resize(width as usize * height as usize, value);
        (self.width, self.height) = (width, height);
    }

    /// Makes this grid a copy of `other`, reusing its memory (no allocation when it already held as many
    /// pixels).
    pub fn copy_from(&mut self, other: &Grid<T>) {
        self.data.clone_from(&other.data);
        (self.width, self.height) = (other.width, other.height);
    }

    /// Makes this grid `other` with `f` applied to each pixel, reusing its memory.
    pub fn map_from<U>(&mut self, other: &Grid<U>, f: impl FnMut(&U) -> T) {
        self.data.clear();
        self.data.extend(other.data.iter().map(f));
        (self.width, self.height) = (other.width, other.height);
    }
}

impl<T> Index<(u32, u32)> for Grid<T> {
    type Output = T;

    #[inline]
    fn index(&self, (x, y): (u32, u32)) -> &T {
        assert!(x < self.width && y < self.height, "({x}, {y}) outside {}×{}", self.width, self.height);
        &self.data[y as usize * self.width as usize + x as usize]
    }
}

impl<T> IndexMut<(u32, u32)> for Grid<T> {
    #[inline]
    fn index_mut(&mut self, (x, y): (u32, u32)) -> &mut T {
        assert!(x < self.width && y < self.height, "({x}, {y}) outside {}×{}", self.width, self.height);
        &mut self.data[y as usize * self.width as usize + x as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_vec_checks_length() {
        assert!(Grid::from_vec(3, 2, vec![0u8; 6]).is_some());
        assert!(Grid::from_vec(3, 2, vec![0u8; 5]).is_none());
    }

    #[test]
    fn indexing_is_x_then_y() {
        let g = Grid::from_fn(3, 2, |x, y| 10 * y + x);
        assert_eq!(g[(2, 1)], 12);
        assert_eq!(g.get(2, 1), Some(&12));
        assert_eq!(g.get(3, 0), None);
        assert_eq!(g.get_signed(-1, 0), None);
        assert_eq!(g.rows().nth(1).unwrap(), &[10, 11, 12]);
        let e: Vec<_> = g.enumerate().map(|(x, y, v)| (x, y, *v)).collect();
        assert_eq!(e[4], (1, 1, 11));
    }

    #[test]
    fn from_rows_rejects_ragged() {
        assert!(Grid::from_rows(vec![vec![1, 2], vec![3]]).is_none());
        assert!(Grid::<u8>::from_rows(vec![]).is_none());
        let g = Grid::from_rows(vec![vec![1, 2], vec![3, 4]]).unwrap();
        assert_eq!(g[(0, 1)], 3);
    }

    #[test]
    fn macro_builds_range_image() {
        let r = crate::range_image![1.0, 2.0; f32::NAN, 3.0];
        assert_eq!(r.dimensions(), (2, 2));
        assert!(r[(0, 1)].is_nan());
        assert_eq!(r[(1, 1)], 3.0);
    }
}
