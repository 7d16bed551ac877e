//! A node's successors in one call (`cbdi_planner.expansion.Expander.moves`), and a
//! move's steps put on a timeline in one call (`Expander.schedule`).
//!
//! `Moves.moves` applies every happening a node may take, in the Python core's order:
//! the end of each running action, the next group of timed literals, then each action
//! that may start (its start, or with `compress` its start and end at once), checking
//! conditions, the invariants of the actions running after it and duration bounds
//! (`cbdi_planner.state`). It returns what the Python core builds its `State`s and
//! `Step`s from, and a `Placing` of the steps that `Moves.schedule` appends to a
//! schedule with the happenings certain to come after each (`Expander._future`).

use crate::apply::{check_within, test, Conj, Duration, Facts, Snap};
use crate::schedule::{Future, Schedule, StepSpec, END};
use crate::starts::Starts;
use crate::{Interference, Touches};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyTuple};

pub(crate) const START: u8 = 0;
pub(crate) const INST: u8 = 2;
pub(crate) const TIL: u8 = 3;

struct Action {
    start: Snap,
    end: Option<Snap>,
    inv: Conj,
    duration: Duration,
    /// The snap codes (`Interference`) of its start and end (the start's if none).
    codes: (usize, usize),
}

struct Til {
    time: f64,
    add: Vec<u32>,
    dele: Vec<u32>,
    code: usize,
}

/// One step of a move as the schedule takes it: `(kind, action, partner, low, high)`
/// as `stn.Step` has them, the actions running after it (`(action, start step)`) and
/// the timed literals still to come (from group `til` on).
pub(crate) struct Scheduled {
    pub kind: u8,
    pub action: usize,
    pub partner: i64,
    pub low: f64,
    pub high: f64,
    pub running: Vec<(usize, usize)>,
    pub til: usize,
}

/// One step of a move and the state after it.
pub(crate) struct Placed {
    pub step: Scheduled,
    pub facts: Facts,
    /// None: the node's values.
    pub nums: Option<Vec<f64>>,
    pub open: Vec<usize>,
}

/// The steps of a move, to schedule (`Moves.schedule`).
#[pyclass(frozen, module = "cbdi_planner_core")]
pub struct Placing {
    steps: Vec<Scheduled>,
}

/// A node as `moves` reads it.
pub(crate) struct Node<'a> {
    pub facts: &'a [u64],
    pub nums: &'a [f64],
    pub open: &'a [usize],
    pub til: usize,
    /// `(action, start step, low, high)` of each running action.
    pub running: &'a [(usize, usize, f64, f64)],
    pub steps: usize,
}

#[pyclass(frozen, module = "cbdi_planner_core")]
pub struct Moves {
    actions: Vec<Action>,
    tils: Vec<Til>,
    starts: Starts,
    /// `(time, snap code)` of each group of timed literals, in order.
    coming: Vec<(f64, usize)>,
    words: usize,
    vars: usize,
    oracle: Py<Interference>,
}

fn bytes_of(facts: &[u64]) -> Vec<u8> {
    facts.iter().flat_map(|w| w.to_le_bytes()).collect()
}

#[pymethods]
impl Moves {
    /// `actions[a]`: `(start, end or None, invariant, fixed duration or None, duration
    /// constraints, start code, end code)` (snaps as `apply::Snap::of` reads them, the
    /// invariant as `Conj::of`); `tils[j]`: `(time, add, dele, code)`; `needs[a]`: the
    /// facts action `a` needs before it starts; `facts`: how many facts; codes of
    /// `oracle`.
    #[new]
    fn new(
        oracle: Py<Interference>,
        actions: Vec<Bound<'_, PyAny>>,
        tils: Vec<(f64, Vec<u32>, Vec<u32>, usize)>,
        needs: Vec<Vec<u32>>,
        facts: usize,
    ) -> PyResult<Self> {
        let known = oracle.get().snaps.read().expect("interference lock").len();
        let mut out = Vec::with_capacity(actions.len());
        let (mut most_fact, mut vars) = (0, 0);
        for spec in &actions {
            type Spec<'py> = (
                Bound<'py, PyAny>,
                Option<Bound<'py, PyAny>>,
                Bound<'py, PyAny>,
                Option<f64>,
                Vec<Bound<'py, PyAny>>,
                usize,
                usize,
            );
            let (start, end, inv, fixed, duration, s, e): Spec<'_> = spec.extract()?;
            let action = Action {
                start: Snap::of(&start)?,
                end: end.as_ref().map(Snap::of).transpose()?,
                inv: Conj::of(&inv)?,
                duration: Duration::of(fixed, &duration)?,
                codes: (s, e),
            };
            if s >= known || e >= known {
                return Err(PyValueError::new_err("a snap code unknown to the oracle"));
            }
            for snap in std::iter::once(&action.start).chain(&action.end) {
                most_fact = most_fact.max(snap.facts());
                vars = vars.max(snap.vars());
            }
            let inv_bits = action.inv.pre.iter().chain(&action.inv.neg);
            most_fact = most_fact.max(inv_bits.map(|&b| b as usize + 1).max().unwrap_or(0));
            vars = vars.max(action.duration.vars());
            vars = vars.max(action.inv.vars());
            out.push(action);
        }
        let tils: Vec<Til> = tils
            .into_iter()
            .map(|(time, add, dele, code)| Til {
                time,
                add,
                dele,
                code,
            })
            .collect();
        for til in &tils {
            let bits = til.add.iter().chain(&til.dele);
            most_fact = most_fact.max(bits.map(|&b| b as usize + 1).max().unwrap_or(0));
            if til.code >= known {
                return Err(PyValueError::new_err("a snap code unknown to the oracle"));
            }
        }
        check_within("a fact", most_fact, facts)?;
        if needs.len() != out.len() || needs.iter().flatten().any(|&f| f as usize >= facts) {
            return Err(PyValueError::new_err("needs: one list of facts per action"));
        }
        let coming = tils.iter().map(|t| (t.time, t.code)).collect();
        Ok(Moves {
            actions: out,
            tils,
            starts: Starts::new(needs),
            coming,
            words: facts.div_ceil(64).max(1),
            vars,
            oracle,
        })
    }

    /// `Expander.moves` of a node: its state (`facts` as the little-endian bytes of the
    /// int, `nums`, `open`, `til`), its running actions `(action, start step, low,
    /// high)`, how many steps its timeline has, the helpful actions to start (sorted;
    /// None: all whose needs hold). Each move is `(placing, *steps)`, a step being
    /// `(kind, action, partner, low, high, facts, nums or None: the node's, open, til,
    /// running)`.
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (facts, nums, open, til, running, steps, helpful, compress, epsilon))]
    fn moves<'py>(
        &self,
        py: Python<'py>,
        facts: &Bound<'py, PyBytes>,
        nums: Vec<f64>,
        open: Vec<usize>,
        til: usize,
        running: Vec<(usize, usize, f64, f64)>,
        steps: usize,
        helpful: Option<Vec<u32>>,
        compress: bool,
        epsilon: f64,
    ) -> PyResult<Vec<Bound<'py, PyTuple>>> {
        let packed = facts.as_bytes();
        let n = self.actions.len();
        let bad = packed.len() > self.words * 8
            || nums.len() < self.vars
            || til > self.tils.len()
            || open.iter().any(|&a| a >= n)
            || running.iter().any(|&(a, s, _, _)| a >= n || s >= steps)
            || helpful.iter().flatten().any(|&a| a as usize >= n);
        if bad {
            return Err(PyValueError::new_err("a state outside the task"));
        }
        let mut words = vec![0u64; self.words];
        for (i, &byte) in packed.iter().enumerate() {
            words[i / 8] |= u64::from(byte) << (8 * (i % 8));
        }
        let candidates = match helpful {
            Some(h) => h,
            None => self.starts.within(packed),
        };
        let node = Node {
            facts: &words,
            nums: &nums,
            open: &open,
            til,
            running: &running,
            steps,
        };
        let found = py.detach(|| self.generate(&node, &candidates, compress, epsilon));
        found
            .into_iter()
            .map(|placed| {
                let mut items = Vec::with_capacity(placed.len() + 1);
                let mut steps = Vec::with_capacity(placed.len());
                for p in placed {
                    let nums = match &p.nums {
                        Some(v) => PyTuple::new(py, v)?.into_any(),
                        None => py.None().into_bound(py),
                    };
                    let s = &p.step;
                    let item = (
                        s.kind,
                        s.action,
                        s.partner,
                        s.low,
                        s.high,
                        PyBytes::new(py, &bytes_of(&p.facts)),
                        nums,
                        PyTuple::new(py, &p.open)?,
                        s.til,
                        PyTuple::new(py, &s.running)?,
                    );
                    items.push(item.into_pyobject(py)?.into_any());
                    steps.push(p.step);
                }
                items.insert(0, Bound::new(py, Placing { steps })?.into_any());
                PyTuple::new(py, items)
            })
            .collect()
    }

    /// `Expander.schedule`: `net` with the steps of `placing` appended, each with the
    /// happenings certain to come after it (None: inconsistent).
    fn schedule(
        &self,
        py: Python<'_>,
        net: &Schedule,
        placing: &Placing,
        epsilon: f64,
    ) -> PyResult<Option<Schedule>> {
        let n = net.len();
        for (k, p) in placing.steps.iter().enumerate() {
            let partner_ok = p.kind != END || (p.partner >= 0 && (p.partner as usize) < n + k);
            let running_ok = p.running.iter().all(|&(_, s)| s <= n + k);
            if !partner_ok || !running_ok || p.til > self.tils.len() {
                return Err(PyValueError::new_err(
                    "a step or happening is unknown to the schedule",
                ));
            }
        }
        Ok(py.detach(|| {
            let snaps = self.oracle.get().snaps.read().expect("interference lock");
            self.placed(&snaps, net, &placing.steps, epsilon)
        }))
    }
}

impl Moves {
    /// `net` with `steps` appended, each with the happenings certain to come after it
    /// (None: inconsistent).
    pub(crate) fn placed(
        &self,
        snaps: &[Touches],
        net: &Schedule,
        steps: &[Scheduled],
        epsilon: f64,
    ) -> Option<Schedule> {
        let mut out = net.fork(steps.len());
        for p in steps {
            let ends: Vec<(usize, usize)> = p
                .running
                .iter()
                .map(|&(a, s)| (s, self.actions[a].codes.1))
                .collect();
            let coming = Future {
                ends: &ends,
                deadlines: &self.coming[p.til..],
            };
            let code = match p.kind {
                TIL => self.tils[p.action].code,
                END => self.actions[p.action].codes.1,
                _ => self.actions[p.action].codes.0,
            };
            let step = StepSpec {
                kind: p.kind,
                action: p.action,
                partner: p.partner,
                low: p.low,
                high: p.high,
                code,
            };
            if !out.append(snaps, &step, Some(coming), epsilon) {
                return None;
            }
        }
        Some(out)
    }

    /// The actions whose needs hold in `packed` facts (little-endian bytes), sorted.
    pub(crate) fn startable(&self, packed: &[u8]) -> Vec<u32> {
        self.starts.within(packed)
    }

    /// How many words a state's facts take.
    pub(crate) fn words(&self) -> usize {
        self.words
    }

    /// How many numeric values a state has at least.
    pub(crate) fn vars(&self) -> usize {
        self.vars
    }

    /// How many actions the task has.
    pub(crate) fn actions(&self) -> usize {
        self.actions.len()
    }

    /// The interference of the task's snaps.
    pub(crate) fn oracle(&self) -> &Interference {
        self.oracle.get()
    }

    /// Whether the invariants of actions `running` hold.
    fn invariants_hold(&self, running: &[usize], facts: &[u64], nums: &[f64]) -> bool {
        running
            .iter()
            .all(|&a| self.actions[a].inv.holds(facts, nums))
    }

    /// `state.apply_end`: end running action `a` (None: not running or not applicable).
    fn end(
        &self,
        a: usize,
        facts: &[u64],
        nums: &[f64],
        open: &[usize],
    ) -> Option<(Facts, Option<Vec<f64>>, Vec<usize>)> {
        let snap = self.actions[a].end.as_ref()?;
        if !open.contains(&a) {
            return None;
        }
        let (facts, values) = snap.fire(facts, nums)?;
        let open: Vec<usize> = open.iter().copied().filter(|&i| i != a).collect();
        let after = values.as_deref().unwrap_or(nums);
        if !self.invariants_hold(&open, &facts, after) {
            return None;
        }
        Some((facts, values, open))
    }

    pub(crate) fn generate(
        &self,
        node: &Node<'_>,
        candidates: &[u32],
        compress: bool,
        epsilon: f64,
    ) -> Vec<Vec<Placed>> {
        let mut out = Vec::new();
        for &(a, start, low, high) in node.running {
            let Some((facts, nums, open)) = self.end(a, node.facts, node.nums, node.open) else {
                continue;
            };
            let running = node.running.iter().filter(|r| r.0 != a);
            let step = Scheduled {
                kind: END,
                action: a,
                partner: start as i64,
                low,
                high,
                running: running.map(|&(i, s, _, _)| (i, s)).collect(),
                til: node.til,
            };
            out.push(vec![Placed {
                step,
                facts,
                nums,
                open,
            }]);
        }
        if let Some(til) = self.tils.get(node.til) {
            let mut facts = node.facts.to_vec();
            for &f in &til.dele {
                facts[(f / 64) as usize] &= !(1u64 << (f % 64));
            }
            for &f in &til.add {
                facts[(f / 64) as usize] |= 1u64 << (f % 64);
            }
            if self.invariants_hold(node.open, &facts, node.nums) {
                let step = node.step(TIL, node.til, til.time, til.time);
                let step = Scheduled {
                    til: node.til + 1,
                    ..step
                };
                out.push(vec![Placed {
                    step,
                    facts,
                    nums: None,
                    open: node.open.to_vec(),
                }]);
            }
        }
        for &a in candidates {
            let a = a as usize;
            let needs = &self.starts.needs[a];
            if !needs.iter().all(|&f| test(node.facts, f)) {
                continue;
            }
            if let Some(placed) = self.start(node, a, compress, epsilon) {
                out.push(placed);
            }
        }
        out
    }

    /// `Expander.moves` for an action that may start: its start (or instantaneous
    /// action), or with `compress` its start and its end.
    fn start(&self, node: &Node<'_>, a: usize, compress: bool, eps: f64) -> Option<Vec<Placed>> {
        let action = &self.actions[a];
        if action.end.is_none() {
            let (facts, nums) = action.start.fire(node.facts, node.nums)?;
            let after = nums.as_deref().unwrap_or(node.nums);
            if !self.invariants_hold(node.open, &facts, after) {
                return None;
            }
            return Some(vec![Placed {
                step: node.step(INST, a, 0.0, f64::INFINITY),
                facts,
                nums,
                open: node.open.to_vec(),
            }]);
        }
        if node.open.contains(&a) {
            return None; // no self-overlap
        }
        let (facts, nums) = action.start.fire(node.facts, node.nums)?;
        let mut open = node.open.to_vec();
        open.push(a);
        open.sort_unstable();
        let after = nums.as_deref().unwrap_or(node.nums);
        if !self.invariants_hold(&open, &facts, after) {
            return None;
        }
        let (low, high) = action.duration.bounds(node.nums, eps);
        if low > high || high <= 0.0 {
            return None;
        }
        let mut step = node.step(START, a, low, high);
        step.running.push((a, node.steps));
        step.running.sort_unstable();
        if !compress {
            return Some(vec![Placed {
                step,
                facts,
                nums,
                open,
            }]);
        }
        // The whole action at once: the end fires in the state after the start.
        let base = nums.as_deref().unwrap_or(node.nums);
        let (ended, values, closed) = self.end(a, &facts, base, &open)?;
        let end = Scheduled {
            kind: END,
            partner: node.steps as i64,
            ..node.step(END, a, low, high)
        };
        let ended = Placed {
            step: end,
            facts: ended,
            nums: values.or_else(|| nums.clone()),
            open: closed,
        };
        let begun = Placed {
            step,
            facts,
            nums,
            open,
        };
        Some(vec![begun, ended])
    }
}

impl Node<'_> {
    /// A step taken in this node that leaves its running actions and timed literals.
    fn step(&self, kind: u8, action: usize, low: f64, high: f64) -> Scheduled {
        Scheduled {
            kind,
            action,
            partner: -1,
            low,
            high,
            running: self.running.iter().map(|&(i, s, _, _)| (i, s)).collect(),
            til: self.til,
        }
    }
}
