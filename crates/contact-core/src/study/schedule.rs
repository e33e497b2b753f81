//! The runs of a study on its threads: largest first, shared set-ups handed on, and at most
//! as many bytes predicted to be in use at once as the per-job memory limit allows (a
//! study is one job: its concurrent runs share its limit; a run that fits alone always runs,
//! if need be alone).

use super::levels::{self, LevelRun, Work};
use super::reference::Reference;
use super::{Execution, StudyError};
use crate::solve::stepper::Prepared;
use crate::solve::SolverSettings;
use std::collections::HashMap;
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Condvar, Mutex};

/// A finished run.
pub(crate) enum Done<const D: usize> {
    Level(LevelRun<D>),
    Reference(Reference<D>),
}

/// Runs the jobs on `exec.threads` threads, largest first, and returns them in input order.
pub(crate) fn run_all<const D: usize>(
    jobs: Vec<Work>,
    exec: Execution,
    total: usize,
    progress: &(dyn Fn(usize, usize) -> ControlFlow<()> + Sync),
) -> Result<Vec<Done<D>>, StudyError> {
    let mut order: Vec<usize> = (0..jobs.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(jobs[i].cost()));
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    let results: Vec<Mutex<Option<Result<Done<D>, StudyError>>>> =
        jobs.iter().map(|_| Mutex::new(None)).collect();
    let mut setups: HashMap<&(String, usize), Mutex<Option<Prepared<D>>>> = HashMap::new();
    for key in jobs.iter().filter_map(|j| j.share.as_ref()) {
        setups.entry(key).or_insert_with(|| Mutex::new(None));
    }
    let tick = || {
        let d = done.fetch_add(1, Ordering::Relaxed) + 1;
        if stop.load(Ordering::Relaxed) || progress(d, total).is_break() {
            stop.store(true, Ordering::Relaxed);
            return ControlFlow::Break(());
        }
        ControlFlow::Continue(())
    };
    let budget = MemoryBudget::new(exec.settings.memory_limit);
    let bytes: Vec<u64> = jobs
        .iter()
        .map(|j| {
            // A run that fits no path fails in its own set-up, with the reason.
            crate::memory::choose(&j.problem, exec.settings.memory_limit).map_or(0, |(_, b)| b)
        })
        .collect();
    // The runs computed at once share the study's threads.
    let at_once = exec.threads.clamp(1, jobs.len().max(1));
    let settings = SolverSettings {
        threads: (exec.threads / at_once).max(1),
        ..exec.settings
    };
    let worker = || loop {
        let i = next.fetch_add(1, Ordering::SeqCst);
        let Some(&j) = order.get(i) else { break };
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let _lease = budget.acquire(bytes[j]);
        if stop.load(Ordering::Relaxed) {
            break;
        }
        // A reference's norms are computed here, on the computing thread, while the other
        // threads may still be running levels.
        let slot = jobs[j].share.as_ref().and_then(|k| setups.get(k));
        let r = levels::run_level(&jobs[j], settings, &tick, slot).map(|run| {
            if jobs[j].is_reference {
                Done::Reference(Reference::new(run))
            } else {
                Done::Level(run)
            }
        });
        if r.is_err() {
            stop.store(true, Ordering::Relaxed);
        }
        *results[j].lock().unwrap() = Some(r);
    };
    std::thread::scope(|s| {
        for _ in 1..at_once {
            s.spawn(worker);
        }
        worker();
    });
    let mut out = Vec::with_capacity(jobs.len());
    let mut first_error = None;
    for r in results {
        match r.into_inner().unwrap() {
            Some(Ok(run)) => out.push(run),
            Some(Err(e)) => {
                // A solver failure explains the others' cancellation better than "cancelled".
                if first_error.is_none() || matches!(first_error, Some(StudyError::Cancelled)) {
                    first_error = Some(e);
                }
            }
            None => first_error = first_error.or(Some(StudyError::Cancelled)),
        }
    }
    match first_error {
        Some(e) => Err(e),
        None => Ok(out),
    }
}

/// Predicted bytes of the runs in progress, bounded by a limit.
struct MemoryBudget {
    limit: Option<u64>,
    in_use: Mutex<u64>,
    freed: Condvar,
}

/// Bytes held by a run until it ends.
struct Lease<'a> {
    budget: &'a MemoryBudget,
    bytes: u64,
}

impl MemoryBudget {
    fn new(limit: Option<u64>) -> Self {
        MemoryBudget {
            limit,
            in_use: Mutex::new(0),
            freed: Condvar::new(),
        }
    }

    /// Waits until `bytes` more fit the limit, or nothing else is running (a run that does
    /// not fit beside others runs alone).
    fn acquire(&self, bytes: u64) -> Lease<'_> {
        let mut in_use = self.in_use.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(limit) = self.limit {
            while *in_use > 0 && in_use.saturating_add(bytes) > limit {
                in_use = self.freed.wait(in_use).unwrap_or_else(|e| e.into_inner());
            }
        }
        *in_use += bytes;
        Lease {
            budget: self,
            bytes,
        }
    }

    #[cfg(test)]
    fn in_use(&self) -> u64 {
        *self.in_use.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Drop for Lease<'_> {
    fn drop(&mut self) {
        let mut in_use = self.budget.in_use.lock().unwrap_or_else(|e| e.into_inner());
        *in_use -= self.bytes;
        self.budget.freed.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicU64;

    #[test]
    fn concurrent_leases_never_exceed_the_limit_and_a_lone_large_one_runs() {
        let budget = MemoryBudget::new(Some(100));
        let peak = AtomicU64::new(0);
        let sizes = [60u64, 50, 40, 30, 30, 20, 10, 150];
        std::thread::scope(|s| {
            for &b in &sizes {
                let (budget, peak) = (&budget, &peak);
                s.spawn(move || {
                    let _l = budget.acquire(b);
                    let now = budget.in_use();
                    peak.fetch_max(now, Ordering::SeqCst);
                    assert!(
                        now <= 100 || now == b,
                        "{now} bytes in use beside a lease of {b}"
                    );
                    std::thread::sleep(std::time::Duration::from_millis(5));
                });
            }
        });
        assert_eq!(budget.in_use(), 0, "every lease returned its bytes");
        assert!(peak.load(Ordering::SeqCst) >= 150, "the lone large run ran");
    }

    #[test]
    fn without_a_limit_every_lease_is_granted_at_once() {
        let budget = MemoryBudget::new(None);
        let a = budget.acquire(u64::MAX / 2);
        let b = budget.acquire(u64::MAX / 4);
        assert_eq!(budget.in_use(), u64::MAX / 2 + u64::MAX / 4);
        drop((a, b));
        assert_eq!(budget.in_use(), 0);
    }
}
