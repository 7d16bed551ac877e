//! cbdi planner's compiled search core.
//!
//! The Python core (`cbdi_planner.heuristic`) is the reference: every function here does
//! exactly what its Python twin does, in the same order and with the same floating-point
//! operations, so that a search gives the same states, expansions and plans with either
//! (`tests/planner/test_compiled_core.py` checks it). What is here so far: a state's
//! whole heuristic estimate in one call (`RelaxedPlanGraph.estimate`: the layered
//! exploration of the temporal relaxed planning graph and FF's relaxed plan extracted
//! from it, with CPython's set order emulated where it decides, `pyset`), the hottest
//! part of a search, the simple temporal network of a partial plan
//! (`cbdi_planner.stn.Timeline`): which earlier steps a new one must follow, and the
//! earliest consistent times, and a node's successors (`Expander.moves`: every
//! happening applied in one call, `moves`, with the semantics of `apply`) and a move's
//! steps put on its timeline in one call (`Expander.schedule`), and whole search loops
//! in one call over nodes kept here (`search`): the offline planner's enforced
//! hill-climbing and best-first search (`climb`), the continual planner's rounds with
//! their open and closed lists (`rounds`).
//!
//! A call runs without the interpreter lock: a service's event loop keeps going while
//! its planner explores (a loop takes it back only to call a Python clock).

mod apply;
mod climb;
mod extract;
mod graph;
mod moves;
mod numeric;
mod pyset;
mod rounds;
mod schedule;
mod search;
mod starts;

use graph::Graph;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use schedule::Schedule;

/// What a happening reads and writes (`cbdi_planner.task.Snap`), as sorted bit positions.
pub(crate) struct Touches {
    reads: Vec<u32>,
    writes: Vec<u32>,
    add: Vec<u32>,
    dele: Vec<u32>,
    num_reads: Vec<u32>,
    num_writes: Vec<u32>,
    num_any: Vec<u32>,
    /// Each list above folded into 64 bits (bit `x % 64` for each `x`), in that order:
    /// two lists whose folds share no bit share no element.
    folds: [u64; 7],
}

fn fold(bits: &[u32]) -> u64 {
    bits.iter().fold(0, |acc, &x| acc | 1u64 << (x % 64))
}

/// Whether two sorted lists share an element.
fn meet(a: &[u32], b: &[u32]) -> bool {
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        match a[i].cmp(&b[j]) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => return true,
        }
    }
    false
}

/// `stn.interferes(a, b)`: whether two happenings must be ordered.
pub(crate) fn interferes(a: &Touches, b: &Touches) -> bool {
    let (f, g) = (&a.folds, &b.folds);
    if (f[1] & g[0]) | (f[0] & g[1]) | (f[2] & g[3]) | (f[3] & g[2]) | (f[5] & g[6]) | (f[4] & g[5])
        == 0
    {
        return false; // the exact test below would find no shared element
    }
    meet(&a.writes, &b.reads)
        || meet(&a.reads, &b.writes)
        || meet(&a.add, &b.dele)
        || meet(&a.dele, &b.add)
        || meet(&a.num_writes, &b.num_any)
        || meet(&a.num_reads, &b.num_writes)
}

/// The happenings of a search, each under a code, and which of them interfere
/// (`cbdi_planner.stn`: which earlier steps a step must follow).
#[pyclass(frozen, module = "cbdi_planner_core")]
pub(crate) struct Interference {
    pub(crate) snaps: std::sync::RwLock<Vec<Touches>>,
}

fn sorted(mut bits: Vec<u32>) -> Vec<u32> {
    bits.sort_unstable();
    bits.dedup();
    bits
}

#[pymethods]
impl Interference {
    #[new]
    fn new() -> Self {
        Interference {
            snaps: std::sync::RwLock::new(Vec::new()),
        }
    }

    /// Add a happening by the bit positions of its masks; return its code.
    fn add(
        &self,
        reads: Vec<u32>,
        writes: Vec<u32>,
        add: Vec<u32>,
        dele: Vec<u32>,
        num_reads: Vec<u32>,
        num_writes: Vec<u32>,
    ) -> usize {
        let num_any = sorted([num_reads.clone(), num_writes.clone()].concat());
        let mut touches = Touches {
            reads: sorted(reads),
            writes: sorted(writes),
            add: sorted(add),
            dele: sorted(dele),
            num_reads: sorted(num_reads),
            num_writes: sorted(num_writes),
            num_any,
            folds: [0; 7],
        };
        touches.folds = [
            fold(&touches.reads),
            fold(&touches.writes),
            fold(&touches.add),
            fold(&touches.dele),
            fold(&touches.num_reads),
            fold(&touches.num_writes),
            fold(&touches.num_any),
        ];
        let mut snaps = self.snaps.write().expect("interference lock");
        snaps.push(touches);
        snaps.len() - 1
    }

    /// The positions in `steps` (codes of a plan's happenings, in order) of those that
    /// interfere with happening `with` (`stn._interfering`).
    fn interfering(&self, py: Python<'_>, steps: Vec<usize>, with: usize) -> PyResult<Vec<usize>> {
        let snaps = self.snaps.read().expect("interference lock");
        if let Some(bad) = steps
            .iter()
            .chain(std::iter::once(&with))
            .find(|&&c| c >= snaps.len())
        {
            return Err(PyValueError::new_err(format!(
                "no happening has code {bad}"
            )));
        }
        drop(snaps);
        Ok(py.detach(|| {
            let snaps = self.snaps.read().expect("interference lock");
            interfering(&snaps, &steps, with)
        }))
    }
}

/// The positions of the steps (by code) that interfere with happening `with`.
fn interfering(snaps: &[Touches], steps: &[usize], with: usize) -> Vec<usize> {
    let b = &snaps[with];
    steps
        .iter()
        .enumerate()
        .filter(|(_, &code)| interferes(&snaps[code], b))
        .map(|(k, _)| k)
        .collect()
}

/// The order in which CPython's `set` iterates `keys` added one by one (the compiled
/// core's emulation of it, which the tests check against `set`).
#[pyfunction]
fn set_order(keys: Vec<usize>) -> Vec<usize> {
    let mut set = pyset::PySet::new();
    for key in keys {
        set.add(key);
    }
    set.iter().collect()
}

/// Whether floats sum to the same in any order (`extract::sums_exactly`).
#[pyfunction]
fn sums_exactly(values: Vec<f64>) -> bool {
    extract::sums_exactly(&values)
}

#[pymodule]
fn cbdi_planner_core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(set_order, m)?)?;
    m.add_function(wrap_pyfunction!(sums_exactly, m)?)?;
    m.add_class::<Graph>()?;
    m.add_class::<Interference>()?;
    m.add_class::<moves::Moves>()?;
    m.add_class::<moves::Placing>()?;
    m.add_class::<Schedule>()?;
    m.add_class::<rounds::Rounds>()?;
    m.add_class::<search::Search>()?;
    m.add_class::<search::SearchNode>()?;
    m.add_class::<starts::Starts>()?;
    Ok(())
}
