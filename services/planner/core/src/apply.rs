//! The semantics of happenings (`cbdi_planner.state`, `cbdi_planner.task`): whether a
//! snap action may fire in a state, the state after it, the invariants of the running
//! actions and an action's duration bounds, with Python's floating-point operations in
//! Python's order.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyTuple, PyTupleMethods};

/// A state's true facts, 64 to a word.
pub type Facts = Vec<u64>;

pub fn test(facts: &[u64], bit: u32) -> bool {
    facts
        .get((bit / 64) as usize)
        .is_some_and(|w| w >> (bit % 64) & 1 == 1)
}

/// A compiled numeric expression (`cbdi_planner.task.NExpr`), as `eval_expr` reads it.
pub enum Expr {
    Const(f64),
    Var(usize),
    Add(Box<Expr>, Box<Expr>),
    Sub(Box<Expr>, Box<Expr>),
    Mul(Box<Expr>, Box<Expr>),
    /// `/` (and any other operator): NaN when dividing by zero.
    Div(Box<Expr>, Box<Expr>),
}

impl Expr {
    pub fn of(obj: &Bound<'_, PyAny>) -> PyResult<Expr> {
        let tuple = obj.cast::<PyTuple>()?;
        let tag: String = tuple.get_item(0)?.extract()?;
        Ok(match tag.as_str() {
            "c" => Expr::Const(tuple.get_item(1)?.extract::<f64>()?),
            "v" => Expr::Var(tuple.get_item(1)?.extract::<usize>()?),
            _ => {
                let a = Box::new(Expr::of(&tuple.get_item(1)?)?);
                let b = Box::new(Expr::of(&tuple.get_item(2)?)?);
                match tag.as_str() {
                    "+" => Expr::Add(a, b),
                    "-" => Expr::Sub(a, b),
                    "*" => Expr::Mul(a, b),
                    _ => Expr::Div(a, b),
                }
            }
        })
    }

    /// One more than the largest variable it reads (0: none).
    pub fn vars(&self) -> usize {
        match self {
            Expr::Var(i) => i + 1,
            Expr::Add(a, b) | Expr::Sub(a, b) | Expr::Mul(a, b) | Expr::Div(a, b) => {
                a.vars().max(b.vars())
            }
            Expr::Const(_) => 0,
        }
    }

    /// `task.eval_expr`.
    pub fn eval(&self, nums: &[f64]) -> f64 {
        match self {
            Expr::Const(v) => *v,
            Expr::Var(i) => nums[*i],
            Expr::Add(a, b) => a.eval(nums) + b.eval(nums),
            Expr::Sub(a, b) => a.eval(nums) - b.eval(nums),
            Expr::Mul(a, b) => a.eval(nums) * b.eval(nums),
            Expr::Div(a, b) => {
                let (lhs, rhs) = (a.eval(nums), b.eval(nums));
                if rhs != 0.0 {
                    lhs / rhs
                } else {
                    f64::NAN
                }
            }
        }
    }
}

/// `task.NumCond`: a comparison `lhs op rhs`.
pub struct Cond {
    op: String,
    lhs: Expr,
    rhs: Expr,
}

impl Cond {
    /// From `(op, lhs, rhs)`.
    pub fn of(obj: &Bound<'_, PyAny>) -> PyResult<Cond> {
        let tuple = obj.cast::<PyTuple>()?;
        Ok(Cond {
            op: tuple.get_item(0)?.extract()?,
            lhs: Expr::of(&tuple.get_item(1)?)?,
            rhs: Expr::of(&tuple.get_item(2)?)?,
        })
    }

    fn vars(&self) -> usize {
        self.lhs.vars().max(self.rhs.vars())
    }

    /// `NumCond.holds`.
    pub fn holds(&self, nums: &[f64]) -> bool {
        let (a, b) = (self.lhs.eval(nums), self.rhs.eval(nums));
        match self.op.as_str() {
            "<" => a < b,
            "<=" => a <= b,
            "=" => (a - b).abs() < 1e-9,
            ">=" => a >= b,
            _ => a > b,
        }
    }
}

/// `task.NumAssign`: an update of variable `var` by `op` with the value of `expr`.
pub struct Assign {
    op: String,
    var: usize,
    expr: Expr,
}

impl Assign {
    /// From `(op, var, expr)`.
    pub fn of(obj: &Bound<'_, PyAny>) -> PyResult<Assign> {
        let tuple = obj.cast::<PyTuple>()?;
        Ok(Assign {
            op: tuple.get_item(0)?.extract()?,
            var: tuple.get_item(1)?.extract()?,
            expr: Expr::of(&tuple.get_item(2)?)?,
        })
    }

    fn vars(&self) -> usize {
        self.expr.vars().max(self.var + 1)
    }

    /// `NumAssign.apply`: write into `new`, reading the expression in `old`.
    fn apply(&self, old: &[f64], new: &mut [f64]) {
        let value = self.expr.eval(old);
        let slot = &mut new[self.var];
        match self.op.as_str() {
            "assign" => *slot = value,
            "increase" => *slot += value,
            "decrease" => *slot -= value,
            "scale-up" => *slot *= value,
            _ => {
                *slot = if value != 0.0 {
                    *slot / value
                } else {
                    f64::NAN
                }
            }
        }
    }
}

/// A conjunction of literals and comparisons (`task.holds`'s arguments).
#[derive(Default)]
pub struct Conj {
    pub pre: Vec<u32>,
    pub neg: Vec<u32>,
    pub num: Vec<Cond>,
}

impl Conj {
    /// From `(pre bits, neg bits, comparisons)`.
    pub fn of(obj: &Bound<'_, PyAny>) -> PyResult<Conj> {
        let (pre, neg, num): (Vec<u32>, Vec<u32>, Vec<Bound<'_, PyAny>>) = obj.extract()?;
        let num = num.iter().map(Cond::of).collect::<PyResult<_>>()?;
        Ok(Conj { pre, neg, num })
    }

    /// `task.holds`.
    pub fn holds(&self, facts: &[u64], nums: &[f64]) -> bool {
        self.pre.iter().all(|&f| test(facts, f))
            && !self.neg.iter().any(|&f| test(facts, f))
            && self.num.iter().all(|c| c.holds(nums))
    }

    fn bits(&self) -> impl Iterator<Item = u32> + '_ {
        self.pre.iter().chain(&self.neg).copied()
    }

    pub fn vars(&self) -> usize {
        self.num.iter().map(Cond::vars).max().unwrap_or(0)
    }
}

/// Effects: adds, deletes and numeric updates.
pub struct Effects {
    add: Vec<u32>,
    dele: Vec<u32>,
    num: Vec<Assign>,
}

impl Effects {
    /// From `(add bits, dele bits, updates)`.
    fn of(obj: &Bound<'_, PyAny>) -> PyResult<Effects> {
        let (add, dele, num): (Vec<u32>, Vec<u32>, Vec<Bound<'_, PyAny>>) = obj.extract()?;
        let num = num.iter().map(Assign::of).collect::<PyResult<_>>()?;
        Ok(Effects { add, dele, num })
    }

    fn bits(&self) -> impl Iterator<Item = u32> + '_ {
        self.add.iter().chain(&self.dele).copied()
    }

    fn vars(&self) -> usize {
        self.num.iter().map(Assign::vars).max().unwrap_or(0)
    }
}

/// `task.Snap`'s semantics: its condition, effects and conditional effects.
pub struct Snap {
    cond: Conj,
    effects: Effects,
    when: Vec<(Conj, Effects)>,
}

impl Snap {
    /// From `(condition, effects, [(condition, effects)])` as `Conj::of`/`Effects::of`.
    pub fn of(obj: &Bound<'_, PyAny>) -> PyResult<Snap> {
        let (cond, effects, when): (Bound<'_, PyAny>, Bound<'_, PyAny>, Vec<Bound<'_, PyAny>>) =
            obj.extract()?;
        let when = when
            .iter()
            .map(|w| {
                let (c, e): (Bound<'_, PyAny>, Bound<'_, PyAny>) = w.extract()?;
                Ok((Conj::of(&c)?, Effects::of(&e)?))
            })
            .collect::<PyResult<_>>()?;
        Ok(Snap {
            cond: Conj::of(&cond)?,
            effects: Effects::of(&effects)?,
            when,
        })
    }

    /// One more than the largest fact it names (0: none).
    pub fn facts(&self) -> usize {
        let mut bits: Vec<u32> = self.cond.bits().chain(self.effects.bits()).collect();
        for (c, e) in &self.when {
            bits.extend(c.bits().chain(e.bits()));
        }
        bits.iter().map(|&b| b as usize + 1).max().unwrap_or(0)
    }

    /// One more than the largest variable it reads or writes (0: none).
    pub fn vars(&self) -> usize {
        let mut most = self.cond.vars().max(self.effects.vars());
        for (c, e) in &self.when {
            most = most.max(c.vars()).max(e.vars());
        }
        most
    }

    /// `state._fire`: the facts and values after the snap (None: its condition fails;
    /// values None: unchanged). Deletes before adds; conditions read the state before.
    pub fn fire(&self, facts: &[u64], nums: &[f64]) -> Option<(Facts, Option<Vec<f64>>)> {
        if !self.cond.holds(facts, nums) {
            return None;
        }
        let on: Vec<&Effects> = std::iter::once(&self.effects)
            .chain(
                self.when
                    .iter()
                    .filter(|(c, _)| c.holds(facts, nums))
                    .map(|(_, e)| e),
            )
            .collect();
        let mut out = facts.to_vec();
        for e in &on {
            for &f in &e.dele {
                out[(f / 64) as usize] &= !(1u64 << (f % 64));
            }
        }
        for e in &on {
            for &f in &e.add {
                out[(f / 64) as usize] |= 1u64 << (f % 64);
            }
        }
        if on.iter().all(|e| e.num.is_empty()) {
            return Some((out, None));
        }
        let mut values = nums.to_vec();
        for e in &on {
            for assign in &e.num {
                assign.apply(nums, &mut values);
            }
        }
        Some((out, Some(values)))
    }
}

/// How long an action may last (`GroundAction.duration_bounds`).
pub enum Duration {
    Fixed(f64),
    /// `(op, expr)` constraints.
    Bounded(Vec<(String, Expr)>),
}

impl Duration {
    /// From the fixed duration (None: none) and the `(op, expr)` constraints.
    pub fn of(fixed: Option<f64>, constraints: &[Bound<'_, PyAny>]) -> PyResult<Duration> {
        if let Some(value) = fixed {
            return Ok(Duration::Fixed(value));
        }
        let mut out = Vec::new();
        for c in constraints {
            let (op, expr): (String, Bound<'_, PyAny>) = c.extract()?;
            out.push((op, Expr::of(&expr)?));
        }
        Ok(Duration::Bounded(out))
    }

    pub fn vars(&self) -> usize {
        match self {
            Duration::Fixed(_) => 0,
            Duration::Bounded(c) => c.iter().map(|(_, e)| e.vars()).max().unwrap_or(0),
        }
    }

    /// The `[min, max]` duration when starting with values `nums` (Python's `max`/`min`:
    /// the first argument unless the second is strictly beyond it).
    pub fn bounds(&self, nums: &[f64], epsilon: f64) -> (f64, f64) {
        match self {
            Duration::Fixed(v) => (*v, *v),
            Duration::Bounded(constraints) => {
                let (mut low, mut high) = (epsilon, f64::INFINITY);
                for (op, expr) in constraints {
                    let value = expr.eval(nums);
                    if (op == "=" || op == ">=") && value > low {
                        low = value;
                    }
                    if (op == "=" || op == "<=") && value < high {
                        high = value;
                    }
                }
                (low, high)
            }
        }
    }
}

/// Refuse a task part naming a fact or variable beyond the state.
pub fn check_within(what: &str, most: usize, limit: usize) -> PyResult<()> {
    if most > limit {
        return Err(PyValueError::new_err(format!(
            "{what} beyond the task's {limit}"
        )));
    }
    Ok(())
}
