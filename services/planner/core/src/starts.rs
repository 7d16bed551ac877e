//! Which actions may start in a state: `cbdi_planner.expansion.Expander._candidates`
//! with the test of what each action needs before it starts (`_needs`) done here too.
//!
//! The Python core files each action under the lowest fact it needs (none: always
//! looked at), walks the state's true facts and gathers their actions, then sorts them
//! and drops those whose needs do not all hold. This returns the same actions in the
//! same (index) order, reading the state's facts as the little-endian bytes of the
//! Python int.

use pyo3::prelude::*;
use pyo3::types::PyBytes;

#[pyclass(frozen, module = "cbdi_planner_core")]
pub struct Starts {
    /// Per fact, the actions whose lowest needed fact it is.
    by_fact: Vec<Vec<u32>>,
    /// The actions that need no fact.
    always: Vec<u32>,
    /// Per action, the facts it needs, sorted.
    pub(crate) needs: Vec<Vec<u32>>,
}

fn holds(facts: &[u8], bit: u32) -> bool {
    let byte = (bit / 8) as usize;
    byte < facts.len() && facts[byte] >> (bit % 8) & 1 == 1
}

#[pymethods]
impl Starts {
    /// `needs[a]`: the facts (bit positions) action `a` needs before it starts.
    #[new]
    pub(crate) fn new(needs: Vec<Vec<u32>>) -> Self {
        let mut by_fact: Vec<Vec<u32>> = Vec::new();
        let mut always = Vec::new();
        let needs: Vec<Vec<u32>> = needs
            .into_iter()
            .map(|mut n| {
                n.sort_unstable();
                n.dedup();
                n
            })
            .collect();
        for (a, need) in needs.iter().enumerate() {
            match need.first() {
                None => always.push(a as u32),
                Some(&low) => {
                    let low = low as usize;
                    if by_fact.len() <= low {
                        by_fact.resize_with(low + 1, Vec::new);
                    }
                    by_fact[low].push(a as u32);
                }
            }
        }
        Starts {
            by_fact,
            always,
            needs,
        }
    }

    /// The actions, in index order, whose needs all hold in `facts` (the state's facts
    /// as the little-endian bytes of its int).
    fn candidates(&self, facts: &Bound<'_, PyBytes>) -> Vec<u32> {
        self.within(facts.as_bytes())
    }
}

impl Starts {
    /// `candidates` of the state whose facts are the little-endian bytes `facts`.
    pub(crate) fn within(&self, facts: &[u8]) -> Vec<u32> {
        let mut out: Vec<u32> = self.always.clone();
        let limit = facts.len().min(self.by_fact.len().div_ceil(8));
        for (i, &byte) in facts[..limit].iter().enumerate() {
            let mut rest = byte;
            while rest != 0 {
                let bit = i * 8 + rest.trailing_zeros() as usize;
                rest &= rest - 1;
                if let Some(actions) = self.by_fact.get(bit) {
                    out.extend(
                        actions
                            .iter()
                            .filter(|&&a| self.needs[a as usize].iter().all(|&f| holds(facts, f))),
                    );
                }
            }
        }
        out.sort_unstable();
        out
    }
}
