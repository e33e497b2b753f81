//! The claim policy both backends apply to the oldest claimable job (see
//! [`super::Store::claim`]): the backends find the candidate and write the verdict, this
//! module decides it.

/// What a claim knows about the oldest claimable job: a queued job, or a running job whose
/// lease expired (its worker died or hung).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Candidate {
    /// How often the job was claimed before.
    pub(super) attempt: i64,
    /// Only ever set on a running candidate: a queued job is cancelled at once instead.
    pub(super) cancel_requested: bool,
    /// Claims in a row that saved no new checkpoint.
    pub(super) stalls: i64,
    /// Whether the job saved a checkpoint after the step its last claim resumed from.
    pub(super) progressed: bool,
}

/// What the claim does with the candidate.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Verdict {
    /// Record it cancelled and look further: its worker died after a cancel request, nobody
    /// is left to honour the request, and running it again would defeat it.
    Cancel,
    /// Record it failed with this problem+json error and look further (dead letter): a job
    /// that kills its worker every time must not loop forever.
    DeadLetter(serde_json::Value),
    /// Hand it to the claiming worker, with this many claims in a row without progress.
    Run { stalls: i64 },
}

/// The verdict on `c` when at most `max_attempts` claims in a row may end without a new
/// checkpoint. An attempt that saved a checkpoint made progress and restarts the count at 1:
/// checkpoints only move forward, so a job that keeps progressing finishes eventually,
/// however often its worker is killed.
pub(super) fn verdict(c: Candidate, max_attempts: u32) -> Verdict {
    if c.cancel_requested {
        Verdict::Cancel
    } else if !c.progressed && c.stalls >= i64::from(max_attempts) {
        Verdict::DeadLetter(abandoned_error(c.attempt, c.stalls, max_attempts))
    } else {
        Verdict::Run {
            stalls: if c.progressed { 1 } else { c.stalls + 1 },
        }
    }
}

/// The problem+json error of a dead-lettered job.
fn abandoned_error(attempt: i64, stalls: i64, max_attempts: u32) -> serde_json::Value {
    serde_json::json!({
        "type": "about:blank",
        "title": "job abandoned",
        "status": 500,
        "detail": format!(
            "the job was started {attempt} times; its worker stopped renewing the \
             lease before finishing (crash, kill or hang) {stalls} times in a row \
             without saving a new checkpoint (max_attempts = {max_attempts}); it \
             is not retried again"
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn candidate(stalls: i64, progressed: bool) -> Candidate {
        Candidate {
            attempt: stalls,
            cancel_requested: false,
            stalls,
            progressed,
        }
    }

    #[test]
    fn a_queued_job_runs_with_its_first_stall_counted() {
        assert_eq!(verdict(candidate(0, false), 3), Verdict::Run { stalls: 1 });
    }

    #[test]
    fn stalls_count_up_to_max_attempts_then_dead_letter() {
        assert_eq!(verdict(candidate(2, false), 3), Verdict::Run { stalls: 3 });
        let Verdict::DeadLetter(error) = verdict(candidate(3, false), 3) else {
            panic!("not dead-lettered");
        };
        assert_eq!(error["type"], "about:blank");
        assert_eq!(error["title"], "job abandoned");
        assert_eq!(error["status"], 500);
        let detail = error["detail"].as_str().unwrap();
        assert!(detail.contains("started 3 times"), "{detail}");
        assert!(detail.contains("3 times in a row"), "{detail}");
        assert!(detail.contains("max_attempts = 3"), "{detail}");
        assert!(matches!(
            verdict(candidate(7, false), 3),
            Verdict::DeadLetter(_)
        ));
    }

    #[test]
    fn progress_restarts_the_count() {
        assert_eq!(verdict(candidate(3, true), 3), Verdict::Run { stalls: 1 });
        assert_eq!(verdict(candidate(50, true), 1), Verdict::Run { stalls: 1 });
    }

    #[test]
    fn a_cancel_request_wins_over_everything() {
        for (stalls, progressed) in [(0, false), (5, false), (5, true)] {
            let c = Candidate {
                cancel_requested: true,
                ..candidate(stalls, progressed)
            };
            assert_eq!(verdict(c, 3), Verdict::Cancel);
        }
    }
}
