//! A job's control state (what clients asked of it) and its transition table; the state
//! a client sees ([`proto::JobState`], [`proto::FrameState`]) is derived from it and from
//! the job's tasks and frames.
//!
//! ```text
//! active --pause--> paused --resume--> active
//! active | paused --cancel--> cancelled          (while work is left)
//! active | paused --retry--> (unchanged)         (its failed tasks are queued again)
//! pause, resume or retry of a cancelled job, pause or cancel of a finished one: refused
//! ```

use std::fmt;

use proto::{FrameState, JobState};

/// What clients asked of a job (the `jobs.control` column).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum JobControl {
    /// Its tasks are leased.
    Active,
    /// Nothing is leased until it resumes.
    Paused,
    /// Its unfinished tasks never run; final.
    Cancelled,
}

/// A client's command on a job (deleting is not one: any job can be deleted).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JobCommand {
    /// Stop leasing; live leases are taken back.
    Pause,
    /// Lease again.
    Resume,
    /// Cancel every unfinished task.
    Cancel,
    /// Queue the failed tasks and frames again.
    Retry,
    /// Render some frames again from scratch.
    Rerender,
}

/// What a command does to a job's control.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ControlChange {
    /// The control becomes this.
    To(JobControl),
    /// The control stays (the job already is where the command leads, or the command
    /// acts on its tasks only).
    Stays,
}

/// A command the table refuses, with what made it so.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ControlRefused {
    /// The job's control.
    pub from: JobControl,
    /// The command.
    pub command: JobCommand,
    /// The job had nothing left to run.
    pub finished: bool,
}

impl fmt::Display for ControlRefused {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (self.from, self.command) {
            (JobControl::Cancelled, _) => write!(f, "is cancelled"),
            (_, JobCommand::Pause) => write!(f, "has nothing left to run"),
            (_, JobCommand::Cancel) => write!(f, "has already finished"),
            (_, command) => write!(f, "cannot take {command:?}"),
        }
    }
}

impl std::error::Error for ControlRefused {}

/// The transition table; `finished`: the job has nothing left to run. No `_` arm: a new
/// control or command must be placed here explicitly.
pub fn control_transition(
    from: JobControl,
    command: JobCommand,
    finished: bool,
) -> Result<ControlChange, ControlRefused> {
    use ControlChange::{Stays, To};
    use JobCommand as C;
    use JobControl as S;
    let change = match (from, command, finished) {
        (S::Active, C::Pause, false) => To(S::Paused),
        (S::Paused, C::Pause, _) => Stays,
        (S::Paused, C::Resume, _) => To(S::Active),
        (S::Active, C::Resume, _) => Stays,
        (S::Active | S::Paused, C::Cancel, false) => To(S::Cancelled),
        (S::Cancelled, C::Cancel, _) => Stays,
        (S::Active | S::Paused, C::Retry | C::Rerender, _) => Stays,

        (S::Active, C::Pause, true)
        | (S::Active | S::Paused, C::Cancel, true)
        | (S::Cancelled, C::Pause | C::Resume | C::Retry | C::Rerender, _) => {
            return Err(ControlRefused {
                from,
                command,
                finished,
            })
        }
    };
    Ok(change)
}

impl JobControl {
    /// Every control state.
    pub const ALL: [JobControl; 3] = [
        JobControl::Active,
        JobControl::Paused,
        JobControl::Cancelled,
    ];

    /// The name stored in the database.
    pub fn as_str(self) -> &'static str {
        match self {
            JobControl::Active => "active",
            JobControl::Paused => "paused",
            JobControl::Cancelled => "cancelled",
        }
    }

    /// The control named `s` in the database.
    pub fn parse(s: &str) -> Option<JobControl> {
        JobControl::ALL.into_iter().find(|c| c.as_str() == s)
    }
}

/// What a job's state is derived from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct JobFacts {
    /// Its control.
    pub control: JobControl,
    /// Frames that failed (a task out of attempts, or the assembly).
    pub frames_failed: u64,
    /// Every frame is assembled and nothing more is planned.
    pub complete: bool,
    /// A task was leased or finished.
    pub started: bool,
}

/// The state a client sees: cancelled, else failed, else done, else paused, running or
/// queued.
pub fn job_state(f: JobFacts) -> JobState {
    match f.control {
        JobControl::Cancelled => JobState::Cancelled,
        _ if f.frames_failed > 0 => JobState::Failed,
        _ if f.complete => JobState::Done,
        JobControl::Paused => JobState::Paused,
        JobControl::Active if f.started => JobState::Running,
        JobControl::Active => JobState::Queued,
    }
}

/// What a frame's state is derived from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameFacts {
    /// Its assembly failed.
    pub assembly_failed: bool,
    /// It is assembled.
    pub assembled: bool,
    /// Tasks of it out of attempts.
    pub tasks_failed: u64,
    /// Its job's control.
    pub control: JobControl,
    /// A task of it was leased or finished.
    pub started: bool,
    /// Its denoise task is not done (the job denoises, and the frame is assembled).
    pub denoise_unfinished: bool,
}

/// A frame's state: failed or done once decided, else cancelled with its job, else
/// denoising, rendering or queued.
pub fn frame_state(f: FrameFacts) -> FrameState {
    if f.assembly_failed {
        FrameState::Failed
    } else if f.assembled && !f.denoise_unfinished {
        FrameState::Done
    } else if f.tasks_failed > 0 {
        FrameState::Failed
    } else if f.control == JobControl::Cancelled {
        FrameState::Cancelled
    } else if f.assembled {
        FrameState::Denoising
    } else if f.started {
        FrameState::Rendering
    } else {
        FrameState::Queued
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ControlChange::{Stays, To};
    use JobCommand as C;
    use JobControl as S;

    const COMMANDS: [JobCommand; 5] = [C::Pause, C::Resume, C::Cancel, C::Retry, C::Rerender];

    #[test]
    fn pause_resume_cancel_move_a_job_with_work_left() {
        assert_eq!(
            control_transition(S::Active, C::Pause, false),
            Ok(To(S::Paused))
        );
        assert_eq!(
            control_transition(S::Paused, C::Resume, false),
            Ok(To(S::Active))
        );
        assert_eq!(
            control_transition(S::Active, C::Cancel, false),
            Ok(To(S::Cancelled))
        );
        assert_eq!(
            control_transition(S::Paused, C::Cancel, false),
            Ok(To(S::Cancelled))
        );
    }

    #[test]
    fn a_command_the_job_already_obeys_changes_nothing() {
        assert_eq!(control_transition(S::Paused, C::Pause, false), Ok(Stays));
        assert_eq!(control_transition(S::Active, C::Resume, true), Ok(Stays));
        assert_eq!(control_transition(S::Cancelled, C::Cancel, true), Ok(Stays));
        assert_eq!(control_transition(S::Paused, C::Retry, true), Ok(Stays));
    }

    /// Every pair not legal above is refused, and says why in words a client reads after
    /// "job 7 ".
    #[test]
    fn every_other_command_is_refused_with_its_reason() {
        let mut refused = Vec::new();
        for from in S::ALL {
            for command in COMMANDS {
                for finished in [false, true] {
                    if let Err(e) = control_transition(from, command, finished) {
                        assert_eq!(
                            e,
                            ControlRefused {
                                from,
                                command,
                                finished
                            }
                        );
                        refused.push(e.to_string());
                    }
                }
            }
        }
        // Cancelled: pause, resume, retry, rerender, each finished or not (8); active and
        // finished: pause; active or paused and finished: cancel (2).
        assert_eq!(refused.len(), 11);
        assert_eq!(refused.iter().filter(|r| *r == "is cancelled").count(), 8);
        assert!(refused.contains(&"has nothing left to run".to_string()));
        assert_eq!(
            refused
                .iter()
                .filter(|r| *r == "has already finished")
                .count(),
            2
        );
    }

    #[test]
    fn control_names_round_trip() {
        for c in S::ALL {
            assert_eq!(JobControl::parse(c.as_str()), Some(c));
        }
        assert_eq!(JobControl::parse("running"), None);
    }

    #[test]
    fn a_cancelled_job_reads_cancelled_whatever_its_frames() {
        let facts = JobFacts {
            control: S::Cancelled,
            frames_failed: 3,
            complete: true,
            started: true,
        };
        assert_eq!(job_state(facts), JobState::Cancelled);
        let failed = JobFacts {
            control: S::Paused,
            ..facts
        };
        assert_eq!(job_state(failed), JobState::Failed);
        let done = JobFacts {
            frames_failed: 0,
            ..failed
        };
        assert_eq!(job_state(done), JobState::Done);
        let paused = JobFacts {
            complete: false,
            ..done
        };
        assert_eq!(job_state(paused), JobState::Paused);
        let running = JobFacts {
            control: S::Active,
            ..paused
        };
        assert_eq!(job_state(running), JobState::Running);
        let queued = JobFacts {
            started: false,
            ..running
        };
        assert_eq!(job_state(queued), JobState::Queued);
    }

    #[test]
    fn a_frame_is_decided_before_its_job_is_cancelled() {
        let facts = FrameFacts {
            assembly_failed: false,
            assembled: true,
            tasks_failed: 0,
            control: S::Cancelled,
            started: true,
            denoise_unfinished: false,
        };
        assert_eq!(frame_state(facts), FrameState::Done);
        let cancelled = FrameFacts {
            assembled: false,
            ..facts
        };
        assert_eq!(frame_state(cancelled), FrameState::Cancelled);
        let failed = FrameFacts {
            tasks_failed: 1,
            ..cancelled
        };
        assert_eq!(frame_state(failed), FrameState::Failed);
        let rendering = FrameFacts {
            control: S::Active,
            tasks_failed: 0,
            ..cancelled
        };
        assert_eq!(frame_state(rendering), FrameState::Rendering);
        let queued = FrameFacts {
            started: false,
            ..rendering
        };
        assert_eq!(frame_state(queued), FrameState::Queued);
    }

    #[test]
    fn an_assembled_frame_is_done_once_denoised() {
        let denoising = FrameFacts {
            assembly_failed: false,
            assembled: true,
            tasks_failed: 0,
            control: S::Active,
            started: true,
            denoise_unfinished: true,
        };
        assert_eq!(frame_state(denoising), FrameState::Denoising);
        let paused = FrameFacts {
            control: S::Paused,
            ..denoising
        };
        assert_eq!(frame_state(paused), FrameState::Denoising);
        let cancelled = FrameFacts {
            control: S::Cancelled,
            ..denoising
        };
        assert_eq!(frame_state(cancelled), FrameState::Cancelled);
        let failed = FrameFacts {
            tasks_failed: 1,
            ..denoising
        };
        assert_eq!(frame_state(failed), FrameState::Failed);
        let done = FrameFacts {
            denoise_unfinished: false,
            ..denoising
        };
        assert_eq!(frame_state(done), FrameState::Done);
    }
}
