//! Search nodes kept in the compiled core, so that a whole search loop runs in one call
//! (`cbdi_planner.expansion.Expander`'s nodes, successors and evaluation).
//!
//! A `Node` holds what `expansion.Node` holds: the state, the running actions, the
//! timeline's `Schedule` (whose steps are shared with the parent's), the heuristic
//! value, helpful happenings and relaxed duration. Python sees one only as a
//! `SearchNode` handle, materialised (`SearchNode.view`) for a loop's result. `Search`
//! makes and evaluates nodes exactly as the Python core does, counting what
//! `Expander` counts; `climb` and `rounds` run the search loops over them.

use crate::apply::{test, Conj, Facts};
use crate::climb;
use crate::graph::Graph;
use crate::moves::{Moves, Node as At, Scheduled, INST, START, TIL};
use crate::schedule::{Schedule, END};
use crate::Touches;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyTuple};
use std::collections::{HashMap, HashSet, VecDeque};
use std::hash::{BuildHasherDefault, Hash, Hasher};
use std::sync::Arc;

/// `heuristic.INFINITE`: the value of a dead end.
pub(crate) const INFINITE: i64 = 1 << 30;
/// `heuristic.KNOWN`: estimates remembered (the oldest forgotten first).
const KNOWN: usize = 4096;

/// A state's heuristic estimate: value, helpful happenings (sorted), relaxed duration.
type Estimate = (i64, Vec<(u8, usize)>, f64);

/// The latest estimates under the current aim (`RelaxedPlanGraph._known`): a
/// continual search's rounds evaluate again states a round before had reached.
#[derive(Default)]
struct Known {
    estimates: StateMap<Estimate>,
    order: VecDeque<Arc<State>>,
}

impl Known {
    fn get(&self, state: &State) -> Option<&Estimate> {
        self.estimates.get(state)
    }

    fn remember(&mut self, state: Arc<State>, estimate: Estimate) {
        if self.order.len() >= KNOWN {
            if let Some(oldest) = self.order.pop_front() {
                self.estimates.remove(&oldest);
            }
        }
        self.order.push_back(state.clone());
        self.estimates.insert(state, estimate);
    }

    fn forget(&mut self) {
        self.estimates.clear();
        self.order.clear();
    }
}

/// A search state (`cbdi_planner.state.State`); equal as `State.key()`s are.
pub(crate) struct State {
    pub facts: Facts,
    pub nums: Arc<Vec<f64>>,
    pub open: Vec<usize>,
    pub til: usize,
}

impl PartialEq for State {
    fn eq(&self, other: &Self) -> bool {
        self.facts == other.facts
            && self.til == other.til
            && self.open == other.open
            && (Arc::ptr_eq(&self.nums, &other.nums) || self.nums == other.nums)
    }
}

impl Eq for State {}

impl Hash for State {
    fn hash<H: Hasher>(&self, hasher: &mut H) {
        self.facts.hash(hasher);
        self.open.hash(hasher);
        self.til.hash(hasher);
        for &x in self.nums.iter() {
            // equal floats hash alike (0.0 == -0.0, as Python's hash has it)
            (if x == 0.0 { 0 } else { x.to_bits() }).hash(hasher);
        }
    }
}

impl State {
    /// The facts as the little-endian bytes of Python's int.
    pub(crate) fn packed(&self) -> Vec<u8> {
        self.facts.iter().flat_map(|w| w.to_le_bytes()).collect()
    }
}

/// A timeline's identity: appended to by one move (`a is b` of `stn.Step`s).
pub(crate) struct Line {
    pub prev: Option<Arc<Line>>,
    pub len: usize,
}

impl Drop for Line {
    fn drop(&mut self) {
        // unlink iteratively: a long chain would overflow the stack recursively
        let mut prev = self.prev.take();
        while let Some(line) = prev {
            match Arc::try_unwrap(line) {
                Ok(mut only) => prev = only.prev.take(),
                Err(_) => break,
            }
        }
    }
}

/// Whether timeline `line` extends `prefix` by at least one step (`SearchSpace.reroot`:
/// the first steps are the very steps of `prefix`).
pub(crate) fn extends(line: &Arc<Line>, prefix: &Arc<Line>) -> bool {
    if line.len <= prefix.len {
        return false;
    }
    if prefix.len == 0 {
        return true; // every step sequence starts with no step
    }
    let mut at = line;
    while at.len > prefix.len {
        match &at.prev {
            Some(prev) => at = prev,
            None => return false,
        }
    }
    Arc::ptr_eq(at, prefix)
}

/// A search node (`expansion.Node`).
pub(crate) struct Node {
    pub state: Arc<State>,
    /// `(action, start step, low, high)` of each running action.
    pub running: Vec<(usize, usize, f64, f64)>,
    pub schedule: Schedule,
    pub line: Arc<Line>,
    pub h: i64,
    /// Sorted `(kind, action)` pairs.
    pub helpful: Vec<(u8, usize)>,
    pub h_time: f64,
}

impl Node {
    pub(crate) fn makespan(&self) -> f64 {
        self.schedule.span
    }

    pub(crate) fn steps(&self) -> usize {
        self.schedule.len()
    }

    pub(crate) fn dead(&self) -> bool {
        self.h >= INFINITE
    }
}

/// A happening applied to a node's state, not yet scheduled (`expansion.Move`).
pub(crate) struct Move {
    pub state: Arc<State>,
    pub steps: Vec<Scheduled>,
}

impl Move {
    /// The actions running after the move: `(action, start step)`.
    pub(crate) fn running(&self) -> &[(usize, usize)] {
        &self.steps.last().expect("a move has a step").running
    }

    /// Whether the step that chose the move is helpful in `parent` (`best_first._helpful_step`).
    pub(crate) fn helpful_in(&self, parent: &Node) -> bool {
        let first = &self.steps[0];
        first.kind == END
            || first.kind == TIL
            || parent
                .helpful
                .binary_search(&(first.kind, first.action))
                .is_ok()
    }
}

/// What a loop may expand: `tick` (Python's clock, called before each expansion) or,
/// without one, `left` expansions more (None: no limit), counted in `done`.
pub(crate) struct Ticker {
    pub tick: Option<Py<PyAny>>,
    pub left: Option<i64>,
    pub done: i64,
}

/// Why a loop stopped early: its expansions ran out, or Python's clock raised.
pub(crate) enum Stop {
    Timeout,
    Raised(PyErr),
}

impl Ticker {
    pub(crate) fn tick(&mut self) -> Result<(), Stop> {
        if let Some(f) = &self.tick {
            return Python::attach(|py| f.call0(py).map(drop).map_err(Stop::Raised));
        }
        self.done += 1;
        match self.left {
            Some(left) if self.done > left => Err(Stop::Timeout),
            _ => Ok(()),
        }
    }
}

/// What a search loop returns: `(node or None, expansions it counted, whether its
/// expansions ran out)`.
pub(crate) type Outcome = (Option<SearchNode>, i64, bool);

pub(crate) fn outcome(found: Result<Option<Arc<Node>>, Stop>, t: &Ticker) -> PyResult<Outcome> {
    match found {
        Ok(node) => Ok((node.map(|node| SearchNode { node }), t.done, false)),
        Err(Stop::Timeout) => Ok((None, t.done, true)),
        Err(Stop::Raised(err)) => Err(err),
    }
}

/// A search node handed to Python.
#[pyclass(frozen, module = "cbdi_planner_core")]
pub struct SearchNode {
    pub(crate) node: Arc<Node>,
}

#[pymethods]
impl SearchNode {
    #[getter]
    fn h(&self) -> i64 {
        self.node.h
    }

    /// `(facts, nums, open, til, running, h, helpful, h_time, schedule, steps)`: what an
    /// `expansion.Node` is built from (facts as little-endian bytes, running as
    /// `(action, start step)`, steps as `(kind, action, partner, low, high)`).
    fn view<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let n = &self.node;
        let s = &n.state;
        let running: Vec<(usize, usize)> = n.running.iter().map(|r| (r.0, r.1)).collect();
        let steps: Vec<_> = (0..n.steps()).map(|k| n.schedule.step(k)).collect();
        (
            PyBytes::new(py, &s.packed()),
            PyTuple::new(py, s.nums.iter())?,
            PyTuple::new(py, &s.open)?,
            s.til,
            PyTuple::new(py, running)?,
            n.h,
            n.helpful.clone(),
            n.h_time,
            n.schedule.clone(),
            steps,
        )
            .into_pyobject(py)
    }
}

/// The nodes of one search of a task: how they are made and evaluated
/// (`Expander`, compiled), with the loops of `climb` and `rounds`.
#[pyclass(module = "cbdi_planner_core")]
pub struct Search {
    pub(crate) moves: Py<Moves>,
    pub(crate) graph: Py<Graph>,
    goal: Conj,
    /// The goal facts aimed at (`Expander.subgoal`; None: the task's goal).
    subgoal: Option<Vec<u32>>,
    /// The heuristic's goal facts (`RelaxedPlanGraph.goal`).
    aim: Vec<usize>,
    goal_bits: Vec<usize>,
    /// The goals of the last evaluation (`aim` and the running actions' ends), kept
    /// for the memory.
    goals: Vec<usize>,
    known: Known,
    compress: bool,
    pub(crate) epsilon: f64,
    words: usize,
    pub(crate) generated: u64,
    pub(crate) evaluated: u64,
    pub(crate) inconsistent: u64,
}

#[pymethods]
impl Search {
    /// `goal`: the task's goal as `(facts, negated facts, comparisons)` (`Conj::of`).
    #[new]
    fn new(
        moves: Py<Moves>,
        graph: Py<Graph>,
        goal: &Bound<'_, PyAny>,
        compress: bool,
        epsilon: f64,
    ) -> PyResult<Self> {
        let goal = Conj::of(goal)?;
        let words = moves.get().words();
        let size = graph.get().pending();
        if goal
            .pre
            .iter()
            .chain(&goal.neg)
            .any(|&f| f as usize >= size)
        {
            return Err(PyValueError::new_err("a goal fact outside the task"));
        }
        let goal_bits: Vec<usize> = goal.pre.iter().map(|&f| f as usize).collect();
        Ok(Search {
            moves,
            graph,
            goal,
            subgoal: None,
            aim: goal_bits.clone(),
            goal_bits,
            goals: Vec::new(),
            known: Known::default(),
            compress,
            epsilon,
            words,
            generated: 0,
            evaluated: 0,
            inconsistent: 0,
        })
    }

    /// `Expander.root`: the evaluated node of a state with an empty plan.
    fn root(&mut self, facts: &[u8], nums: Vec<f64>, til: usize) -> PyResult<SearchNode> {
        if facts.len() > self.words * 8 || nums.len() < self.moves.get().vars() {
            return Err(PyValueError::new_err("a state outside the task"));
        }
        let mut words = vec![0u64; self.words];
        for (i, &byte) in facts.iter().enumerate() {
            words[i / 8] |= u64::from(byte) << (8 * (i % 8));
        }
        let state = State {
            facts: words,
            nums: Arc::new(nums),
            open: Vec::new(),
            til,
        };
        let line = Arc::new(Line { prev: None, len: 0 });
        let node = self.evaluate(Arc::new(state), Vec::new(), Schedule::default(), line);
        Ok(SearchNode {
            node: Arc::new(node),
        })
    }

    /// `Expander.aim`: the facts to reach (sorted bit positions; None: the goal).
    #[pyo3(signature = (subgoal))]
    fn aim(&mut self, subgoal: Option<Vec<u32>>) -> PyResult<()> {
        let size = self.graph.get().pending();
        if subgoal.iter().flatten().any(|&f| f as usize >= size) {
            return Err(PyValueError::new_err("a goal fact outside the task"));
        }
        self.set_aim(subgoal);
        Ok(())
    }

    /// `Expander.evaluate` of a node again (under the current aim).
    fn reevaluate(&mut self, node: &SearchNode) -> SearchNode {
        SearchNode {
            node: Arc::new(self.again(&node.node)),
        }
    }

    /// `hill_climbing.enforced_hill_climbing` from `root`, in one call without the interpreter
    /// lock: `(goal node or None, expansions counted here, whether they ran out)`. Each
    /// expansion calls `tick` (a search clock's, which counts it) or, without one,
    /// counts itself against `left` more (None: no limit).
    #[pyo3(signature = (root, tick, left))]
    fn hill_climb(
        &mut self,
        py: Python<'_>,
        root: &SearchNode,
        tick: Option<Py<PyAny>>,
        left: Option<i64>,
    ) -> PyResult<Outcome> {
        let moves = self.moves.clone_ref(py);
        let root = root.node.clone();
        let mut t = Ticker {
            tick,
            left,
            done: 0,
        };
        let found = py.detach(|| {
            let snaps = moves
                .get()
                .oracle()
                .snaps
                .read()
                .expect("interference lock");
            climb::hill_climb(self, &snaps, root, &mut t)
        });
        outcome(found, &t)
    }

    /// `best_first.best_first` from `root` below makespan `bound`, at most `limit`
    /// expansions (None: unlimited), in one call as `hill_climb`.
    #[pyo3(signature = (root, bound, limit, tick, left))]
    fn best_first(
        &mut self,
        py: Python<'_>,
        root: &SearchNode,
        bound: f64,
        limit: Option<i64>,
        tick: Option<Py<PyAny>>,
        left: Option<i64>,
    ) -> PyResult<Outcome> {
        let moves = self.moves.clone_ref(py);
        let root = root.node.clone();
        let mut t = Ticker {
            tick,
            left,
            done: 0,
        };
        let found = py.detach(|| {
            let snaps = moves
                .get()
                .oracle()
                .snaps
                .read()
                .expect("interference lock");
            climb::best_first(self, &snaps, root, &mut t, bound, limit)
        });
        outcome(found, &t)
    }

    /// The facts aimed at (`Expander.subgoal`, sorted bit positions; None: the goal).
    #[getter]
    fn subgoal(&self) -> Option<Vec<u32>> {
        self.subgoal.clone()
    }

    /// `(generated, evaluated, inconsistent)` since the last call.
    fn take_counts(&mut self) -> (u64, u64, u64) {
        let out = (self.generated, self.evaluated, self.inconsistent);
        (self.generated, self.evaluated, self.inconsistent) = (0, 0, 0);
        out
    }
}

impl Search {
    pub(crate) fn set_aim(&mut self, subgoal: Option<Vec<u32>>) {
        let aim = match &subgoal {
            Some(bits) => bits.iter().map(|&f| f as usize).collect(),
            None => self.goal_bits.clone(),
        };
        if aim != self.aim {
            self.known.forget(); // estimates under another aim
        }
        self.aim = aim;
        self.subgoal = subgoal;
    }

    /// Whether the task's goal holds with no action running (`state.is_goal`).
    pub(crate) fn is_goal(&self, state: &State) -> bool {
        state.open.is_empty() && self.goal.holds(&state.facts, &state.nums)
    }

    /// `Expander.reached`: a goal of the current aim.
    pub(crate) fn reached(&self, state: &State) -> bool {
        match &self.subgoal {
            None => self.is_goal(state),
            Some(bits) => state.open.is_empty() && bits.iter().all(|&f| test(&state.facts, f)),
        }
    }

    /// `hill_climbing.agenda_stage`: the goal facts reached in `state` plus the one whose
    /// relaxed graph layer is lowest (ties: the lowest fact); None: the whole goal.
    pub(crate) fn agenda_stage(&self, state: &State) -> Option<Vec<u32>> {
        let facts = &state.facts;
        let remaining: Vec<usize> = self
            .goal_bits
            .iter()
            .copied()
            .filter(|&f| !test(facts, f as u32))
            .collect();
        if remaining.len() < 2 {
            return None;
        }
        let graph = self.graph.get();
        let levels = graph.levels(
            &state.facts,
            &state.open,
            state.til,
            &state.nums,
            &remaining,
        )?;
        let (_, nearest) = levels.iter().zip(&remaining).min()?;
        let mut stage: Vec<u32> = self
            .goal_bits
            .iter()
            .filter(|&&f| test(facts, f as u32))
            .map(|&f| f as u32)
            .collect();
        stage.push(*nearest as u32);
        stage.sort_unstable();
        Some(stage)
    }

    /// Whether a subgoal is aimed at (a stage of a goal agenda).
    pub(crate) fn staged(&self) -> bool {
        self.subgoal.is_some()
    }

    /// `Expander.evaluate`: a node with its heuristic estimate.
    pub(crate) fn evaluate(
        &mut self,
        state: Arc<State>,
        running: Vec<(usize, usize, f64, f64)>,
        schedule: Schedule,
        line: Arc<Line>,
    ) -> Node {
        self.evaluated += 1;
        let (h, helpful, h_time) = match self.known.get(&state) {
            Some(known) => known.clone(),
            None => {
                let estimate = self.estimate(&state);
                self.known.remember(state.clone(), estimate.clone());
                estimate
            }
        };
        Node {
            state,
            running,
            schedule,
            line,
            h,
            helpful,
            h_time,
        }
    }

    /// The heuristic estimate of `state` under the current aim.
    fn estimate(&mut self, state: &State) -> Estimate {
        let ended = self.graph.get().pending() + self.moves.get().actions();
        let mut goals = std::mem::take(&mut self.goals);
        goals.clear();
        goals.extend_from_slice(&self.aim);
        goals.extend(state.open.iter().map(|a| ended + a));
        let found =
            self.graph
                .get()
                .relaxed(&state.facts, &state.open, state.til, &state.nums, &goals);
        self.goals = goals;
        match found {
            Some((value, helpful, duration)) => (value as i64, helpful, duration),
            None => (INFINITE, Vec::new(), 0.0),
        }
    }

    /// A node evaluated again under the current aim.
    pub(crate) fn again(&mut self, node: &Node) -> Node {
        let state = node.state.clone();
        let line = node.line.clone();
        self.evaluate(state, node.running.clone(), node.schedule.clone(), line)
    }

    /// `Expander.moves`: the applicable happenings of a node (helpful ones only: those
    /// it may start that the heuristic found helpful, and every end and timed literal).
    pub(crate) fn moves(&mut self, node: &Node, helpful_only: bool) -> Vec<Move> {
        let found = self.moves_lazily(node, helpful_only);
        self.generated += found.len() as u64;
        found
    }

    /// `moves` without counting them (the caller counts the ones it takes).
    pub(crate) fn moves_lazily(&self, node: &Node, helpful_only: bool) -> Vec<Move> {
        let state = &node.state;
        let moves = self.moves.get();
        let candidates: Vec<u32> = if helpful_only {
            let mut out: Vec<u32> = node
                .helpful
                .iter()
                .filter(|&&(kind, _)| kind == START || kind == INST)
                .map(|&(_, a)| a as u32)
                .collect();
            out.sort_unstable();
            out
        } else {
            moves.startable(&state.packed())
        };
        let at = At {
            facts: &state.facts,
            nums: &state.nums,
            open: &state.open,
            til: state.til,
            running: &node.running,
            steps: node.steps(),
        };
        let found = moves.generate(&at, &candidates, self.compress, self.epsilon);
        found
            .into_iter()
            .map(|mut placed| {
                let last = placed.pop().expect("a move has a step");
                let state = State {
                    facts: last.facts,
                    nums: match last.nums {
                        Some(values) => Arc::new(values),
                        None => state.nums.clone(),
                    },
                    open: last.open,
                    til: last.step.til,
                };
                let mut steps: Vec<Scheduled> = placed.into_iter().map(|p| p.step).collect();
                steps.push(last.step);
                Move {
                    state: Arc::new(state),
                    steps,
                }
            })
            .collect()
    }

    /// `Expander.schedule`: the parent's schedule with the move's steps (None:
    /// inconsistent).
    pub(crate) fn schedule(
        &mut self,
        snaps: &[Touches],
        parent: &Node,
        mv: &Move,
    ) -> Option<Schedule> {
        let found = self
            .moves
            .get()
            .placed(snaps, &parent.schedule, &mv.steps, self.epsilon);
        if found.is_none() {
            self.inconsistent += 1;
        }
        found
    }

    /// The evaluated node a scheduled move makes.
    pub(crate) fn child(&mut self, parent: &Node, mv: &Move, schedule: Schedule) -> Node {
        let running = mv
            .running()
            .iter()
            .map(|&(a, s)| {
                let (_, _, _, low, high) = schedule.step(s);
                (a, s, low, high)
            })
            .collect();
        let line = Arc::new(Line {
            prev: Some(parent.line.clone()),
            len: schedule.len(),
        });
        self.evaluate(mv.state.clone(), running, schedule, line)
    }
}

/// A hasher for the search's own states (no outside input to guard against): a word at
/// a time, multiplied and rotated (as rustc's FxHasher), much cheaper than SipHash on
/// states of many words.
#[derive(Default, Clone, Copy)]
pub(crate) struct StateHasher(u64);

impl Hasher for StateHasher {
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(word));
        }
    }

    fn write_u64(&mut self, word: u64) {
        self.0 = (self.0.rotate_left(5) ^ word).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }

    fn write_usize(&mut self, word: usize) {
        self.write_u64(word as u64);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

/// Sets and maps of states hashed by `StateHasher`.
pub(crate) type States = HashSet<Arc<State>, BuildHasherDefault<StateHasher>>;
type StateMap<V> = HashMap<Arc<State>, V, BuildHasherDefault<StateHasher>>;
