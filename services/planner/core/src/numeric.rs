//! Numeric expressions and conditions as the relaxed planning graph reads them
//! (`cbdi_planner.heuristic`): intervals of values a variable may take, widened by
//! effects, and whether a comparison may hold over them.

use pyo3::prelude::*;
use pyo3::types::{PyTuple, PyTupleMethods};

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

impl Expr {
    /// One more than the largest variable it reads (0: none).
    fn vars(&self) -> usize {
        match self {
            Expr::Var(i) => i + 1,
            Expr::Add(a, b) | Expr::Sub(a, b) | Expr::Mul(a, b) => a.vars().max(b.vars()),
            Expr::Const(_) | Expr::Other => 0,
        }
    }
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

/// `relaxation.interval`: the interval an expression may take given variable intervals.
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

pub(crate) struct Cond {
    op: CmpOp,
    lhs: Expr,
    rhs: Expr,
}

impl Cond {
    /// One more than the largest variable it reads (0: none).
    pub(crate) fn vars(&self) -> usize {
        self.lhs.vars().max(self.rhs.vars())
    }
}

/// `relaxation.may_hold`: whether a comparison may hold given variable intervals.
pub(crate) fn may_hold(cond: &Cond, lo: &[f64], hi: &[f64]) -> bool {
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

pub(crate) struct Assign {
    op: AssignOp,
    var: usize,
    expr: Expr,
}

impl Assign {
    /// One more than the largest variable it reads or writes.
    pub(crate) fn vars(&self) -> usize {
        (self.var + 1).max(self.expr.vars())
    }
}

/// `relaxation.widen`: widen a variable's interval by what an effect may do to it.
pub(crate) fn widen(effect: &Assign, lo: &mut [f64], hi: &mut [f64]) {
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

pub(crate) fn cond_of(obj: &Bound<'_, PyAny>) -> PyResult<Cond> {
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

pub(crate) fn assign_of(obj: &Bound<'_, PyAny>) -> PyResult<Assign> {
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
