//! FF's relaxed plan, extracted backwards from an explored graph
//! (`RelaxedPlanGraph._extract`), with the same sets in the same order.

use crate::graph::{Csr, Layers};
use crate::pyset::PySet;

/// Op kinds (`cbdi_planner.stn`).
pub const START: u8 = 0;
pub const END: u8 = 1;
pub const TIL: u8 = 3;

/// What extraction needs of a graph's ops beyond exploring it.
pub struct Ops<'a> {
    pub kind: &'a [u8],
    pub action: &'a [usize],
    pub pre: &'a Csr,
    pub add: &'a Csr,
    pub adders: &'a Csr,
    /// The start op of each action (-1: none).
    pub start_op: &'a [i64],
    pub duration: &'a [f64],
    /// Whether the durations sum to the same in any order (`sums_exactly`): then the
    /// chosen ops need no set that iterates in CPython's order.
    pub exact: bool,
}

/// Whether floats `values` sum exactly, so to the same in any order: all multiples of
/// one power of two 2^-k (k <= 64) whose sum of magnitudes is below 2^(53-k).
pub fn sums_exactly(values: &[f64]) -> bool {
    let mut k = 0i32;
    let mut total = 0.0f64;
    for &v in values {
        if !v.is_finite() {
            return false;
        }
        while (v * 2f64.powi(k)).fract() != 0.0 {
            k += 1;
            if k > 64 {
                return false;
            }
        }
        total += v.abs();
    }
    total * 2f64.powi(k) < 2f64.powi(52)
}

/// A relaxed plan's length, its helpful happenings `(kind, action)`, sorted, and the
/// sum of its actions' durations.
pub type Relaxed = (usize, Vec<(u8, usize)>, f64);

/// Which ops an extraction took and which facts it has achieved, kept between calls.
#[derive(Default)]
pub struct Marks {
    taken: Vec<bool>,
    done: Vec<bool>,
    buckets: Vec<PySet>,
    chosen: PySet,
    sought: Vec<usize>,
}

/// `marks` as `size` times false, in the memory it has (filled at once).
fn unmark(marks: &mut Vec<bool>, size: usize) {
    marks.truncate(size);
    marks.resize(size, false);
    marks.fill(false);
}

/// Extract the relaxed plan of `goals` from the layers of an exploration.
pub fn extract(
    ops: &Ops<'_>,
    goals: &[usize],
    layers: &Layers,
    til: usize,
    marks: &mut Marks,
) -> Relaxed {
    let Layers {
        level,
        achiever,
        op_level,
    } = layers;
    let top = goals.iter().map(|&g| level[g]).max().unwrap_or(0).max(0) as usize;
    let Marks {
        taken,
        done,
        buckets,
        chosen,
        sought,
    } = marks;
    if buckets.len() <= top {
        buckets.resize_with(top + 1, PySet::new);
    }
    for bucket in &mut buckets[..=top] {
        bucket.clear();
    }
    for &g in goals {
        buckets[level[g] as usize].add(g);
    }
    chosen.clear();
    unmark(taken, ops.kind.len());
    unmark(done, level.len());
    sought.clear();
    let (mut count, mut duration) = (0usize, 0.0f64);
    for depth in (1..=top).rev() {
        // An achiever's conditions lie in lower layers: the bucket in hand stays as it
        // is (the Python core would add a condition of a layer above to a bucket it has
        // passed, to no effect).
        let (lower, upper) = buckets.split_at_mut(depth);
        for g in upper[0].iter() {
            if done[g] {
                continue;
            }
            let k = achiever[g] as usize;
            if depth == 2 && ops.kind[k] == END {
                sought.push(g);
            }
            if taken[k] {
                continue;
            }
            taken[k] = true;
            if ops.exact {
                count += 1;
                duration += ops.duration[k];
            } else {
                chosen.add(k);
            }
            for &f in ops.add.get(k) {
                done[f as usize] = true;
            }
            for &p in ops.pre.get(k) {
                let p = p as usize;
                if level[p] > 0 && !done[p] && (level[p] as usize) < depth {
                    lower[level[p] as usize].add(p);
                }
            }
        }
    }
    let mut helpful: Vec<(u8, usize)> = Vec::new();
    if top >= 1 {
        for g in buckets[1].iter() {
            for &k in ops.adders.get(g) {
                let k = k as usize;
                if op_level[k] == 0 && (ops.kind[k] != TIL || ops.action[k] == til) {
                    helpful.push((ops.kind[k], ops.action[k]));
                }
            }
        }
    }
    for &g in sought.iter() {
        for &k in ops.adders.get(g) {
            let k = k as usize;
            if ops.kind[k] == END {
                let start = ops.start_op[ops.action[k]];
                if start >= 0 && op_level[start as usize] == 0 {
                    helpful.push((START, ops.action[k]));
                }
            }
        }
    }
    helpful.sort_unstable();
    helpful.dedup();
    if !ops.exact {
        for k in chosen.iter() {
            duration += ops.duration[k];
        }
        count = chosen.iter().count();
    }
    (count, helpful, duration)
}
