//! The task state machine: one transition table, pure. Storage ([`crate::db::tasks`]) reads a
//! task's state, asks [`transition`] and writes the answer in the same transaction.
//!
//! ```text
//! queued --lease--> leased --complete--> done
//! leased --fail / expire--> queued            (attempts left)
//! leased --fail / expire--> failed            (out of attempts)
//! leased --revoke--> queued                    (job paused, server restarted)
//! queued | leased --cancel--> cancelled
//! failed --retry--> queued
//! done | failed --rerender--> queued          (its frame is rendered again)
//! ```

use std::fmt;

/// Where one task stands: the wire's type, which the table below moves.
pub use proto::TaskState;

/// What happens to a task.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TaskEvent {
    /// A worker takes it.
    Lease,
    /// Its tile was accepted.
    Complete,
    /// The worker reported a failure; `exhausted` when that was the last attempt.
    Fail {
        /// No attempt is left.
        exhausted: bool,
    },
    /// The lease ran out without a heartbeat; counts as a failed attempt.
    Expire {
        /// No attempt is left.
        exhausted: bool,
    },
    /// The lease is taken back through no fault of the worker (job paused, server
    /// restarted): no attempt is counted.
    Revoke,
    /// The job was cancelled.
    Cancel,
    /// A client asked to retry failed tasks.
    Retry,
    /// A client asked to render the task's frame again.
    Rerender,
}

/// A transition the table does not allow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InvalidTransition {
    /// The state the task was in.
    pub from: TaskState,
    /// The event refused.
    pub event: TaskEvent,
}

impl fmt::Display for InvalidTransition {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "a {} task cannot take {:?}",
            self.from.as_str(),
            self.event
        )
    }
}

impl std::error::Error for InvalidTransition {}

/// The transition table. No `_` arm: a new state or event must be placed here explicitly.
pub fn transition(from: TaskState, event: TaskEvent) -> Result<TaskState, InvalidTransition> {
    use TaskEvent as E;
    use TaskState as S;
    let to = match (from, event) {
        (S::Queued, E::Lease) => S::Leased,
        (S::Leased, E::Complete) => S::Done,
        (S::Leased, E::Fail { exhausted: false } | E::Expire { exhausted: false }) => S::Queued,
        (S::Leased, E::Fail { exhausted: true } | E::Expire { exhausted: true }) => S::Failed,
        (S::Leased, E::Revoke) => S::Queued,
        (S::Queued | S::Leased, E::Cancel) => S::Cancelled,
        (S::Failed, E::Retry) => S::Queued,
        (S::Done | S::Failed, E::Rerender) => S::Queued,

        (
            S::Queued,
            E::Complete | E::Fail { .. } | E::Expire { .. } | E::Revoke | E::Retry | E::Rerender,
        )
        | (S::Leased, E::Lease | E::Retry | E::Rerender)
        | (S::Done, _)
        | (S::Failed, E::Lease | E::Complete | E::Fail { .. } | E::Expire { .. } | E::Revoke)
        | (S::Failed, E::Cancel)
        | (S::Cancelled, _) => return Err(InvalidTransition { from, event }),
    };
    Ok(to)
}

#[cfg(test)]
mod tests {
    use super::*;
    use TaskEvent as E;
    use TaskState as S;

    const EVENTS: [TaskEvent; 10] = [
        E::Lease,
        E::Complete,
        E::Fail { exhausted: false },
        E::Fail { exhausted: true },
        E::Expire { exhausted: false },
        E::Expire { exhausted: true },
        E::Revoke,
        E::Cancel,
        E::Retry,
        E::Rerender,
    ];

    #[test]
    fn queued_to_leased_when_leased() {
        assert_eq!(transition(S::Queued, E::Lease), Ok(S::Leased));
    }

    #[test]
    fn leased_to_done_when_complete() {
        assert_eq!(transition(S::Leased, E::Complete), Ok(S::Done));
    }

    #[test]
    fn leased_to_queued_when_worker_fails_with_attempts_left() {
        assert_eq!(
            transition(S::Leased, E::Fail { exhausted: false }),
            Ok(S::Queued)
        );
    }

    #[test]
    fn leased_to_failed_when_worker_fails_last_attempt() {
        assert_eq!(
            transition(S::Leased, E::Fail { exhausted: true }),
            Ok(S::Failed)
        );
    }

    #[test]
    fn leased_to_queued_when_lease_expires() {
        assert_eq!(
            transition(S::Leased, E::Expire { exhausted: false }),
            Ok(S::Queued)
        );
    }

    #[test]
    fn leased_to_failed_when_last_lease_expires() {
        assert_eq!(
            transition(S::Leased, E::Expire { exhausted: true }),
            Ok(S::Failed)
        );
    }

    #[test]
    fn leased_to_queued_when_revoked() {
        assert_eq!(transition(S::Leased, E::Revoke), Ok(S::Queued));
    }

    #[test]
    fn queued_and_leased_to_cancelled_when_cancelled() {
        assert_eq!(transition(S::Queued, E::Cancel), Ok(S::Cancelled));
        assert_eq!(transition(S::Leased, E::Cancel), Ok(S::Cancelled));
    }

    #[test]
    fn failed_to_queued_when_retried() {
        assert_eq!(transition(S::Failed, E::Retry), Ok(S::Queued));
    }

    #[test]
    fn done_and_failed_to_queued_when_their_frame_is_rendered_again() {
        assert_eq!(transition(S::Done, E::Rerender), Ok(S::Queued));
        assert_eq!(transition(S::Failed, E::Rerender), Ok(S::Queued));
        assert!(transition(S::Leased, E::Rerender).is_err());
    }

    /// Every pair not listed above is refused, naming the state and event.
    #[test]
    fn every_other_transition_is_illegal() {
        let legal = [
            (S::Queued, E::Lease),
            (S::Leased, E::Complete),
            (S::Leased, E::Fail { exhausted: false }),
            (S::Leased, E::Fail { exhausted: true }),
            (S::Leased, E::Expire { exhausted: false }),
            (S::Leased, E::Expire { exhausted: true }),
            (S::Leased, E::Revoke),
            (S::Queued, E::Cancel),
            (S::Leased, E::Cancel),
            (S::Failed, E::Retry),
            (S::Done, E::Rerender),
            (S::Failed, E::Rerender),
        ];
        let mut refused = 0;
        for from in S::ALL {
            for event in EVENTS {
                let result = transition(from, event);
                if legal.contains(&(from, event)) {
                    assert!(result.is_ok(), "{from:?} {event:?}");
                } else {
                    assert_eq!(result, Err(InvalidTransition { from, event }));
                    refused += 1;
                }
            }
        }
        assert_eq!(refused, 5 * EVENTS.len() - legal.len());
    }

    #[test]
    fn done_task_cannot_be_leased_again() {
        let err = transition(S::Done, E::Lease).unwrap_err();
        assert_eq!(err.to_string(), "a done task cannot take Lease");
    }

    #[test]
    fn cancelled_task_cannot_be_retried() {
        assert!(transition(S::Cancelled, E::Retry).is_err());
    }

    #[test]
    fn state_names_round_trip() {
        for s in S::ALL {
            assert_eq!(TaskState::parse(s.as_str()), Some(s));
        }
        assert_eq!(TaskState::parse("running"), None);
    }
}
