//! cbdi planner's compiled search core.
//!
//! The Python core (`cbdi_planner.heuristic`) is the reference: every function here does
//! exactly what its Python twin does, in the same order and with the same floating-point
//! operations, so that a search gives the same states, expansions and plans with either
//! (`tests/planner/test_compiled_core.py` checks it). What is here so far: a state's
//! whole heuristic estimate in one call (`RelaxedPlanGraph.estimate`: the layered
//! exploration of the temporal relaxed planning graph and FF's relaxed plan extracted
//! from it, with CPython's set order emulated where it decides, `pyset`), the hottest
//! part of a search, and the simple temporal network of a partial plan
//! (`cbdi_planner.stn.Timeline`): which earlier steps a new one must follow, and the
//! earliest consistent times.
//!
//! A call runs without the interpreter lock: a service's event loop keeps going while
//! its planner explores.

mod extract;
mod pyset;
mod schedule;
mod starts;

use extract::{extract, Ops, Relaxed};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyTuple, PyTupleMethods};
use schedule::Schedule;
use std::collections::HashMap;

/// A compiled numeric expression (`cbdi_planner.task.NExpr`).
enum Expr {
    Const(f64),
    Var(usize),
    Add(Box<Expr>, Box<Expr>),
    Sub(Box<Expr>, Box<Expr>),
    Mul(Box<Expr>, Box<Expr>),
    /// Any other operator (`/`): its interval is unbounded.
    Other,
}

fn expr_of(obj: &Bound<'_, PyAny>) -> PyResult<Expr> {
    let tuple = obj.cast::<PyTuple>()?;
    let tag: String = tuple.get_item(0)?.extract()?;
    Ok(match tag.as_str() {
        "c" => Expr::Const(tuple.get_item(1)?.extract::<f64>()?),
        "v" => Expr::Var(tuple.get_item(1)?.extract::<usize>()?),
        "+" | "-" | "*" => {
            let a = Box::new(expr_of(&tuple.get_item(1)?)?);
            let b = Box::new(expr_of(&tuple.get_item(2)?)?);
            match tag.as_str() {
                "+" => Expr::Add(a, b),
                "-" => Expr::Sub(a, b),
                _ => Expr::Mul(a, b),
            }
        }
        _ => Expr::Other,
    })
}

/// Python's `min(items)`: the first item no later item is below (NaN as Python has it).
fn py_min(items: &[f64]) -> f64 {
    let mut best = items[0];
    for &x in &items[1..] {
        if x < best {
            best = x;
        }
    }
    best
}

fn py_max(items: &[f64]) -> f64 {
    let mut best = items[0];
    for &x in &items[1..] {
        if x > best {
            best = x;
        }
    }
    best
}

/// `heuristic._interval`: the interval an expression may take given variable intervals.
fn interval(expr: &Expr, lo: &[f64], hi: &[f64]) -> (f64, f64) {
    match expr {
        Expr::Const(v) => (*v, *v),
        Expr::Var(i) => (lo[*i], hi[*i]),
        Expr::Add(x, y) => {
            let ((a, b), (c, d)) = (interval(x, lo, hi), interval(y, lo, hi));
            (a + c, b + d)
        }
        Expr::Sub(x, y) => {
            let ((a, b), (c, d)) = (interval(x, lo, hi), interval(y, lo, hi));
            (a - d, b - c)
        }
        Expr::Mul(x, y) => {
            let ((a, b), (c, d)) = (interval(x, lo, hi), interval(y, lo, hi));
            let has_inf = [a, b, c, d].iter().any(|v| v.is_infinite());
            if has_inf {
                return (f64::NEG_INFINITY, f64::INFINITY);
            }
            let products = [a * c, a * d, b * c, b * d];
            (py_min(&products), py_max(&products))
        }
        Expr::Other => (f64::NEG_INFINITY, f64::INFINITY),
    }
}

#[derive(Clone, Copy)]
enum CmpOp {
    Less,
    LessEq,
    Greater,
    GreaterEq,
    Equal,
}

struct Cond {
    op: CmpOp,
    lhs: Expr,
    rhs: Expr,
}

/// `heuristic._may_hold`: whether a comparison may hold given variable intervals.
fn may_hold(cond: &Cond, lo: &[f64], hi: &[f64]) -> bool {
    let (a, b) = interval(&cond.lhs, lo, hi);
    let (c, d) = interval(&cond.rhs, lo, hi);
    if [a, b, c, d].iter().any(|v| v.is_nan()) {
        return false;
    }
    match cond.op {
        CmpOp::Less => a < d,
        CmpOp::LessEq => a < d || a <= d,
        CmpOp::Greater => b > c,
        CmpOp::GreaterEq => b > c || b >= c,
        CmpOp::Equal => a <= d && c <= b,
    }
}

#[derive(Clone, Copy)]
enum AssignOp {
    Assign,
    Increase,
    Decrease,
    Other,
}

struct Assign {
    op: AssignOp,
    var: usize,
    expr: Expr,
}

/// `heuristic._widen`: widen a variable's interval by what an effect may do to it.
fn widen(effect: &Assign, lo: &mut [f64], hi: &mut [f64]) {
    let (a, b) = interval(&effect.expr, lo, hi);
    let v = effect.var;
    match effect.op {
        AssignOp::Assign => {
            let (old_lo, old_hi) = (lo[v], hi[v]);
            lo[v] = if a < old_lo { a } else { old_lo }; // Python's min(old, a)
            hi[v] = if b > old_hi { b } else { old_hi }; // Python's max(old, b)
        }
        AssignOp::Increase | AssignOp::Decrease => {
            let (up, down) = if matches!(effect.op, AssignOp::Increase) {
                (b > 0.0, a < 0.0)
            } else {
                (a < 0.0, b > 0.0)
            };
            if up {
                hi[v] = f64::INFINITY;
            }
            if down {
                lo[v] = f64::NEG_INFINITY;
            }
        }
        AssignOp::Other => {
            lo[v] = f64::NEG_INFINITY;
            hi[v] = f64::INFINITY;
        }
    }
}

/// What firing an op does (`RelaxedPlanGraph._fire`).
struct Fire {
    numeric: bool,
    then: i64,
    live: Vec<usize>,
    quiet: Vec<usize>,
    all: Vec<usize>,
}

/// The layers of one exploration: each fact's and op's first layer, each fact's achiever.
type Layers = (Vec<i64>, Vec<i64>, Vec<i64>);

/// A relaxed planning graph's operators, flattened as `RelaxedPlanGraph._index` does.
#[pyclass(frozen, module = "cbdi_planner_core")]
struct Graph {
    size: usize,
    pending: usize,
    users: Vec<Vec<usize>>,
    counts: Vec<i64>,
    fire: Vec<Fire>,
    num_pre: Vec<Vec<Cond>>,
    num_eff: Vec<Vec<Assign>>,
    free: Vec<usize>,
    til_ops: Vec<usize>,
    op_pre: Vec<Vec<usize>>,
    chained_end: HashMap<usize, usize>,
    op_kind: Vec<u8>,
    op_action: Vec<usize>,
    op_add: Vec<Vec<usize>>,
    adders: Vec<Vec<usize>>,
    start_op: Vec<i64>,
    op_duration: Vec<f64>,
}

fn cond_of(obj: &Bound<'_, PyAny>) -> PyResult<Cond> {
    let op: String = obj.getattr("op")?.extract()?;
    let op = match op.as_str() {
        "<" => CmpOp::Less,
        "<=" => CmpOp::LessEq,
        ">" => CmpOp::Greater,
        ">=" => CmpOp::GreaterEq,
        _ => CmpOp::Equal,
    };
    Ok(Cond {
        op,
        lhs: expr_of(&obj.getattr("lhs")?)?,
        rhs: expr_of(&obj.getattr("rhs")?)?,
    })
}

fn assign_of(obj: &Bound<'_, PyAny>) -> PyResult<Assign> {
    let op: String = obj.getattr("op")?.extract()?;
    let op = match op.as_str() {
        "assign" => AssignOp::Assign,
        "increase" => AssignOp::Increase,
        "decrease" => AssignOp::Decrease,
        _ => AssignOp::Other,
    };
    let var: usize = obj.getattr("var")?.extract()?;
    Ok(Assign {
        op,
        var,
        expr: expr_of(&obj.getattr("expr")?)?,
    })
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
        let fire = fires
            .into_iter()
            .zip(op_add.iter().cloned())
            .map(|((numeric, then, live, quiet), all)| Fire {
                numeric,
                then,
                live,
                quiet,
                all,
            })
            .collect();
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
        let graph = Graph {
            size,
            pending,
            users,
            counts,
            fire,
            num_pre,
            num_eff,
            free: rpg.getattr("free")?.extract()?,
            til_ops: rpg.getattr("til_ops")?.extract()?,
            op_pre,
            chained_end: rpg.getattr("chained_end")?.extract()?,
            op_kind,
            op_action,
            op_add,
            adders: rpg.getattr("adders")?.extract()?,
            start_op,
            op_duration: rpg.getattr("op_duration")?.extract()?,
        };
        graph.check()?;
        Ok(graph)
    }

    /// `RelaxedPlanGraph._explore` of the state (`facts` as little-endian bytes of its
    /// bitmask, its running actions, timed-literal groups past and numeric values):
    /// `(level, achiever, op_level)`, or None when a goal is never reached.
    fn explore(
        &self,
        py: Python<'_>,
        facts: &[u8],
        open: Vec<usize>,
        til: usize,
        nums: Vec<f64>,
        goals: Vec<usize>,
    ) -> PyResult<Option<Layers>> {
        self.check_state(facts, &open, &goals)?;
        let facts = facts.to_vec();
        Ok(py.detach(move || self.run(&facts, &open, til, nums, &goals)))
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
        self.check_state(facts, &open, &goals)?;
        let facts = facts.to_vec();
        Ok(py.detach(move || {
            let (level, achiever, op_level) = self.run(&facts, &open, til, nums, &goals)?;
            let ops = Ops {
                kind: &self.op_kind,
                action: &self.op_action,
                pre: &self.op_pre,
                add: &self.op_add,
                adders: &self.adders,
                start_op: &self.start_op,
                duration: &self.op_duration,
            };
            Some(extract(&ops, &goals, &level, &achiever, &op_level, til))
        }))
    }
}

impl Graph {
    /// Refuse a state or goals outside the graph.
    fn check_state(&self, facts: &[u8], open: &[usize], goals: &[usize]) -> PyResult<()> {
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
            .any(|(i, &byte)| (0..8).any(|j| byte & (1 << j) != 0 && i * 8 + j >= self.size));
        if outside {
            return Err(PyValueError::new_err("a fact is outside the graph"));
        }
        Ok(())
    }

    fn check(&self) -> PyResult<()> {
        let ops = self.fire.len();
        let fact_ok = |f: &usize| *f < self.size;
        let op_ok = |k: &usize| *k < ops;
        let ok = self.users.len() == self.size
            && self.counts.len() == ops
            && self.num_pre.len() == ops
            && self.num_eff.len() == ops
            && self.op_pre.len() == ops
            && self.users.iter().all(|u| u.iter().all(op_ok))
            && self.fire.iter().all(|f| {
                f.then < ops as i64
                    && f.live.iter().all(fact_ok)
                    && f.quiet.iter().all(fact_ok)
                    && f.all.iter().all(fact_ok)
            })
            && self.op_pre.iter().all(|p| p.iter().all(fact_ok))
            && self.free.iter().all(op_ok)
            && self.til_ops.iter().all(op_ok)
            && self.chained_end.values().all(op_ok)
            && self.op_kind.len() == ops
            && self.op_action.len() == ops
            && self.op_add.len() == ops
            && self.op_duration.len() == ops
            && self.adders.len() == self.size
            && self.adders.iter().all(|a| a.iter().all(op_ok))
            && self.op_add.iter().all(|a| a.iter().all(fact_ok))
            && self.start_op.iter().all(|&k| k < ops as i64);
        if ok {
            Ok(())
        } else {
            Err(PyValueError::new_err("inconsistent relaxed planning graph"))
        }
    }

    fn run(
        &self,
        facts: &[u8],
        open: &[usize],
        til: usize,
        nums: Vec<f64>,
        goals: &[usize],
    ) -> Option<Layers> {
        let mut level = vec![-1i64; self.size];
        let mut achiever = vec![-1i64; self.size];
        let mut op_level = vec![-1i64; self.fire.len()];
        let mut counts = self.counts.clone();
        let mut frontier: Vec<usize> = Vec::new();
        for (i, byte) in facts.iter().enumerate() {
            for j in 0..8 {
                if byte & (1 << j) != 0 {
                    frontier.push(i * 8 + j);
                }
            }
        }
        frontier.extend(open.iter().map(|a| self.pending + a));
        for &f in &frontier {
            level[f] = 0;
        }
        let mut missing: Vec<usize> = goals.iter().copied().filter(|&g| level[g] < 0).collect();
        let (mut lo, mut hi) = (nums.clone(), nums);
        let mut ready: Vec<usize> = self.free.clone();
        if til < self.til_ops.len() {
            ready.extend_from_slice(&self.til_ops[til..]);
        }
        let extra = self.running_ends(open, &level, &mut counts, &mut ready);
        let everything = !extra.is_empty();
        let mut waiting: Vec<usize> = Vec::new();
        let mut depth = 0i64;
        while !missing.is_empty() {
            for &f in &frontier {
                for &k in &self.users[f] {
                    counts[k] -= 1;
                    if counts[k] == 0 {
                        ready.push(k);
                    }
                }
                if everything {
                    if let Some(ks) = extra.get(&f) {
                        for &k in ks {
                            counts[k] -= 1;
                            if counts[k] == 0 {
                                ready.push(k);
                            }
                        }
                    }
                }
            }
            let mut held: Vec<usize> = Vec::new();
            let mut acting: Vec<usize> = Vec::new();
            let due = if waiting.is_empty() {
                std::mem::take(&mut ready)
            } else {
                let mut d = std::mem::take(&mut waiting);
                d.append(&mut ready);
                d
            };
            frontier.clear();
            let mut fired = false;
            let next_level = depth + 1;
            for k in due {
                if op_level[k] >= 0 {
                    continue;
                }
                let fire = &self.fire[k];
                if fire.numeric {
                    let pre = &self.num_pre[k];
                    if !pre.is_empty() && !pre.iter().all(|c| may_hold(c, &lo, &hi)) {
                        held.push(k);
                        continue;
                    }
                    if !self.num_eff[k].is_empty() {
                        acting.push(k);
                    }
                }
                op_level[k] = depth;
                fired = true;
                if fire.then >= 0 {
                    ready.push(fire.then as usize);
                }
                let (live, quiet): (&[usize], &[usize]) = if everything {
                    (&fire.all, &[])
                } else {
                    (&fire.live, &fire.quiet)
                };
                for &f in live {
                    if level[f] < 0 {
                        level[f] = next_level;
                        achiever[f] = k as i64;
                        frontier.push(f);
                    }
                }
                for &f in quiet {
                    if level[f] < 0 {
                        level[f] = next_level;
                        achiever[f] = k as i64;
                    }
                }
            }
            if !fired {
                return None;
            }
            for k in acting {
                for effect in &self.num_eff[k] {
                    widen(effect, &mut lo, &mut hi);
                }
            }
            waiting = held;
            depth = next_level;
            missing.retain(|&g| level[g] < 0);
        }
        Some((level, achiever, op_level))
    }

    /// `RelaxedPlanGraph._running_ends`: the counters of running actions' chained ends.
    fn running_ends(
        &self,
        open: &[usize],
        level: &[i64],
        counts: &mut [i64],
        ready: &mut Vec<usize>,
    ) -> HashMap<usize, Vec<usize>> {
        let mut extra: HashMap<usize, Vec<usize>> = HashMap::new();
        for a in open {
            let Some(&k) = self.chained_end.get(a) else {
                continue;
            };
            let need: Vec<usize> = self.op_pre[k]
                .iter()
                .copied()
                .filter(|&f| level[f] < 0)
                .collect();
            counts[k] = need.len() as i64;
            if need.is_empty() {
                ready.push(k);
            }
            for f in need {
                extra.entry(f).or_default().push(k);
            }
        }
        extra
    }
}

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

#[pymodule]
fn cbdi_planner_core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(set_order, m)?)?;
    m.add_class::<Graph>()?;
    m.add_class::<Interference>()?;
    m.add_class::<Schedule>()?;
    m.add_class::<starts::Starts>()?;
    Ok(())
}
