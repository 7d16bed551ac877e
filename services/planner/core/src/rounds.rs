//! The continual search's rounds in one call each (`cbdi_planner.continual.rounds`,
//! the paper's Algorithm 1): the open and closed lists of a `SearchSpace` live here,
//! from round to round, over the nodes of `search`.
//!
//! `G` is enforced hill-climbing on helpful successors (a breadth-first queue emptied
//! when a better node becomes the climber), `NG` best-first search on h (ties: shorter
//! plans) over every successor. Same nodes, same order, same counts as the Python
//! reference.

use crate::schedule::END;
use crate::search::{extends, Node, Search, SearchNode, States};
use crate::Touches;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::cmp::Reverse;
use std::collections::{BinaryHeap, VecDeque};
use std::sync::Arc;

/// An `NG` open-list entry: `(h, steps, tie-break)` and the node.
struct Open(i64, usize, u64, Arc<Node>);

impl Open {
    fn rank(&self) -> (i64, usize, u64) {
        (self.0, self.1, self.2)
    }
}

impl PartialEq for Open {
    fn eq(&self, other: &Self) -> bool {
        self.rank() == other.rank()
    }
}

impl Eq for Open {}

impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Open {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.rank().cmp(&other.rank())
    }
}

/// When a round stops (`RoundBound`), and the clock its seconds are read on.
struct Bound {
    seconds: Option<f64>,
    expansions: Option<i64>,
    plan_size: Option<usize>,
    now: Option<Py<PyAny>>,
    started: f64,
}

/// What a round found: `(kind, node, whether it is the root, expanded, best h)`.
type Found = (&'static str, Option<SearchNode>, bool, i64, i64);

/// A continual search's lists (`SearchSpace`).
#[pyclass(module = "cbdi_planner_core")]
pub struct Rounds {
    search: Py<Search>,
    greedy: bool,
    agenda: bool,
    root: Arc<Node>,
    root_steps: usize,
    open: BinaryHeap<Reverse<Open>>,
    queue: VecDeque<Arc<Node>>,
    current: Arc<Node>,
    closed: States,
    counter: u64,
    best: Arc<Node>,
}

fn greedy_of(mode: &str) -> PyResult<bool> {
    match mode {
        "G" => Ok(true),
        "NG" => Ok(false),
        _ => Err(PyValueError::new_err(format!(
            "unknown search mode {mode:?} (G or NG)"
        ))),
    }
}

#[pymethods]
impl Rounds {
    /// The lists of a search from `root` (evaluated under the aim `SearchSpace` chose).
    #[new]
    fn new(search: Py<Search>, root: &SearchNode, mode: &str, agenda: bool) -> PyResult<Self> {
        let root = root.node.clone();
        let mut out = Rounds {
            search,
            greedy: greedy_of(mode)?,
            agenda,
            root: root.clone(),
            root_steps: 0,
            open: BinaryHeap::new(),
            queue: VecDeque::new(),
            current: root.clone(),
            closed: States::default(),
            counter: 0,
            best: root.clone(),
        };
        out.push(root);
        Ok(out)
    }

    /// `SearchSpace.search_round` in one call: `(kind, node, whether the node is the
    /// root, expanded, best h)`. With `seconds`, `now()` is read as Python reads it,
    /// from `started` on.
    #[pyo3(signature = (seconds, expansions, plan_size, now, started))]
    fn search_round(
        &mut self,
        py: Python<'_>,
        seconds: Option<f64>,
        expansions: Option<i64>,
        plan_size: Option<usize>,
        now: Option<Py<PyAny>>,
        started: f64,
    ) -> PyResult<Found> {
        let bound = Bound {
            seconds,
            expansions,
            plan_size,
            now,
            started,
        };
        let search = self.search.clone_ref(py);
        let mut guard = search.bind(py).borrow_mut();
        let s: &mut Search = &mut guard;
        let moves = s.moves.clone_ref(py);
        py.detach(|| {
            let snaps = moves
                .get()
                .oracle()
                .snaps
                .read()
                .expect("interference lock");
            self.round(s, &snaps, &bound)
        })
    }

    /// `SearchSpace.reroot`: root the search at `node` (no running action).
    fn reroot(&mut self, node: &SearchNode) -> PyResult<()> {
        let node = node.node.clone();
        if !node.running.is_empty() {
            return Err(PyValueError::new_err(
                "cannot re-root on a state with running actions",
            ));
        }
        let prefix = node.line.clone();
        let open = std::mem::take(&mut self.open);
        self.open = open
            .into_iter()
            .filter(|Reverse(e)| extends(&e.3.line, &prefix))
            .collect();
        self.queue.retain(|n| extends(&n.line, &prefix));
        if !extends(&self.current.line, &prefix) {
            self.current = node.clone();
            self.queue.clear();
        }
        self.closed.clear();
        self.root_steps = node.steps();
        self.root = node.clone();
        self.push(node);
        Ok(())
    }

    /// `SearchSpace.restart`: search again in `mode` from `root` with empty lists; the
    /// root evaluated again under its aim.
    fn restart(&mut self, py: Python<'_>, mode: &str, root: &SearchNode) -> PyResult<SearchNode> {
        self.greedy = greedy_of(mode)?;
        let search = self.search.clone_ref(py);
        let mut guard = search.bind(py).borrow_mut();
        let s: &mut Search = &mut guard;
        let root = root.node.clone();
        self.aim_at(s, &root);
        let root = Arc::new(s.again(&root));
        self.root = root.clone();
        self.current = root.clone();
        self.root_steps = root.steps();
        self.open.clear();
        self.queue.clear();
        self.closed.clear();
        self.push(root.clone());
        Ok(SearchNode { node: root })
    }
}

impl Rounds {
    fn push(&mut self, node: Arc<Node>) {
        if self.greedy {
            self.queue.push_back(node);
            return;
        }
        self.counter += 1;
        let entry = Open(node.h, node.steps(), self.counter, node);
        self.open.push(Reverse(entry));
    }

    fn pop(&mut self) -> Option<Arc<Node>> {
        if self.greedy {
            self.queue.pop_front()
        } else {
            self.open.pop().map(|Reverse(e)| e.3)
        }
    }

    fn unpop(&mut self, node: Arc<Node>) {
        if self.greedy {
            self.queue.push_front(node);
        } else {
            self.push(node);
        }
    }

    /// `SearchSpace._aim_at`: the agenda's next stage (greedy with an agenda), else the goal.
    fn aim_at(&self, s: &mut Search, node: &Node) {
        let stage = if self.agenda && self.greedy {
            s.agenda_stage(&node.state)
        } else {
            None
        };
        s.set_aim(stage);
    }

    /// Algorithm 1 from the root until the goal, a bound, or an empty open list.
    fn round(&mut self, s: &mut Search, snaps: &[Touches], bound: &Bound) -> PyResult<Found> {
        let mut expanded = 0i64;
        self.best = self.root.clone(); // line 1
        if self.root.dead() {
            self.open.clear();
            self.queue.clear();
        }
        while let Some(mut node) = self.pop() {
            // lines 4-5
            if !self.closed.insert(node.state.clone()) {
                continue;
            }
            self.consider(&node); // lines 6-7
            if s.is_goal(&node.state) {
                return Ok(self.done("goal", node, expanded)); // line 8
            }
            if s.staged() && s.reached(&node.state) {
                node = self.next_stage(s, &node);
            }
            if self.bound_hit(bound, expanded)? {
                // lines 9-11: `node` is not expanded yet; it stays open for the next round
                self.closed.remove(&node.state);
                self.unpop(node);
                let best = self.best.clone();
                return Ok(self.done("best", best, expanded));
            }
            expanded += 1;
            self.expand(s, snaps, &node); // lines 12-14
        }
        if !Arc::ptr_eq(&self.best, &self.root) {
            let best = self.best.clone();
            return Ok(self.done("best", best, expanded));
        }
        Ok(("exhausted", None, false, expanded, self.root.h)) // line 16
    }

    fn done(&self, kind: &'static str, node: Arc<Node>, expanded: i64) -> Found {
        let is_root = Arc::ptr_eq(&node, &self.root);
        let h = node.h;
        (kind, Some(SearchNode { node }), is_root, expanded, h)
    }

    /// `SearchSpace._next_stage`: aim at the agenda's next stage and climb on from
    /// `node`, evaluated again.
    fn next_stage(&mut self, s: &mut Search, node: &Node) -> Arc<Node> {
        self.aim_at(s, node);
        let node = Arc::new(s.again(node));
        self.current = node.clone();
        self.best = node.clone();
        self.queue.clear();
        self.closed = States::from_iter([node.state.clone()]);
        node
    }

    /// Lines 6-7: the best state has the lowest h and no running action.
    fn consider(&mut self, node: &Arc<Node>) {
        if node.running.is_empty() && node.h < self.best.h {
            self.best = node.clone();
        }
    }

    fn bound_hit(&self, bound: &Bound, expanded: i64) -> PyResult<bool> {
        if let (Some(seconds), Some(now)) = (bound.seconds, &bound.now) {
            let now: f64 = Python::attach(|py| now.call0(py)?.extract(py))?;
            if now - bound.started >= seconds {
                return Ok(true); // line 9: INTERVAL
            }
        }
        if bound.expansions.is_some_and(|limit| expanded >= limit) {
            return Ok(true);
        }
        // lines 10-11: PLAN_SIZE_LIMIT
        Ok(bound
            .plan_size
            .is_some_and(|limit| plan_size(&self.best, self.root_steps) >= limit))
    }

    /// searchCoreLogic: G keeps helpful successors only, NG every successor. Moves are
    /// made, scheduled and counted one at a time, as the Python generators are, so a
    /// climb's early stop leaves the rest uncounted.
    fn expand(&mut self, s: &mut Search, snaps: &[Touches], node: &Arc<Node>) {
        let greedy = self.greedy;
        for mv in s.moves_lazily(node, greedy) {
            s.generated += 1;
            let Some(net) = s.schedule(snaps, node, &mv) else {
                continue;
            };
            if self.closed.contains(&mv.state) {
                continue; // needToVisit
            }
            let child = Arc::new(s.child(node, &mv, net));
            if child.dead() {
                continue;
            }
            self.consider(&child);
            if greedy && child.h < self.current.h {
                // enforced hill-climbing: climb to the better node, forget the plateau
                self.current = child.clone();
                self.queue.clear();
                self.queue.push_back(child);
                break;
            }
            self.push(child);
        }
    }
}

/// The number of actions started in `node`'s plan after the first `root_steps` steps.
fn plan_size(node: &Node, root_steps: usize) -> usize {
    (root_steps..node.steps())
        .filter(|&k| node.schedule.step(k).0 != END)
        .count()
}
