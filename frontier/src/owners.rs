//! The cluster that owns each frontier cell, stored block by block like the map.

use crate::grid::{Cell, NEIGHBOURS_26};
use crate::map::{BLOCK_BITS, BLOCK_CELLS, BLOCK_MASK, NO_BLOCK, VoxelMap};

/// The offsets of the 26 neighbours' indices within a block (x fastest, then y, then z), for
/// a cell whose neighbours all lie in its block.
const NEIGHBOUR_INDEX_OFFSETS: [isize; 26] = {
    let mut out = [0; 26];
    let mut n = 0;
    while n < 26 {
        let [x, y, z] = NEIGHBOURS_26[n];
        out[n] = (x + (y << BLOCK_BITS) + (z << (2 * BLOCK_BITS))) as isize;
        n += 1;
    }
    out
};

/// A map from frontier cells to small integer handles: a dense block directory over the grid
/// and one array of handles per block that holds a frontier cell.
///
/// A lookup is two array reads instead of a hash probe; the region growing and the dirty
/// checks of an update make many of them, mostly in the same few blocks. Blocks that lose
/// their last cell are recycled.
#[derive(Debug, Clone, Default)]
pub(crate) struct Owners {
    /// Grid size in cells; all zero before the first [`Owners::reset`].
    dims: [u32; 3],
    block_dims: [u32; 3],
    /// Slot per block of the grid, or `NO_BLOCK`.
    directory: Vec<u32>,
    /// Handle + 1 per cell of each slot (0: not a frontier cell).
    slots: Vec<[u32; BLOCK_CELLS]>,
    /// Cells per slot and the directory entry of each slot.
    counts: Vec<u16>,
    homes: Vec<usize>,
    /// Slots with no cell, ready for reuse.
    free: Vec<u32>,
    len: usize,
}

impl Owners {
    /// Empties the store and sizes it for a grid of `dims` cells: a map's grid, whose block
    /// count [`VoxelMap::new`] bounds by [`MAX_BLOCKS`](crate::MAX_BLOCKS).
    pub(crate) fn reset(&mut self, dims: [u32; 3]) {
        self.dims = dims;
        self.block_dims = dims.map(|n| n.div_ceil(1 << BLOCK_BITS));
        let blocks = self.block_dims.iter().map(|&b| b as usize).product();
        self.directory.clear();
        self.directory.resize(blocks, NO_BLOCK);
        self.slots.clear();
        self.counts.clear();
        self.homes.clear();
        self.free.clear();
        self.len = 0;
    }

    /// The grid size the store was last reset for.
    pub(crate) fn dims(&self) -> [u32; 3] {
        self.dims
    }

    /// Number of cells with an owner.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// The directory entry and in-block index of `c`, `None` outside the grid.
    #[inline]
    fn locate(&self, c: Cell) -> Option<(usize, usize)> {
        if c.x >= self.dims[0] || c.y >= self.dims[1] || c.z >= self.dims[2] {
            return None;
        }
        let [bx, by, _] = self.block_dims.map(|v| v as usize);
        let b = |v: u32| (v >> BLOCK_BITS) as usize;
        let dir = b(c.x) + bx * (b(c.y) + by * b(c.z));
        // The same layout as the map's blocks.
        Some((dir, VoxelMap::index_in_block(c)))
    }

    /// The handle owning `c`.
    #[inline]
    pub(crate) fn get(&self, c: Cell) -> Option<u32> {
        let (dir, i) = self.locate(c)?;
        let slot = *self.directory.get(dir)?;
        let h = self.slots.get(slot as usize)?[i];
        h.checked_sub(1)
    }

    /// Calls `f` with the handle of every owned cell among the 26 neighbours of `c` (inside
    /// the grid), in no particular order.
    ///
    /// When the neighbourhood lies inside `c`'s block, the block is found once and the 26
    /// handles are read at fixed offsets from `c`'s index; an empty block ends the search.
    #[inline]
    pub(crate) fn for_each_neighbour(&self, c: Cell, mut f: impl FnMut(u32)) {
        const INNER: core::ops::RangeInclusive<u32> = 1..=BLOCK_MASK - 1;
        let m = BLOCK_MASK;
        let inner =
            INNER.contains(&(c.x & m)) && INNER.contains(&(c.y & m)) && INNER.contains(&(c.z & m));
        if let Some((dir, i)) = self.locate(c).filter(|_| inner) {
            let Some(cells) = self
                .directory
                .get(dir)
                .and_then(|&s| self.slots.get(s as usize))
            else {
                return;
            };
            for d in &NEIGHBOUR_INDEX_OFFSETS {
                if let Some(h) = cells
                    .get(i.wrapping_add_signed(*d))
                    .and_then(|h| h.checked_sub(1))
                {
                    f(h);
                }
            }
            return;
        }
        for d in &NEIGHBOURS_26 {
            let n = |v: u32, dv: i32| v.checked_add_signed(dv);
            if let (Some(x), Some(y), Some(z)) = (n(c.x, d[0]), n(c.y, d[1]), n(c.z, d[2]))
                && let Some(h) = self.get(Cell::new(x, y, z))
            {
                f(h);
            }
        }
    }

    /// Sets the owner of `c` to `handle`; `false` (and nothing stored) for a cell outside the
    /// grid or the handle `u32::MAX`.
    pub(crate) fn insert(&mut self, c: Cell, handle: u32) -> bool {
        let (Some((dir, i)), Some(value)) = (self.locate(c), handle.checked_add(1)) else {
            return false;
        };
        let slot = match self.directory[dir] {
            NO_BLOCK => self.allocate(dir),
            s => s as usize,
        };
        let old = core::mem::replace(&mut self.slots[slot][i], value);
        if old == 0 {
            self.counts[slot] += 1;
            self.len += 1;
        }
        true
    }

    /// Removes `c`; its handle, if it had one.
    pub(crate) fn remove(&mut self, c: Cell) -> Option<u32> {
        let (dir, i) = self.locate(c)?;
        let slot = self.directory[dir];
        if slot == NO_BLOCK {
            return None;
        }
        let s = slot as usize;
        let old = core::mem::replace(&mut self.slots[s][i], 0);
        let h = old.checked_sub(1)?;
        self.len -= 1;
        self.counts[s] -= 1;
        if self.counts[s] == 0 {
            self.directory[dir] = NO_BLOCK;
            self.free.push(slot);
        }
        Some(h)
    }

    /// Every cell with an owner and its handle, block by block.
    pub(crate) fn for_each(&self, mut f: impl FnMut(Cell, u32)) {
        let [bx, by, _] = self.block_dims;
        for (slot, (cells, &home)) in self.slots.iter().zip(&self.homes).enumerate() {
            if self.counts[slot] == 0 {
                continue;
            }
            let (bx, by) = (bx as usize, by as usize);
            // Block coordinates of a grid of u32 cell coordinates fit in u32.
            #[allow(clippy::cast_possible_truncation)]
            let (x, y, z) = (
                (home % bx) as u32,
                ((home / bx) % by) as u32,
                (home / (bx * by)) as u32,
            );
            let corner = Cell::new(x << BLOCK_BITS, y << BLOCK_BITS, z << BLOCK_BITS);
            for (i, &h) in (0u32..).zip(cells.iter()) {
                if h != 0 {
                    f(VoxelMap::cell_in_block(corner, i), h - 1);
                }
            }
        }
    }

    /// A slot for directory entry `dir`, reusing a free one if any.
    fn allocate(&mut self, dir: usize) -> usize {
        let home = dir;
        let slot = if let Some(s) = self.free.pop() {
            let s = s as usize;
            self.homes[s] = home;
            s
        } else {
            self.slots.push([0; BLOCK_CELLS]);
            self.counts.push(0);
            self.homes.push(home);
            self.slots.len() - 1
        };
        // Slots hold at least one cell each; a grid has far fewer than 2^32 · 512 frontier
        // cells that fit in memory.
        #[allow(clippy::cast_possible_truncation)]
        {
            self.directory[dir] = slot as u32;
        }
        slot
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use proptest::prelude::*;
    use std::collections::BTreeMap;

    proptest! {
        /// The store agrees with a plain map under any sequence of inserts and removes,
        /// including cells outside the grid and recycled blocks.
        #[test]
        fn owners_agree_with_a_map(
            ops in proptest::collection::vec(
                (any::<bool>(), 0u32..20, 0u32..20, 0u32..12, 0u32..5),
                1..300,
            ),
        ) {
            let dims = [17, 19, 9];
            let mut owners = Owners::default();
            owners.reset(dims);
            let mut reference = BTreeMap::new();
            for (insert, x, y, z, h) in ops {
                let c = Cell::new(x, y, z);
                let inside = x < dims[0] && y < dims[1] && z < dims[2];
                if insert {
                    prop_assert_eq!(owners.insert(c, h), inside);
                    if inside {
                        reference.insert(c, h);
                    }
                } else {
                    prop_assert_eq!(owners.remove(c), reference.remove(&c));
                }
                prop_assert_eq!(owners.get(c), reference.get(&c).copied());
                prop_assert_eq!(owners.len(), reference.len());
            }
            let mut all = BTreeMap::new();
            owners.for_each(|c, h| {
                all.insert(c, h);
            });
            prop_assert_eq!(all, reference);
        }
    }

    proptest! {
        /// The neighbours' handles are those found one `get` at a time, with the fast path
        /// (the neighbourhood inside one block) and the general one.
        #[test]
        fn neighbour_handles_equal_lookups(
            cells in proptest::collection::vec((0u32..17, 0u32..19, 0u32..9, 0u32..4), 1..200),
            probes in proptest::collection::vec((0u32..20, 0u32..20, 0u32..12), 1..50),
        ) {
            let mut owners = Owners::default();
            owners.reset([17, 19, 9]);
            for (x, y, z, h) in cells {
                owners.insert(Cell::new(x, y, z), h);
            }
            for (x, y, z) in probes {
                let c = Cell::new(x, y, z);
                let mut got = Vec::new();
                owners.for_each_neighbour(c, |h| got.push(h));
                let mut want: Vec<u32> = NEIGHBOURS_26
                    .iter()
                    .filter_map(|d| {
                        let n = |v: u32, dv: i32| v.checked_add_signed(dv);
                        Some(Cell::new(n(x, d[0])?, n(y, d[1])?, n(z, d[2])?))
                    })
                    .filter_map(|n| owners.get(n))
                    .collect();
                got.sort_unstable();
                want.sort_unstable();
                prop_assert_eq!(got, want);
            }
        }
    }

    #[test]
    fn the_largest_handle_is_refused() {
        let mut owners = Owners::default();
        owners.reset([4, 4, 4]);
        assert!(!owners.insert(Cell::new(1, 1, 1), u32::MAX));
        assert_eq!(owners.get(Cell::new(1, 1, 1)), None);
        assert!(owners.insert(Cell::new(1, 1, 1), u32::MAX - 1));
        assert_eq!(owners.get(Cell::new(1, 1, 1)), Some(u32::MAX - 1));
    }
}
