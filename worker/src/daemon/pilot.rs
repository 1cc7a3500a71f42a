//! Pilot-job mode: a worker that a cluster's scheduler started (a Slurm job, a Kubernetes
//! Job) leaves by itself when the farm has no work for it (`--exit-when-idle`), after so
//! many tasks (`--max-tasks`), or when asked to drain (SIGUSR1, which Slurm sends before a
//! time limit: the task in hand is finished and uploaded first). It says goodbye to the
//! server like any shutdown, so nothing it did counts as failed.

use std::time::{Duration, Instant};

use crate::config::PilotLimits;

/// Why a worker stopped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Ending {
    /// Its shutdown future completed (SIGINT, SIGTERM): a task in hand was given back.
    #[default]
    Shutdown,
    /// No task for [`PilotLimits::exit_when_idle`].
    Idle,
    /// [`PilotLimits::max_tasks`] tasks worked on.
    MaxTasks,
    /// Asked to drain: the task in hand was finished first.
    Drained,
}

impl Ending {
    /// In words, for the worker's last log line.
    pub fn describe(self, limits: &PilotLimits) -> String {
        let secs = |d: Option<Duration>| d.map_or(0.0, |d| d.as_secs_f64());
        match self {
            Ending::Shutdown => "shut down".into(),
            Ending::Idle => format!("idle for {} s", secs(limits.exit_when_idle)),
            Ending::MaxTasks => format!("{} tasks done", limits.max_tasks.unwrap_or(0)),
            Ending::Drained => "drained".into(),
        }
    }
}

/// A worker's progress against its [`PilotLimits`].
#[derive(Debug)]
pub(super) struct Pilot {
    limits: PilotLimits,
    /// Since when it has had no task.
    idle_since: Instant,
    /// Leases worked on.
    leases: u64,
}

impl Pilot {
    pub(super) fn new(limits: PilotLimits) -> Self {
        Pilot {
            limits,
            idle_since: Instant::now(),
            leases: 0,
        }
    }

    /// The limits it leaves at.
    pub(super) fn limits(&self) -> &PilotLimits {
        &self.limits
    }

    /// A lease was worked on (its upload may still be running).
    pub(super) fn worked(&mut self) {
        self.leases += 1;
        self.idle_since = Instant::now();
    }

    /// Why the worker should leave before asking for another lease, if it should:
    /// `draining` when a drain was asked for.
    pub(super) fn ending(&self, draining: bool) -> Option<Ending> {
        if draining {
            return Some(Ending::Drained);
        }
        if self.limits.max_tasks.is_some_and(|n| self.leases >= n) {
            return Some(Ending::MaxTasks);
        }
        if self
            .limits
            .exit_when_idle
            .is_some_and(|d| self.idle_since.elapsed() >= d)
        {
            return Some(Ending::Idle);
        }
        None
    }

    /// How long a long poll may wait: the server's `longest`, or less so that an idle
    /// worker leaves on time.
    pub(super) fn poll_wait(&self, longest: Duration) -> Duration {
        match self.limits.exit_when_idle {
            Some(d) => longest.min(d.saturating_sub(self.idle_since.elapsed())),
            None => longest,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pilot_leaves_when_drained_after_its_tasks_or_when_idle() {
        let mut p = Pilot::new(PilotLimits {
            exit_when_idle: Some(Duration::from_secs(60)),
            max_tasks: Some(2),
        });
        assert_eq!(p.ending(false), None);
        assert_eq!(p.ending(true), Some(Ending::Drained));
        p.worked();
        assert_eq!(p.ending(false), None);
        p.worked();
        assert_eq!(p.ending(false), Some(Ending::MaxTasks));
        // The long poll never outlasts the idle time left.
        assert!(p.poll_wait(Duration::from_secs(120)) <= Duration::from_secs(60));
        assert_eq!(p.poll_wait(Duration::from_secs(5)), Duration::from_secs(5));
        let idle = Pilot::new(PilotLimits {
            exit_when_idle: Some(Duration::ZERO),
            max_tasks: None,
        });
        assert_eq!(idle.ending(false), Some(Ending::Idle));
        assert_eq!(idle.poll_wait(Duration::from_secs(5)), Duration::ZERO);
        let daemon = Pilot::new(PilotLimits::default());
        assert_eq!(daemon.ending(false), None);
        assert_eq!(
            Ending::Idle.describe(&PilotLimits {
                exit_when_idle: Some(Duration::from_secs(30)),
                max_tasks: None
            }),
            "idle for 30 s"
        );
    }
}
