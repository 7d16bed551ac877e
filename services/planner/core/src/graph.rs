//! The temporal relaxed planning graph of a state (`RelaxedPlanGraph._explore`) and a
//! state's whole heuristic estimate in one call (`RelaxedPlanGraph.estimate`).
//!
//! The graph's lists live in flat arrays (`Csr`) of 32-bit indices, and every
//! exploration works in buffers its thread keeps from one call to the next (`Scratch`),
//! so that exploring allocates nothing once a thread has warmed up: on a big map the
//! exploration touches most of the graph, and pointer chasing and allocation were most
//! of its cost.

use crate::extract::{extract, sums_exactly, Marks, Ops, Relaxed};
use crate::numeric::{assign_of, cond_of, may_hold, widen, Assign, Cond};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::cell::RefCell;
use std::collections::HashMap;

/// One list of indices per key, all in one array (compressed sparse rows).
pub(crate) struct Csr {
    offsets: Vec<u32>,
    items: Vec<u32>,
}

impl Csr {
    fn new(lists: &[Vec<usize>]) -> PyResult<Self> {
        let too_big = || PyValueError::new_err("relaxed planning graph too large");
        let mut offsets = Vec::with_capacity(lists.len() + 1);
        let mut items = Vec::new();
        offsets.push(0);
        for list in lists {
            for &x in list {
                items.push(u32::try_from(x).map_err(|_| too_big())?);
            }
            offsets.push(u32::try_from(items.len()).map_err(|_| too_big())?);
        }
        Ok(Csr { offsets, items })
    }

    /// The list of key `i`.
    #[inline]
    pub(crate) fn get(&self, i: usize) -> &[u32] {
        &self.items[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    fn all_below(&self, bound: usize) -> bool {
        self.items.iter().all(|&x| (x as usize) < bound)
    }
}

/// The layers of one exploration (-1: never): each fact's first layer and achiever op,
/// each op's first layer.
#[derive(Default)]
pub(crate) struct Layers {
    pub level: Vec<i32>,
    pub achiever: Vec<i32>,
    pub op_level: Vec<i32>,
}

/// What an exploration works in, kept per thread between calls.
#[derive(Default)]
struct Scratch {
    layers: Layers,
    counts: Vec<i32>,
    /// Every fact reached, in the order reached (a layer's frontier is a run of it),
    /// with one slot more: a fact is written at the end unconditionally and kept only
    /// if new, so that the hot loops need no unpredictable branch.
    reached: Vec<u32>,
    /// Every op whose counter ran out, in that order (each runs out once), and a slot
    /// more, as `reached`.
    zeroed: Vec<u32>,
    ready: Vec<u32>,
    waiting: Vec<u32>,
    due: Vec<u32>,
    held: Vec<u32>,
    acting: Vec<u32>,
    missing: Vec<u32>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    marks: Marks,
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// A relaxed planning graph's operators, flattened as `RelaxedPlanGraph._index` does.
#[pyclass(frozen, module = "cbdi_planner_core")]
pub(crate) struct Graph {
    size: usize,
    pending: usize,
    /// The ops counting each fact among their conditions.
    users: Csr,
    counts: Vec<i32>,
    /// What firing op k does (`RelaxedPlanGraph._fire`), in one record per op.
    fire: Vec<Fire>,
    /// The facts the ops add: op k's `live` ones, then its `quiet` ones (`Fire`).
    adds: Vec<u32>,
    num_pre: Vec<Vec<Cond>>,
    num_eff: Vec<Vec<Assign>>,
    free: Vec<u32>,
    til_ops: Vec<u32>,
    op_pre: Csr,
    /// The chained end op of each action (-1: none).
    chained_end: Vec<i32>,
    op_kind: Vec<u8>,
    op_action: Vec<usize>,
    op_add: Csr,
    adders: Csr,
    start_op: Vec<i64>,
    op_duration: Vec<f64>,
    /// Whether the ops' durations sum exactly (`extract::sums_exactly`).
    exact: bool,
    /// How many numeric variables the ops read or write (a state has at least these).
    vars: usize,
}

/// The facts of an exploration: each one's layer and achiever (-1: not reached), and
/// those reached, in order, up to `tail`.
struct Facts<'a> {
    level: &'a mut [i32],
    achiever: &'a mut [i32],
    reached: &'a mut [u32],
    tail: usize,
}

/// The op lists a layer's firing appends to.
struct Lists<'a> {
    ready: &'a mut Vec<u32>,
    held: &'a mut Vec<u32>,
    acting: &'a mut Vec<u32>,
}

/// What firing an op does (`RelaxedPlanGraph._fire`): numeric or not, the end op it
/// enables by itself (-1: none), and where its added facts lie in `Graph::adds`: those
/// some op counts (`live`, `start..split`), then the others (`quiet`, `split..end`).
#[derive(Clone, Copy)]
struct Fire {
    then: i32,
    start: u32,
    split: u32,
    end: u32,
    numeric: bool,
}

fn indices(list: Vec<usize>) -> PyResult<Vec<u32>> {
    list.into_iter()
        .map(|x| u32::try_from(x).map_err(|_| PyValueError::new_err("op index too large")))
        .collect()
}

#[pymethods]
impl Graph {
    /// Build from a `RelaxedPlanGraph` once it has indexed its operators.
    #[new]
    fn new(rpg: &Bound<'_, PyAny>) -> PyResult<Self> {
        let size: usize = rpg.getattr("size")?.extract()?;
        let pending: usize = rpg.getattr("pending")?.extract()?;
        let users: Vec<Vec<usize>> = rpg.getattr("users")?.extract()?;
        let counts: Vec<i64> = rpg.getattr("counts")?.extract()?;
        let op_pre: Vec<Vec<usize>> = rpg.getattr("op_pre")?.extract()?;
        let op_add: Vec<Vec<usize>> = rpg.getattr("op_add")?.extract()?;
        let op_kind: Vec<u8> = rpg.getattr("op_kind")?.extract()?;
        let op_action: Vec<usize> = rpg.getattr("op_action")?.extract()?;
        let starts: HashMap<usize, usize> = rpg.getattr("start_op")?.extract()?;
        let actions = op_action.iter().map(|&a| a + 1).max().unwrap_or(0);
        let mut start_op = vec![-1i64; actions];
        for (a, k) in starts {
            if a >= actions {
                return Err(PyValueError::new_err(format!(
                    "start of unknown action {a}"
                )));
            }
            start_op[a] = k as i64;
        }
        let fires: Vec<(bool, i64, Vec<usize>, Vec<usize>)> = rpg.getattr("_fire")?.extract()?;
        let bad = || PyValueError::new_err("bad op");
        let mut fire = Vec::with_capacity(fires.len());
        let mut adds = Vec::new();
        let at = |adds: &Vec<u32>| u32::try_from(adds.len()).map_err(|_| bad());
        for (numeric, next, live, quiet) in fires {
            let start = at(&adds)?;
            adds.extend(indices(live)?);
            let split = at(&adds)?;
            adds.extend(indices(quiet)?);
            fire.push(Fire {
                then: i32::try_from(next).map_err(|_| bad())?,
                start,
                split,
                end: at(&adds)?,
                numeric,
            });
        }
        let mut num_pre = Vec::new();
        for conds in rpg.getattr("op_num_pre")?.try_iter()? {
            num_pre.push(
                conds?
                    .try_iter()?
                    .map(|c| cond_of(&c?))
                    .collect::<PyResult<Vec<_>>>()?,
            );
        }
        let mut num_eff = Vec::new();
        for effects in rpg.getattr("op_num_eff")?.try_iter()? {
            num_eff.push(
                effects?
                    .try_iter()?
                    .map(|e| assign_of(&e?))
                    .collect::<PyResult<Vec<_>>>()?,
            );
        }
        let counts = counts
            .into_iter()
            .map(|c| i32::try_from(c).map_err(|_| PyValueError::new_err("bad op count")))
            .collect::<PyResult<Vec<_>>>()?;
        let adders: Vec<Vec<usize>> = rpg.getattr("adders")?.extract()?;
        let graph = Graph {
            size,
            pending,
            users: Csr::new(&users)?,
            counts,
            fire,
            adds,
            num_pre,
            num_eff,
            free: indices(rpg.getattr("free")?.extract()?)?,
            til_ops: indices(rpg.getattr("til_ops")?.extract()?)?,
            op_pre: Csr::new(&op_pre)?,
            chained_end: chained(rpg.getattr("chained_end")?.extract()?, actions)?,
            op_kind,
            op_action,
            op_add: Csr::new(&op_add)?,
            adders: Csr::new(&adders)?,
            start_op,
            op_duration: rpg.getattr("op_duration")?.extract()?,
            vars: 0,
            exact: false,
        };
        let vars = graph.num_pre.iter().flatten().map(Cond::vars);
        let vars = vars
            .chain(graph.num_eff.iter().flatten().map(Assign::vars))
            .max();
        let graph = Graph {
            vars: vars.unwrap_or(0),
            exact: sums_exactly(&graph.op_duration),
            ..graph
        };
        graph.check()?;
        Ok(graph)
    }

    /// Whether the ops' durations sum to the same in any order (`sums_exactly`).
    #[getter]
    fn exact(&self) -> bool {
        self.exact
    }

    /// `RelaxedPlanGraph._explore` of the state (`facts` as little-endian bytes of its
    /// bitmask, its running actions, timed-literal groups past and numeric values):
    /// `(level, achiever, op_level)`, or None when a goal is never reached.
    #[allow(clippy::type_complexity)]
    fn explore(
        &self,
        py: Python<'_>,
        facts: &[u8],
        open: Vec<usize>,
        til: usize,
        nums: Vec<f64>,
        goals: Vec<usize>,
    ) -> PyResult<Option<(Vec<i64>, Vec<i64>, Vec<i64>)>> {
        self.check_state(facts, &open, &goals, &nums)?;
        let facts = words_of(facts);
        Ok(py.detach(move || {
            SCRATCH.with(|cell| {
                let s = &mut *cell.borrow_mut();
                if !self.run(s, &facts, &open, til, &nums, &goals) {
                    return None;
                }
                let wide = |v: &[i32]| v.iter().map(|&x| x as i64).collect::<Vec<_>>();
                let layers = &s.layers;
                Some((
                    wide(&layers.level),
                    wide(&layers.achiever),
                    wide(&layers.op_level),
                ))
            })
        }))
    }

    /// `RelaxedPlanGraph.estimate` of a state (as `explore` takes it) without the cache:
    /// `(length, helpful, duration)` of its relaxed plan (helpful happenings as sorted
    /// `(kind, action)` pairs), or None when a goal is never reached.
    fn estimate(
        &self,
        py: Python<'_>,
        facts: &[u8],
        open: Vec<usize>,
        til: usize,
        nums: Vec<f64>,
        goals: Vec<usize>,
    ) -> PyResult<Option<Relaxed>> {
        self.check_state(facts, &open, &goals, &nums)?;
        let facts = words_of(facts);
        Ok(py.detach(move || {
            SCRATCH.with(|cell| {
                let s = &mut *cell.borrow_mut();
                if !self.run(s, &facts, &open, til, &nums, &goals) {
                    return None;
                }
                let ops = Ops {
                    kind: &self.op_kind,
                    action: &self.op_action,
                    pre: &self.op_pre,
                    add: &self.op_add,
                    adders: &self.adders,
                    start_op: &self.start_op,
                    duration: &self.op_duration,
                    exact: self.exact,
                };
                Some(extract(&ops, &goals, &s.layers, til, &mut s.marks))
            })
        }))
    }
}

impl Graph {
    /// `estimate` for the compiled search (a state it made, so not checked).
    pub(crate) fn relaxed(
        &self,
        facts: &[u64],
        open: &[usize],
        til: usize,
        nums: &[f64],
        goals: &[usize],
    ) -> Option<Relaxed> {
        SCRATCH.with(|cell| {
            let s = &mut *cell.borrow_mut();
            if !self.run(s, facts, open, til, nums, goals) {
                return None;
            }
            let ops = Ops {
                kind: &self.op_kind,
                action: &self.op_action,
                pre: &self.op_pre,
                add: &self.op_add,
                adders: &self.adders,
                start_op: &self.start_op,
                duration: &self.op_duration,
                exact: self.exact,
            };
            Some(extract(&ops, goals, &s.layers, til, &mut s.marks))
        })
    }

    /// `RelaxedPlanGraph.levels`: the first layer of each of `wanted` (None: one never).
    pub(crate) fn levels(
        &self,
        facts: &[u64],
        open: &[usize],
        til: usize,
        nums: &[f64],
        wanted: &[usize],
    ) -> Option<Vec<i32>> {
        SCRATCH.with(|cell| {
            let s = &mut *cell.borrow_mut();
            if !self.run(s, facts, open, til, nums, wanted) {
                return None;
            }
            Some(wanted.iter().map(|&f| s.layers.level[f]).collect())
        })
    }

    /// The first token fact of running actions (`RelaxedPlanGraph.pending`).
    pub(crate) fn pending(&self) -> usize {
        self.pending
    }

    /// Refuse a state or goals outside the graph.
    fn check_state(
        &self,
        facts: &[u8],
        open: &[usize],
        goals: &[usize],
        nums: &[f64],
    ) -> PyResult<()> {
        if let Some(bad) = goals.iter().find(|&&g| g >= self.size) {
            return Err(PyValueError::new_err(format!(
                "goal {bad} is outside the graph"
            )));
        }
        if let Some(bad) = open.iter().find(|&&a| self.pending + a >= self.size) {
            return Err(PyValueError::new_err(format!(
                "running action {bad} is unknown"
            )));
        }
        let outside = facts
            .iter()
            .enumerate()
            .skip(self.size / 8)
            .any(|(i, &byte)| (0..8).any(|j| byte & (1 << j) != 0 && i * 8 + j >= self.size));
        if outside {
            return Err(PyValueError::new_err("a fact is outside the graph"));
        }
        if nums.len() < self.vars {
            return Err(PyValueError::new_err("a numeric variable has no value"));
        }
        Ok(())
    }

    fn check(&self) -> PyResult<()> {
        let ops = self.fire.len();
        let fact_ok = |f: &usize| *f < self.size;
        let ok = self.users.len() == self.size
            && self.users.all_below(ops)
            && self.counts.len() == ops
            && self.fire.iter().all(|r| r.then < ops as i32)
            && self
                .fire
                .iter()
                .all(|r| r.start <= r.split && r.split <= r.end)
            && self
                .fire
                .last()
                .is_none_or(|r| r.end as usize == self.adds.len())
            && self.adds.iter().all(|&f| (f as usize) < self.size)
            && self.num_pre.len() == ops
            && self.num_eff.len() == ops
            && self.op_pre.len() == ops
            && self.op_pre.all_below(self.size)
            && self.free.iter().all(|&k| (k as usize) < ops)
            && self.til_ops.iter().all(|&k| (k as usize) < ops)
            && self.chained_end.iter().all(|&k| k < ops as i32)
            && (self.chained_end.iter().enumerate())
                .all(|(a, &k)| k < 0 || fact_ok(&(self.pending + a)))
            && self.op_kind.len() == ops
            && self.op_action.len() == ops
            && self.op_add.len() == ops
            && self.op_add.all_below(self.size)
            && self.op_duration.len() == ops
            && self.adders.len() == self.size
            && self.adders.all_below(ops)
            && self.start_op.iter().all(|&k| k < ops as i64);
        if ok {
            Ok(())
        } else {
            Err(PyValueError::new_err("inconsistent relaxed planning graph"))
        }
    }

    /// Explore layer by layer until every goal is reached (false: one never is), into
    /// `s.layers`. `facts`: the state's, as words of bits.
    fn run(
        &self,
        s: &mut Scratch,
        facts: &[u64],
        open: &[usize],
        til: usize,
        nums: &[f64],
        goals: &[usize],
    ) -> bool {
        let Scratch {
            layers,
            counts,
            reached,
            zeroed,
            ready,
            waiting,
            due,
            held,
            acting,
            missing,
            lo,
            hi,
            ..
        } = s;
        let Layers {
            level,
            achiever,
            op_level,
        } = layers;
        let ops = self.fire.len();
        reset(level, self.size);
        reset(achiever, self.size);
        reset(op_level, ops);
        counts.clear();
        counts.extend_from_slice(&self.counts);
        reached.resize(self.size + 1, 0);
        zeroed.resize(ops + 1, 0);
        let mut tail = 0; // facts reached so far
        for (i, &word) in facts.iter().enumerate() {
            let mut bits = word;
            while bits != 0 {
                reached[tail] = (i * 64) as u32 + bits.trailing_zeros();
                tail += 1;
                bits &= bits - 1;
            }
        }
        for &a in open {
            reached[tail] = (self.pending + a) as u32;
            tail += 1;
        }
        for &f in &reached[..tail] {
            level[f as usize] = 0;
        }
        missing.clear();
        missing.extend(goals.iter().filter(|&&g| level[g] < 0).map(|&g| g as u32));
        lo.clear();
        lo.extend_from_slice(nums);
        hi.clear();
        hi.extend_from_slice(nums);
        ready.clear();
        ready.extend_from_slice(&self.free);
        if til < self.til_ops.len() {
            ready.extend_from_slice(&self.til_ops[til..]);
        }
        let extra = self.running_ends(open, level, counts, ready);
        let everything = !extra.is_empty();
        waiting.clear();
        let (mut head, mut zeros) = (0, 0);
        let mut depth = 0i32;
        while !missing.is_empty() {
            // The frontier's users, in its order: the ops whose counters run out join
            // `zeroed` (the slot after the last is written, and kept only if so).
            let zeros_before = zeros;
            for &f in &reached[head..tail] {
                zeros = count_down(self.users.get(f as usize), counts, zeroed, zeros);
                if everything {
                    if let Some(ks) = extra.get(&f) {
                        zeros = count_down(ks, counts, zeroed, zeros);
                    }
                }
            }
            head = tail;
            held.clear();
            acting.clear();
            due.clear();
            due.append(waiting);
            due.append(ready);
            due.extend_from_slice(&zeroed[zeros_before..zeros]);
            let next_level = depth + 1;
            let lists = Lists {
                ready,
                held,
                acting,
            };
            let mut facts = Facts {
                level,
                achiever,
                reached,
                tail,
            };
            let fired = self.fire_layer(
                due,
                depth,
                everything,
                op_level,
                &mut facts,
                lists,
                (lo, hi),
            );
            tail = facts.tail;
            if !fired {
                return false;
            }
            for &k in acting.iter() {
                for effect in &self.num_eff[k as usize] {
                    widen(effect, lo, hi);
                }
            }
            std::mem::swap(waiting, held);
            depth = next_level;
            missing.retain(|&g| level[g as usize] < 0);
        }
        true
    }

    /// Fire the ops `due` at layer `depth` that can fire (`_explore`'s inner loop):
    /// whether one did. An op whose numeric condition cannot hold yet is `held`; one with
    /// numeric effects is `acting`; the end op a start enables by itself is `ready`.
    #[allow(clippy::too_many_arguments)]
    fn fire_layer(
        &self,
        due: &[u32],
        depth: i32,
        everything: bool,
        op_level: &mut [i32],
        facts: &mut Facts<'_>,
        lists: Lists<'_>,
        (lo, hi): (&[f64], &[f64]),
    ) -> bool {
        let Lists {
            ready,
            held,
            acting,
        } = lists;
        let (level, achiever, reached) =
            (&mut *facts.level, &mut *facts.achiever, &mut *facts.reached);
        let mut tail = facts.tail;
        let mut fired = false;
        let next_level = depth + 1;
        for &k in due {
            let k = k as usize;
            if op_level[k] >= 0 {
                continue;
            }
            let fire = &self.fire[k];
            if fire.numeric {
                let pre = &self.num_pre[k];
                if !pre.is_empty() && !pre.iter().all(|c| may_hold(c, lo, hi)) {
                    held.push(k as u32);
                    continue;
                }
                if !self.num_eff[k].is_empty() {
                    acting.push(k as u32);
                }
            }
            op_level[k] = depth;
            fired = true;
            if fire.then >= 0 {
                ready.push(fire.then as u32);
            }
            let (live, quiet) = if everything {
                (self.op_add.get(k), &[][..])
            } else {
                let (start, split, end) =
                    (fire.start as usize, fire.split as usize, fire.end as usize);
                (&self.adds[start..split], &self.adds[split..end])
            };
            let at = (next_level, k as i32);
            tail = reach(live, at, level, achiever, reached, tail);
            reach_quietly(quiet, at, level, achiever);
        }
        facts.tail = tail;
        fired
    }

    /// `RelaxedPlanGraph._running_ends`: the counters of running actions' chained ends.
    fn running_ends(
        &self,
        open: &[usize],
        level: &[i32],
        counts: &mut [i32],
        ready: &mut Vec<u32>,
    ) -> HashMap<u32, Vec<u32>> {
        let mut extra: HashMap<u32, Vec<u32>> = HashMap::new();
        for &a in open {
            let Some(k) = self
                .chained_end
                .get(a)
                .and_then(|&k| usize::try_from(k).ok())
            else {
                continue;
            };
            let unmet = |f: &&u32| level[**f as usize] < 0;
            let need = self.op_pre.get(k).iter().filter(unmet);
            counts[k] = need.clone().count() as i32;
            if counts[k] == 0 {
                ready.push(k as u32);
            }
            for &f in need {
                extra.entry(f).or_default().push(k as u32);
            }
        }
        extra
    }
}

/// The chained end op of each of `actions` actions (-1: none) from a map.
fn chained(ends: HashMap<usize, usize>, actions: usize) -> PyResult<Vec<i32>> {
    let mut out = vec![-1; actions];
    for (a, k) in ends {
        let bad = || PyValueError::new_err(format!("chained end of unknown action {a}"));
        *out.get_mut(a).ok_or_else(bad)? = i32::try_from(k).map_err(|_| bad())?;
    }
    Ok(out)
}

/// Count down the counters of `ops`: those that run out are written to `zeroed` from
/// `zeros` on; the new end of `zeroed`. (Each op is written to the slot after the last,
/// and kept only if its counter ran out: no branch the processor could not predict.)
fn count_down(ops: &[u32], counts: &mut [i32], zeroed: &mut [u32], mut zeros: usize) -> usize {
    for &k in ops {
        let count = &mut counts[k as usize];
        *count -= 1;
        zeroed[zeros] = k;
        zeros += usize::from(*count == 0);
    }
    zeros
}

/// Give the facts `adds` not reached yet layer and achiever `at`, and append them to
/// `reached` from `tail` on; the new end of `reached`. (Without a branch, as
/// `count_down`.)
fn reach(
    adds: &[u32],
    at: (i32, i32),
    level: &mut [i32],
    achiever: &mut [i32],
    reached: &mut [u32],
    mut tail: usize,
) -> usize {
    for &f in adds {
        let (old, first) = (level[f as usize], achiever[f as usize]);
        let new = old < 0;
        level[f as usize] = if new { at.0 } else { old };
        achiever[f as usize] = if new { at.1 } else { first };
        reached[tail] = f;
        tail += usize::from(new);
    }
    tail
}

/// `reach` for facts no op counts: they need no frontier.
fn reach_quietly(adds: &[u32], at: (i32, i32), level: &mut [i32], achiever: &mut [i32]) {
    for &f in adds {
        let (old, first) = (level[f as usize], achiever[f as usize]);
        let new = old < 0;
        level[f as usize] = if new { at.0 } else { old };
        achiever[f as usize] = if new { at.1 } else { first };
    }
}

/// Little-endian bytes of bits as words.
fn words_of(bytes: &[u8]) -> Vec<u64> {
    bytes
        .chunks(8)
        .map(|chunk| {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            u64::from_le_bytes(word)
        })
        .collect()
}

/// `values` as `size` times -1, in the memory it has (filled at once: a fill by
/// `resize` writes one element at a time).
fn reset(values: &mut Vec<i32>, size: usize) {
    values.truncate(size);
    values.resize(size, -1);
    values.fill(-1);
}
