//! Triangles laid out for the lane test ([`RayLanes::test`](super::RayLanes::test)):
//! each leaf's triangles in blocks of up to four, a block of `n` triangles in `10·n`
//! words: nine rows of `n` floats, row `3·j + axis` holding coordinate `axis` of vertex `j`
//! of each triangle, then the `n` triangles' ids (their bits). The lane test loads each
//! row it needs into four lanes as it is, where a leaf of triangles one after another
//! would need its vertices transposed into lanes first (four shuffles per vertex and
//! coordinate). A block takes the bytes its triangles would one after another (40 per
//! triangle: vertices and id), so a leaf is as many cache lines either way.
//!
//! A row is read as four lanes from its start: the lanes past `n` hold the words after the
//! row (the next row, or past the last row the ids and the next block), which the lane
//! test ignores. The words array ends with [`PAD`] zeros so that every block's read is in
//! bounds as a whole, in one check.

use glam::{Vec3, Vec4};

use crate::bvh::on_huge_pages;

/// Triangles per block: the lanes of one SIMD register.
pub const BLOCK: usize = 4;

/// Words per triangle: nine coordinates and an id.
const WORDS: usize = 10;

/// Words after the last triangle: a block is then always followed by at least a full
/// block's worth of words.
const PAD: usize = WORDS * BLOCK - WORDS;

/// Triangles with their ids in blocks of up to [`BLOCK`], in the order of the leaves they
/// were given in; triangle `i` of that order starts the block that holds it at word
/// `10·i` when it is the first of a block.
#[derive(Clone, Default, PartialEq)]
pub struct TriangleRows {
    words: Vec<f32>,
}

impl std::fmt::Debug for TriangleRows {
    // A summary: a mesh's rows may be millions of words.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TriangleRows")
            .field("words", &self.words.len())
            .finish()
    }
}

impl TriangleRows {
    /// Lays out `triangles` (vertices and id, in leaf order) for the leaves `(start,
    /// count)` of `leaves`, in order; each leaf's triangles go in blocks of four from its
    /// start, the last block holding the rest.
    ///
    /// # Panics
    /// If the leaves do not cover the triangles in order, each once.
    pub fn new(
        mut triangles: impl ExactSizeIterator<Item = ([Vec3; 3], u32)>,
        leaves: &[(u32, u32)],
    ) -> Self {
        let total = triangles.len();
        let mut words = Vec::with_capacity(WORDS * total + PAD);
        let mut next = 0;
        for &(start, count) in leaves {
            let start = start as usize;
            assert_eq!(start, next, "leaves out of order, or overlapping");
            next = start + count as usize;
            assert!(next <= total, "leaves past the last triangle");
            for (_, n) in blocks(start, count as usize) {
                match n {
                    1 => push_block::<1>(&mut words, &mut triangles),
                    2 => push_block::<2>(&mut words, &mut triangles),
                    3 => push_block::<3>(&mut words, &mut triangles),
                    _ => push_block::<4>(&mut words, &mut triangles),
                }
            }
        }
        assert_eq!(next, total, "leaves leave triangles out");
        words.resize(words.len() + PAD, 0.0);
        Self {
            words: on_huge_pages(words),
        }
    }

    /// Number of triangles.
    pub fn count(&self) -> usize {
        self.words.len().saturating_sub(PAD) / WORDS
    }

    /// The blocks of the leaf of the `count` triangles from triangle `start`, in order, as
    /// [`Self::new`] laid them out.
    #[inline(always)]
    pub fn leaf(&self, start: usize, count: usize) -> impl Iterator<Item = Block<'_>> {
        blocks(start, count).map(|(first, n)| self.block(first, n))
    }

    /// The block of the `n` (1 to [`BLOCK`]) triangles from triangle `first`, which must
    /// be where a block starts (see [`Self::leaf`]).
    #[inline(always)]
    fn block(&self, first: usize, n: usize) -> Block<'_> {
        debug_assert!((1..=BLOCK).contains(&n));
        let at = WORDS * first;
        Block {
            // One bounds check for every read of the block (see `PAD`).
            words: self.words[at..at + WORDS * BLOCK].try_into().unwrap(),
            n: n.min(BLOCK),
        }
    }

    /// The words of triangle `first` on, for prefetching.
    #[inline(always)]
    pub fn at(&self, first: usize) -> &f32 {
        &self.words[WORDS * first]
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.words.as_slice())
    }
}

/// The blocks of the leaf of the `count` triangles from triangle `start`, as (first
/// triangle, triangles): four each from the start, the last one the rest. Where blocks
/// start is decided here alone, for laying them out and for reading them.
#[inline(always)]
fn blocks(start: usize, count: usize) -> impl Iterator<Item = (usize, usize)> {
    let end = start + count;
    (start..end)
        .step_by(BLOCK)
        .map(move |first| (first, (end - first).min(BLOCK)))
}

/// Appends the block of the next `N` triangles of `triangles` to `words`. (`N` a constant,
/// so that each row's place is one too: a mesh's triangles are laid out in a few
/// instructions each.)
fn push_block<const N: usize>(
    words: &mut Vec<f32>,
    triangles: &mut impl Iterator<Item = ([Vec3; 3], u32)>,
) {
    let block: [_; N] =
        std::array::from_fn(|_| triangles.next().expect("as many triangles as leaves hold"));
    let mut rows = [[0.0; N]; WORDS];
    for (i, (v, id)) in block.into_iter().enumerate() {
        for j in 0..3 {
            for axis in 0..3 {
                rows[3 * j + axis][i] = v[j][axis];
            }
        }
        rows[9][i] = f32::from_bits(id);
    }
    words.extend_from_slice(rows.as_flattened());
}

/// One block of a [`TriangleRows`]: `n` triangles, and the words after them up to a
/// whole block's.
#[derive(Clone, Copy)]
pub struct Block<'a> {
    words: &'a [f32; WORDS * BLOCK],
    n: usize,
}

impl Block<'_> {
    /// Number of triangles.
    #[inline(always)]
    pub fn count(&self) -> usize {
        self.n
    }

    /// Where the rows of coordinate `axis` start, for [`Self::row`].
    #[inline(always)]
    pub(super) fn axis(&self, axis: usize) -> usize {
        axis * self.n
    }

    /// Row `3·j + axis` in four lanes, for `at` = [`Self::axis`]`(axis)`: coordinate
    /// `axis` of vertex `j` of each triangle in lanes `..n`, arbitrary words in the others.
    #[inline(always)]
    pub(super) fn row(&self, j: usize, at: usize) -> Vec4 {
        let at = 3 * j * self.n + at;
        Vec4::from_slice(&self.words[at..at + 4])
    }

    /// The vertices of triangle `i`.
    #[inline(always)]
    pub fn vertices(&self, i: usize) -> [Vec3; 3] {
        let n = self.n;
        let vertex = |j: usize| {
            let at = 3 * j * n + i;
            Vec3::new(self.words[at], self.words[at + n], self.words[at + 2 * n])
        };
        [vertex(0), vertex(1), vertex(2)]
    }

    /// The id of triangle `i`.
    #[inline(always)]
    pub fn id(&self, i: usize) -> u32 {
        self.words[9 * self.n + i].to_bits()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_hold_each_leafs_triangles_in_rows() {
        let sizes = [3, 1, 4, 9, 2, 5, 8, 6, 7];
        let total: u32 = sizes.iter().sum();
        // Ids whose bits are NaNs, infinities and subnormals as floats keep their bits.
        let ids = [0, 1, 0x7f80_0000, 0x7f80_0001, 0xffc0_0000, u32::MAX];
        let triangles: Vec<([Vec3; 3], u32)> = (0..total)
            .map(|i| {
                let f = i as f32;
                let v = |j: f32| Vec3::new(f + j, -f - j / 8.0, f * j + 0.5);
                ([v(0.0), v(1.0), v(2.0)], ids[i as usize % ids.len()] ^ i)
            })
            .collect();
        let leaves: Vec<(u32, u32)> = sizes
            .iter()
            .scan(0, |start, &count| {
                *start += count;
                Some((*start - count, count))
            })
            .collect();
        let rows = TriangleRows::new(triangles.iter().copied(), &leaves);
        assert_eq!(rows.count(), triangles.len());
        assert_eq!(rows.memory_bytes(), 4 * (WORDS * total as usize + PAD));
        for (start, count) in leaves {
            let (start, count) = (start as usize, count as usize);
            let blocks: Vec<Block> = rows.leaf(start, count).collect();
            let chunks: Vec<_> = triangles[start..start + count].chunks(BLOCK).collect();
            assert_eq!(blocks.len(), chunks.len());
            for (block, chunk) in blocks.iter().zip(chunks) {
                assert_eq!(block.count(), chunk.len());
                for (i, (v, id)) in chunk.iter().enumerate() {
                    assert_eq!(block.vertices(i), *v);
                    assert_eq!(block.id(i), *id);
                    for (j, axis) in (0..3).flat_map(|j| (0..3).map(move |axis| (j, axis))) {
                        assert_eq!(block.row(j, block.axis(axis))[i], v[j][axis]);
                    }
                }
            }
        }
        assert_eq!(TriangleRows::default().count(), 0);
    }

    /// `n` copies of one triangle.
    fn triangles(n: usize) -> impl ExactSizeIterator<Item = ([Vec3; 3], u32)> {
        std::iter::repeat_n(([Vec3::ZERO, Vec3::X, Vec3::Y], 0), n)
    }

    #[test]
    #[should_panic(expected = "leaves out of order, or overlapping")]
    fn leaves_must_come_in_order() {
        TriangleRows::new(triangles(4), &[(3, 1), (0, 3)]);
    }

    #[test]
    #[should_panic(expected = "leaves leave triangles out")]
    fn leaves_must_cover_every_triangle() {
        TriangleRows::new(triangles(4), &[(0, 3)]);
    }

    #[test]
    #[should_panic(expected = "leaves past the last triangle")]
    fn leaves_must_not_reach_past_the_triangles() {
        TriangleRows::new(triangles(4), &[(0, 3), (3, 2)]);
    }
}
