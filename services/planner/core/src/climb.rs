//! The offline search loops in one call each (`cbdi_planner.hill_climbing`, `best_first`): enforced
//! hill-climbing (`enforced_hill_climbing`, `_climb`) and lazy greedy best-first search
//! with a boosted helpful list (`best_first`), over the nodes of `search`, expanding the
//! same nodes in the same order as the Python reference.

use crate::schedule::Schedule;
use crate::search::{Move, Node, Search, States, Stop, Ticker};
use crate::Touches;
use std::cmp::{Ordering, Reverse};
use std::collections::{BinaryHeap, VecDeque};
use std::sync::Arc;

/// `hill_climbing.PLATEAU`: expansions one climbing step may take.
const PLATEAU: usize = 1000;
/// `best_first._BOOST`: expansions on the helpful list alone after h improves.
const BOOST: u32 = 1000;

pub(crate) type Found = Result<Option<Arc<Node>>, Stop>;

/// `Expander.successors`: the consistent successors of a node, in move order.
pub(crate) fn successors(
    s: &mut Search,
    snaps: &[Touches],
    node: &Node,
    helpful_only: bool,
) -> Vec<(Move, Schedule)> {
    let moves = s.moves(node, helpful_only);
    moves
        .into_iter()
        .filter_map(|mv| s.schedule(snaps, node, &mv).map(|net| (mv, net)))
        .collect()
}

/// `hill_climbing.enforced_hill_climbing`: climb to strictly better values, breadth-first on
/// helpful actions, then on all; None when a plateau cannot be escaped.
pub(crate) fn hill_climb(
    s: &mut Search,
    snaps: &[Touches],
    root: Arc<Node>,
    t: &mut Ticker,
) -> Found {
    let mut current = root;
    while !s.reached(&current.state) {
        let mut better = climb(s, snaps, &current, t, true)?;
        if better.is_none() {
            better = climb(s, snaps, &current, t, false)?;
        }
        match better {
            Some(node) => current = node,
            None => return Ok(None),
        }
    }
    Ok(Some(current))
}

/// `hill_climbing._climb`: breadth-first from `current` for a goal or a smaller h.
fn climb(
    s: &mut Search,
    snaps: &[Touches],
    current: &Arc<Node>,
    t: &mut Ticker,
    helpful_only: bool,
) -> Found {
    let mut seen = States::from_iter([current.state.clone()]);
    let mut queue = VecDeque::from([current.clone()]);
    for _ in 0..PLATEAU {
        let Some(node) = queue.pop_front() else {
            break;
        };
        t.tick()?;
        let mut found = successors(s, snaps, &node, helpful_only);
        // stable, as Python's sorted: of equal makespans, the first move first
        found.sort_by(|a, b| a.1.span.partial_cmp(&b.1.span).unwrap_or(Ordering::Equal));
        for (mv, net) in found {
            if !seen.insert(mv.state.clone()) {
                continue;
            }
            let child = s.child(&node, &mv, net);
            if child.dead() {
                continue;
            }
            if s.reached(&child.state) || child.h < current.h {
                return Ok(Some(Arc::new(child)));
            }
            queue.push_back(Arc::new(child));
        }
    }
    Ok(None)
}

/// An open-list entry of `best_first`: `(priority, steps, tie-break, node or parent,
/// move to schedule and evaluate or None)` (`best_first._Lazy`).
struct Entry {
    h: i64,
    steps: usize,
    counter: u64,
    parent: Arc<Node>,
    mv: Option<Arc<Move>>,
}

impl Entry {
    fn rank(&self) -> (i64, usize, u64) {
        (self.h, self.steps, self.counter)
    }
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.rank() == other.rank()
    }
}

impl Eq for Entry {}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        self.rank().cmp(&other.rank())
    }
}

type Open = BinaryHeap<Reverse<Entry>>;

/// `best_first.best_first`: greedy best-first search on h (ties: fewer steps), evaluation
/// deferred until a node is taken out; partial plans as long as `bound` pruned, at most
/// `limit` expansions (None when reached, as when exhausted).
pub(crate) fn best_first(
    s: &mut Search,
    snaps: &[Touches],
    root: Arc<Node>,
    t: &mut Ticker,
    bound: f64,
    mut limit: Option<i64>,
) -> Found {
    let mut lists: [Open; 2] = [BinaryHeap::new(), BinaryHeap::new()];
    let mut best_h = root.h;
    lists[0].push(Reverse(Entry {
        h: root.h,
        steps: 0,
        counter: 0,
        parent: root,
        mv: None,
    }));
    let mut closed = States::default();
    let (mut counter, mut turn, mut boost) = (0u64, 0usize, 0u32);
    while !lists[0].is_empty() || !lists[1].is_empty() {
        turn = next_list(&lists, turn, boost);
        boost = boost.saturating_sub(1);
        let Some(Reverse(entry)) = lists[turn].pop() else {
            continue;
        };
        let Some(node) = take(s, snaps, &entry, &closed) else {
            continue;
        };
        if node.makespan() >= bound - 1e-9 {
            continue;
        }
        closed.insert(node.state.clone());
        if s.reached(&node.state) {
            return Ok(Some(node));
        }
        if node.h < best_h {
            (best_h, boost) = (node.h, BOOST);
        }
        if let Some(left) = limit.as_mut() {
            if *left <= 0 {
                return Ok(None);
            }
            *left -= 1;
        }
        t.tick()?;
        let steps = node.steps();
        for mv in s.moves(&node, false) {
            if closed.contains(&mv.state) {
                continue;
            }
            counter += 1;
            let helpful = mv.helpful_in(&node);
            let mv = Arc::new(mv);
            let entry = |mv: Arc<Move>| Entry {
                h: node.h,
                steps: steps + mv.steps.len(),
                counter,
                parent: node.clone(),
                mv: Some(mv),
            };
            if helpful {
                lists[1].push(Reverse(entry(mv.clone())));
            }
            lists[0].push(Reverse(entry(mv)));
        }
    }
    Ok(None)
}

/// `best_first._take`: the node of an entry, scheduled and evaluated now (None: closed,
/// inconsistent or dead).
fn take(s: &mut Search, snaps: &[Touches], entry: &Entry, closed: &States) -> Option<Arc<Node>> {
    let parent = &entry.parent;
    let Some(mv) = &entry.mv else {
        return (!closed.contains(&parent.state)).then(|| parent.clone());
    };
    if closed.contains(&mv.state) {
        return None;
    }
    let net = s.schedule(snaps, parent, mv)?;
    let node = s.child(parent, mv, net);
    (!node.dead()).then(|| Arc::new(node))
}

/// `best_first._next_list`: alternate, staying on the helpful list while boosted.
fn next_list(lists: &[Open; 2], turn: usize, boost: u32) -> usize {
    if lists[1].is_empty() {
        return 0;
    }
    if boost > 0 || lists[0].is_empty() {
        return 1;
    }
    turn ^ 1
}
