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
}

/// A relaxed plan's length, its helpful happenings `(kind, action)`, sorted, and the
/// sum of its actions' durations.
pub type Relaxed = (usize, Vec<(u8, usize)>, f64);

/// Which ops an extraction took and which facts it has achieved, kept between calls.
#[derive(Default)]
pub struct Marks {
    taken: Vec<bool>,
    done: Vec<bool>,
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
    let mut buckets: Vec<PySet> = (0..=top).map(|_| PySet::new()).collect();
    for &g in goals {
        buckets[level[g] as usize].add(g);
    }
    let mut chosen = PySet::new();
    let Marks { taken, done } = marks;
    taken.clear();
    taken.resize(ops.kind.len(), false);
    done.clear();
    done.resize(level.len(), false);
    let mut sought: Vec<usize> = Vec::new();
    for depth in (1..=top).rev() {
        let bucket: Vec<usize> = buckets[depth].iter().collect();
        for g in bucket {
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
            chosen.add(k);
            for &f in ops.add.get(k) {
                done[f as usize] = true;
            }
            for &p in ops.pre.get(k) {
                let p = p as usize;
                if level[p] > 0 && !done[p] {
                    buckets[level[p] as usize].add(p);
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
    for g in sought {
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
    let mut duration = 0.0;
    for k in chosen.iter() {
        duration += ops.duration[k];
    }
    (chosen.iter().count(), helpful, duration)
}
