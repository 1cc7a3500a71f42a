//! The state machines, pure: a task's ([`task`]) and a job's control ([`job`]), each one
//! transition table with no fallback arm, and the states clients see, derived from them.
//! Storage ([`crate::db`]) reads a state, asks the table and writes the answer in the
//! same transaction.

pub mod job;
pub mod task;

pub use job::{control_transition, frame_state, job_state, ControlChange, ControlRefused};
pub use job::{FrameFacts, JobCommand, JobControl, JobFacts};
pub use task::{transition, InvalidTransition, TaskEvent, TaskState};
