//! A set of small non-negative integers that iterates in CPython's order.
//!
//! The Python core iterates `set`s of fact and op indices where the order decides the
//! result (which achiever a relaxed plan takes first, the order floats are summed in).
//! CPython's set of ints is an open-addressing table (an int hashes to itself) probed
//! linearly nine slots, then by perturbation, and rebuilt at more than four times its
//! entries once three fifths of its slots are taken; iteration walks the table.
//! This is that table (`Objects/setobject.c`, CPython 3.11 and later, no deletions),
//! so the compiled core iterates exactly as the Python one does
//! (`tests/planner/test_compiled_core.py` checks it against `set`).

const LINEAR_PROBES: usize = 9;
const PERTURB_SHIFT: u32 = 5;
const EMPTY: usize = usize::MAX;

pub struct PySet {
    table: Vec<usize>,
    mask: usize,
    used: usize,
    /// The memory of the table before the last rebuild, for the next one.
    spare: Vec<usize>,
}

impl Default for PySet {
    fn default() -> Self {
        Self::new()
    }
}

impl PySet {
    pub fn new() -> Self {
        PySet {
            table: vec![EMPTY; 8],
            mask: 7,
            used: 0,
            spare: Vec::new(),
        }
    }

    /// `set.clear()`, keeping the memory.
    pub fn clear(&mut self) {
        self.table.clear();
        self.table.resize(8, EMPTY);
        self.mask = 7;
        self.used = 0;
    }

    /// Put `key` in `table` unless it is there; whether it was put.
    fn insert(table: &mut [usize], mask: usize, key: usize) -> bool {
        let mut i = key & mask;
        let mut perturb = key;
        loop {
            let probes = if i + LINEAR_PROBES <= mask {
                LINEAR_PROBES
            } else {
                0
            };
            for slot in &mut table[i..=i + probes] {
                if *slot == EMPTY {
                    *slot = key;
                    return true;
                }
                if *slot == key {
                    return false;
                }
            }
            perturb >>= PERTURB_SHIFT;
            i = (i.wrapping_mul(5).wrapping_add(1).wrapping_add(perturb)) & mask;
        }
    }

    /// `set.add`.
    pub fn add(&mut self, key: usize) {
        if !Self::insert(&mut self.table, self.mask, key) {
            return;
        }
        self.used += 1;
        if self.used * 5 < self.mask * 3 {
            return;
        }
        let least = if self.used > 50000 {
            self.used * 2
        } else {
            self.used * 4
        };
        let mut size = 8;
        while size <= least {
            size <<= 1;
        }
        let mut old = std::mem::take(&mut self.spare);
        old.clear();
        old.resize(size, EMPTY);
        std::mem::swap(&mut self.table, &mut old);
        self.mask = size - 1;
        for &key in old.iter().filter(|&&k| k != EMPTY) {
            Self::insert(&mut self.table, self.mask, key);
        }
        self.spare = old;
    }

    /// The keys in CPython's iteration order.
    pub fn iter(&self) -> impl Iterator<Item = usize> + '_ {
        self.table.iter().copied().filter(|&k| k != EMPTY)
    }
}
