//! Candidate refits of a diagnosis computed ahead, on the other cores.
//!
//! The search of a diagnosis ([`crate::diagnose`]) refits candidates one
//! after the other and stops as soon as one settles the question; which
//! candidate comes next depends on the ones before. Each refit, though, is
//! a function of its own candidate's state only (the baseline, the edited
//! model and the candidate's estimates). So when the search is about to
//! refit a candidate nobody has computed yet, the candidates of its list
//! are refitted ahead on the workers ([`Ahead::compute`]), each from a copy
//! of its present state, and kept beside the input state they were
//! computed from. When a candidate's turn comes, its result is used only if
//! its state is still equal to that input ([`Ahead::take`]); otherwise it
//! is computed again in turn. The search therefore does exactly what it
//! does on one thread, whatever the number of threads.
//!
//! The rule for the work ahead: the list is taken in the search's order by
//! whichever worker is free ([`crate::parallel::par_map_until`]: a long
//! refit does not hold the other cores idle until it ends, as fixed batches
//! did; the QUBE round-1 refits take 0.3 to 2.3 s each), and no worker
//! takes a candidate past the first result that ends the search's walk of
//! the list (the search's own `stop` test: a candidate that settles the
//! diagnosis). The work ahead that the search no longer needs is at most
//! the refits in flight when that result came in, one per other worker:
//! the price of the wall time. A list of one candidate runs in turn, where
//! its fit spreads its own experiments over the cores instead.

use std::cell::RefCell;

use crate::diagnose::Ranked;
use crate::parallel::{par_map_until, workers_for};

/// Which computation on a candidate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Step {
    /// The refit from the baseline, judged; it may stop where it cannot
    /// reach a margin above `bar` (an f64's bits, so that steps compare
    /// exactly; see `diagnose`'s screening options).
    Refit { bar: u64 },
    /// The second start from the nominal values, judged.
    SecondStart,
}

impl Step {
    /// [`Step::Refit`] against the margin `bar`.
    pub(crate) fn refit(bar: f64) -> Step {
        Step::Refit { bar: bar.to_bits() }
    }
}

/// One result computed ahead: the step, the candidate's index, the state
/// it was computed from, the state after.
type Entry = (Step, usize, Ranked, Ranked);

/// Results computed ahead, waiting for their turn.
#[derive(Default)]
pub(crate) struct Ahead {
    done: RefCell<Vec<Entry>>,
}

impl Ahead {
    /// Whether `step` of candidate `idx` in state `r` has been computed.
    fn has(&self, step: Step, idx: usize, r: &Ranked) -> bool {
        self.done
            .borrow()
            .iter()
            .any(|(s, i, from, _)| *s == step && *i == idx && same(from, r))
    }

    /// The result of `step` on candidate `idx` if it was computed ahead
    /// from the state `r` it has now (and forget it).
    pub(crate) fn take(&self, step: Step, idx: usize, r: &Ranked) -> Option<Ranked> {
        let mut done = self.done.borrow_mut();
        let k = done
            .iter()
            .position(|(s, i, from, _)| *s == step && *i == idx && same(from, r))?;
        Some(done.swap_remove(k).3)
    }

    /// Compute `step` (`run` on a copy of the candidate and its index) for
    /// the candidates of `upcoming` (indices into `ranking`, in the
    /// search's order) on the workers, if the first has not been computed
    /// from its present state, up to the first result that `stop`s the
    /// search's walk (see the module docs for the rule).
    pub(crate) fn compute(
        &self,
        step: Step,
        ranking: &[Ranked],
        upcoming: &[usize],
        run: impl Fn(&mut Ranked, usize) + Sync,
        stop: impl Fn(&Ranked) -> bool + Sync,
    ) {
        let Some(&first) = upcoming.first() else {
            return;
        };
        if self.has(step, first, &ranking[first]) {
            return;
        }
        let batch: Vec<usize> = upcoming
            .iter()
            .copied()
            .filter(|&i| !self.has(step, i, &ranking[i]))
            .collect();
        if batch.len() < 2 || workers_for(batch.len()) < 2 {
            return;
        }
        let results = par_map_until(
            batch.len(),
            |b| {
                let idx = batch[b];
                let mut r = ranking[idx].clone();
                run(&mut r, idx);
                r
            },
            stop,
        );
        let mut done = self.done.borrow_mut();
        for (idx, after) in batch.into_iter().zip(results) {
            if let Some(after) = after {
                done.push((step, idx, ranking[idx].clone(), after));
            }
        }
    }
}

/// Whether two states of a candidate are the same, NaN included (`==` is
/// false on a NaN field: a candidate's estimates hold NaN standard errors
/// where the equation error could not give one, and `==` alone threw away
/// every result computed ahead for them). Rust's `{:?}` of an f64 is exact
/// (the shortest text that reads back to the same bits), so equal texts are
/// equal values; the fit's samples and warm start, which its `{:?}` leaves
/// out, are compared apart, by bits.
fn same(a: &Ranked, b: &Ranked) -> bool {
    if a == b {
        return true;
    }
    if format!("{a:?}") != format!("{b:?}") {
        return false;
    }
    match (&a.fit, &b.fit) {
        (None, None) => true,
        (Some(f), Some(g)) => {
            let bits = |x: &Vec<Vec<Vec<f64>>>| -> Vec<u64> {
                x.iter().flatten().flatten().map(|v| v.to_bits()).collect()
            };
            bits(&f.simulated) == bits(&g.simulated)
                && f.simulated_start.as_ref().map(bits) == g.simulated_start.as_ref().map(bits)
                && format!("{:?}", (&f.warm, &f.nuisance_flags))
                    == format!("{:?}", (&g.warm, &g.nuisance_flags))
        }
        _ => false,
    }
}
