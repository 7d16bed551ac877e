//! The simple temporal network of a partial plan (`cbdi_planner.stn.Timeline`'s
//! numbers), exactly the Python reference's: which earlier steps a new one must follow,
//! and the earliest consistent times.
//!
//! A search keeps every node's network, each its parent's with one step more. What a
//! step is (its kind, partner, bound, snap code and incoming edges) never changes once
//! appended, so it lives in chunks of `CHUNK` steps that the networks share (a full
//! chunk is never written again; the last one is copied when a child appends to it);
//! only the times, which propagation may change anywhere, are each network's own.

use crate::{interferes, Interference, Touches};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::sync::Arc;

pub const END: u8 = 1;
pub const TIL: u8 = 3;
const TOL: f64 = 1e-9;
const CHUNK: usize = 16;
/// Room for edges a copied chunk gets (a step has a few incoming edges, mostly).
const EDGES_MORE: usize = 16;

/// One step: what `stn.Step` holds, its snap code, and where its incoming edges end in
/// its chunk's `edges`.
#[derive(Clone, Copy)]
struct Row {
    kind: u8,
    action: usize,
    partner: i64,
    low: f64,
    high: f64,
    code: usize,
    /// The step's `Touches::folds` (the first six), here beside its code: a scan for
    /// interfering steps reads these and looks a step's happening up only on a hit.
    folds: [u64; 6],
    edges_end: usize,
}

/// Up to `CHUNK` consecutive steps and their incoming edges, in two arrays (a copy of
/// the last chunk, when a child appends to it, is two allocations).
struct Chunk {
    rows: Vec<Row>,
    edges: Vec<(usize, f64)>,
}

impl Clone for Chunk {
    /// A copy with room for a chunk's rows and some edges more: a copy is made to be
    /// appended to.
    fn clone(&self) -> Self {
        let mut rows = Vec::with_capacity(CHUNK);
        rows.extend_from_slice(&self.rows);
        let mut edges = Vec::with_capacity(self.edges.len() + EDGES_MORE);
        edges.extend_from_slice(&self.edges);
        Chunk { rows, edges }
    }
}

impl Chunk {
    fn new() -> Self {
        Chunk {
            rows: Vec::with_capacity(CHUNK),
            edges: Vec::new(),
        }
    }

    fn edges(&self, j: usize) -> &[(usize, f64)] {
        let start = if j == 0 {
            0
        } else {
            self.rows[j - 1].edges_end
        };
        &self.edges[start..self.rows[j].edges_end]
    }
}

#[pyclass(frozen, module = "cbdi_planner_core")]
#[derive(Clone, Default)]
pub struct Schedule {
    chunks: Vec<Arc<Chunk>>,
    times: Vec<f64>,
    #[pyo3(get)]
    pub(crate) span: f64,
}

/// The happenings certain to come after a step: `(start step, end snap code)` of each
/// running action, `(time, snap code)` of each timed literal still to happen.
pub(crate) type Coming = (Vec<(usize, usize)>, Vec<(f64, usize)>);

/// `Coming` as `append` reads it.
#[derive(Clone, Copy)]
pub(crate) struct Future<'a> {
    pub ends: &'a [(usize, usize)],
    pub deadlines: &'a [(f64, usize)],
}

/// A running action's future end: its start step, its bound, the steps it must follow.
struct Wait {
    start: usize,
    high: f64,
    after: Vec<usize>,
}

#[pymethods]
impl Schedule {
    #[new]
    fn new() -> Self {
        Schedule::default()
    }

    /// The earliest time of each step.
    #[getter]
    fn times(&self) -> Vec<f64> {
        self.times.clone()
    }

    /// Each step's incoming edges `(earlier step, least distance)`.
    #[getter]
    fn edges(&self) -> Vec<Vec<(usize, f64)>> {
        (0..self.len())
            .map(|k| self.edges_of(k).collect())
            .collect()
    }

    /// `Timeline.extend`: the schedule with a step appended (its kind, action, partner,
    /// bounds and snap code), or None if inconsistent. `future` (None: not checked) holds
    /// the happenings certain to come: `(start step, end snap code)` of each running
    /// action, `(time, snap code)` of each timed literal still to happen.
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (oracle, kind, action, partner, low, high, code, future, epsilon))]
    fn extend(
        &self,
        py: Python<'_>,
        oracle: &Interference,
        kind: u8,
        action: usize,
        partner: i64,
        low: f64,
        high: f64,
        code: usize,
        future: Option<Coming>,
        epsilon: f64,
    ) -> PyResult<Option<Schedule>> {
        let n = self.len();
        let known = oracle.snaps.read().expect("interference lock").len();
        let ends_ok = future.as_ref().is_none_or(|(ends, deadlines)| {
            ends.iter().all(|&(s, c)| s <= n && c < known)
                && deadlines.iter().all(|&(_, c)| c < known)
        });
        let partner_ok = kind != END || (partner >= 0 && (partner as usize) < n);
        if code >= known || !ends_ok || !partner_ok {
            return Err(PyValueError::new_err(
                "a step or happening is unknown to the schedule",
            ));
        }
        let step = StepSpec {
            kind,
            action,
            partner,
            low,
            high,
            code,
        };
        Ok(py.detach(|| {
            let snaps = oracle.snaps.read().expect("interference lock");
            let mut out = self.clone();
            let future = future
                .as_ref()
                .map(|(ends, deadlines)| Future { ends, deadlines });
            out.append(&snaps, &step, future, epsilon).then_some(out)
        }))
    }

    /// Each step's `(kind, action, partner, low, high)`, as `stn.Step` has them.
    fn steps(&self) -> Vec<(u8, usize, i64, f64, f64)> {
        (0..self.len()).map(|k| self.step(k)).collect()
    }
}

/// A step to append: its kind, action (a timed literal's group), partner (-1: none),
/// bounds and snap code.
#[derive(Clone, Copy)]
pub(crate) struct StepSpec {
    pub kind: u8,
    pub action: usize,
    pub partner: i64,
    pub low: f64,
    pub high: f64,
    pub code: usize,
}

impl Schedule {
    pub(crate) fn len(&self) -> usize {
        self.times.len()
    }

    /// A copy with room for `steps` steps more.
    pub(crate) fn fork(&self, steps: usize) -> Schedule {
        let mut chunks = Vec::with_capacity(self.chunks.len() + 1);
        chunks.extend_from_slice(&self.chunks);
        let mut times = Vec::with_capacity(self.times.len() + steps);
        times.extend_from_slice(&self.times);
        Schedule {
            chunks,
            times,
            span: self.span,
        }
    }

    fn chunk(&self, k: usize) -> (&Chunk, usize) {
        (&self.chunks[k / CHUNK], k % CHUNK)
    }

    fn row(&self, k: usize) -> &Row {
        let (c, j) = self.chunk(k);
        &c.rows[j]
    }

    fn kind(&self, k: usize) -> u8 {
        self.row(k).kind
    }

    fn edges_of(&self, k: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let (c, j) = self.chunk(k);
        c.edges(j).iter().copied()
    }

    /// The steps (positions) that interfere with happening `with` (`stn._interfering`).
    fn interfering(&self, snaps: &[Touches], with: usize) -> Vec<usize> {
        let mut out = Vec::new();
        self.each_interfering(snaps, with, |k| out.push(k));
        out
    }

    /// Call `found` with each step (position, in order) that interferes with happening
    /// `with`.
    fn each_interfering(&self, snaps: &[Touches], with: usize, mut found: impl FnMut(usize)) {
        let b = &snaps[with];
        let g = &b.folds;
        for (i, chunk) in self.chunks.iter().enumerate() {
            for (j, row) in chunk.rows.iter().enumerate() {
                let f = &row.folds;
                let maybe = (f[1] & g[0])
                    | (f[0] & g[1])
                    | (f[2] & g[3])
                    | (f[3] & g[2])
                    | (f[5] & g[6])
                    | (f[4] & g[5]);
                if maybe != 0 && interferes(&snaps[row.code], b) {
                    found(i * CHUNK + j);
                }
            }
        }
    }

    /// Step k's `(kind, action, partner, low, high)`.
    pub(crate) fn step(&self, k: usize) -> (u8, usize, i64, f64, f64) {
        let r = self.row(k);
        (r.kind, r.action, r.partner, r.low, r.high)
    }

    /// Append a step (its time not yet set).
    fn push(&mut self, snap: &Touches, step: &StepSpec, incoming: &[(usize, f64)]) {
        if self.len().is_multiple_of(CHUNK) {
            self.chunks.push(Arc::new(Chunk::new()));
        }
        let chunk = Arc::make_mut(self.chunks.last_mut().expect("a chunk"));
        chunk.edges.extend_from_slice(incoming);
        let f = &snap.folds;
        chunk.rows.push(Row {
            kind: step.kind,
            action: step.action,
            partner: step.partner,
            low: step.low,
            high: step.high,
            code: step.code,
            folds: [f[0], f[1], f[2], f[3], f[4], f[5]],
            edges_end: chunk.edges.len(),
        });
    }

    /// `Timeline.extend` in place (several steps appended copy the schedule once): false
    /// when inconsistent, the schedule then half extended (to be dropped).
    pub(crate) fn append(
        &mut self,
        snaps: &[Touches],
        step: &StepSpec,
        future: Option<Future<'_>>,
        eps: f64,
    ) -> bool {
        let StepSpec {
            kind,
            partner,
            low,
            code,
            ..
        } = *step;
        let n = self.len();
        let mut incoming: Vec<(usize, f64)> = Vec::new();
        self.each_interfering(snaps, code, |i| incoming.push((i, eps)));
        if kind == END {
            incoming.push((partner as usize, low));
        }
        self.push(&snaps[code], step, &incoming);
        // `Timeline._base`
        let mut value = if kind == TIL { low } else { 0.0 };
        for &(i, w) in &incoming {
            if self.times[i] + w > value {
                value = self.times[i] + w;
            }
        }
        self.times.push(value);
        let mut waits = Vec::new();
        if let Some(Future { ends, .. }) = future {
            for &(start, end_code) in ends {
                let bound = self.row(start).high;
                if bound == f64::INFINITY {
                    continue;
                }
                let mut after: Vec<usize> = Vec::new();
                self.each_interfering(snaps, end_code, |k| {
                    if k != start {
                        after.push(k);
                    }
                });
                if !after.is_empty() {
                    waits.push(Wait {
                        start,
                        high: bound,
                        after,
                    });
                }
            }
        }
        let Some(touched) = self.settle(n, &waits, eps) else {
            return false;
        };
        if let Some(Future { deadlines, .. }) = future {
            for &(when, snap) in deadlines {
                let late = self
                    .interfering(snaps, snap)
                    .into_iter()
                    .any(|k| self.times[k] + eps > when + TOL);
                if late {
                    return false;
                }
            }
        }
        // Python's max(..., default=0.0) over the times of the steps that are not TILs:
        // times only grow (and are not negative), so the old span and the times that
        // changed (`touched` on) give it.
        let mut span = self.span;
        for k in touched..self.len() {
            if self.kind(k) != TIL && self.times[k] > span {
                span = self.times[k];
            }
        }
        self.span = span;
        true
    }

    /// `stn._settle`: propagate earliest times from step `first` on; None on a positive
    /// cycle, else the first step whose time may have changed.
    ///
    /// The schedule was consistent before (every bound held), and times only grow: a
    /// step's own bound (a timed literal's time, an action's longest duration, checked
    /// at its end) can break only where its time changed, so only those are checked
    /// (the Python reference checks them all, and finds the same).
    fn settle(&mut self, mut first: usize, waits: &[Wait], eps: f64) -> Option<usize> {
        let n = self.len();
        let mut touched = first;
        for _ in 0..n + 1 {
            touched = touched.min(first);
            for k in first..n {
                let (c, j) = (&self.chunks[k / CHUNK], k % CHUNK);
                let mut value = self.times[k];
                for &(i, w) in c.edges(j) {
                    if self.times[i] + w > value {
                        value = self.times[i] + w;
                    }
                }
                self.times[k] = value;
            }
            let mut lowest = n;
            for k in touched..n {
                let r = &self.chunks[k / CHUNK].rows[k % CHUNK];
                if r.kind == TIL {
                    if self.times[k] > r.high + TOL {
                        return None;
                    }
                } else if r.kind == END {
                    let p = r.partner as usize;
                    if self.times[k] - self.times[p] > r.high + TOL {
                        self.times[p] = self.times[k] - r.high;
                        lowest = lowest.min(p);
                    }
                }
            }
            for wait in waits {
                // Python's max() over the steps' times, then + eps.
                let mut latest = self.times[wait.after[0]];
                for &k in &wait.after[1..] {
                    if self.times[k] > latest {
                        latest = self.times[k];
                    }
                }
                let latest = latest + eps;
                if latest - self.times[wait.start] > wait.high + TOL {
                    self.times[wait.start] = latest - wait.high;
                    lowest = lowest.min(wait.start);
                }
            }
            if lowest == n {
                return Some(touched);
            }
            first = lowest;
        }
        None
    }
}
