//! What happened to a job, for people reading it afterwards: the lines a worker logged
//! while it held a task (sent with its heartbeats, its failure report or its next lease
//! request), and the job's event log (created, paused, a task failed, a frame assembled,
//! ...).

use serde::{Deserialize, Serialize};

/// Lines the server keeps per attempt of a task; later ones are dropped and the attempt is
/// marked [`AttemptLog::truncated`]. A worker buffers no more than this either.
pub const MAX_TASK_LOG_LINES: usize = 200;
/// Length of one log line, bytes; longer ones are cut at a character boundary.
pub const MAX_LOG_LINE_BYTES: usize = 1_000;
/// Events one page of `GET /jobs/{id}/log` holds at most (and by default).
pub const MAX_EVENTS_PER_PAGE: u32 = 1_000;

/// How much a line matters, as the worker's logger rated it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum LogLevel {
    /// Something failed.
    Error,
    /// Something is wrong but work goes on.
    Warn,
    /// What the worker did.
    Info,
    /// Detail for debugging.
    Debug,
    /// Finest detail.
    Trace,
}

impl LogLevel {
    /// Every level, most severe first.
    pub const ALL: [LogLevel; 5] = [
        LogLevel::Error,
        LogLevel::Warn,
        LogLevel::Info,
        LogLevel::Debug,
        LogLevel::Trace,
    ];

    /// The level [`LogLevel::as_str`] names.
    pub fn parse(name: &str) -> Option<LogLevel> {
        LogLevel::ALL.into_iter().find(|l| l.as_str() == name)
    }

    /// Its name as log lines print it: `ERROR`, `WARN`, ...
    pub fn as_str(self) -> &'static str {
        match self {
            LogLevel::Error => "ERROR",
            LogLevel::Warn => "WARN",
            LogLevel::Info => "INFO",
            LogLevel::Debug => "DEBUG",
            LogLevel::Trace => "TRACE",
        }
    }
}

/// One line a worker logged.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct LogLine {
    /// When, Unix ms (the worker's clock).
    pub at_ms: i64,
    /// How much it matters.
    pub level: LogLevel,
    /// The message with its fields, as the worker's own log prints it.
    pub text: String,
}

impl LogLine {
    /// `text` cut to [`MAX_LOG_LINE_BYTES`] at a character boundary.
    pub fn bounded(at_ms: i64, level: LogLevel, mut text: String) -> LogLine {
        truncate_at_char(&mut text, MAX_LOG_LINE_BYTES);
        LogLine { at_ms, level, text }
    }
}

/// Cuts `text` to at most `max` bytes, at a character boundary.
pub fn truncate_at_char(text: &mut String, max: usize) {
    if text.len() > max {
        let mut cut = max;
        while !text.is_char_boundary(cut) {
            cut -= 1;
        }
        text.truncate(cut);
    }
}

/// The lines of one attempt at a task.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct AttemptLog {
    /// The attempt (the lease's number).
    pub attempt: u32,
    /// The worker that held it.
    pub worker_id: u64,
    /// That worker's name.
    pub worker: String,
    /// Its lines, oldest first.
    pub lines: Vec<LogLine>,
    /// More lines came than [`MAX_TASK_LOG_LINES`]; the later ones were dropped.
    pub truncated: bool,
}

/// `GET /jobs/{id}/tasks/{task}/log`: what the workers logged while they held the task.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct TaskLog {
    /// The task.
    pub task_id: u64,
    /// Its frame.
    pub frame: i32,
    /// Every attempt that logged something, oldest first.
    pub attempts: Vec<AttemptLog>,
}

/// One entry of a job's event log.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct JobEvent {
    /// Its id: events are numbered in the order they happened.
    pub id: u64,
    /// When, Unix ms.
    pub at_ms: i64,
    /// What happened, one word: `job_created`, `task_failed`, `frame_assembled`, ...
    pub kind: String,
    /// The details, for people.
    pub detail: String,
}

/// A page of a job's event log, oldest first.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct JobEventList {
    /// The events.
    pub events: Vec<JobEvent>,
    /// Pass as `after` for the next page; absent on the last one.
    pub next_after: Option<u64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_line_is_cut_at_a_character_boundary() {
        let line = LogLine::bounded(0, LogLevel::Info, "é".repeat(MAX_LOG_LINE_BYTES));
        assert_eq!(line.text.len(), MAX_LOG_LINE_BYTES);
        let line = LogLine::bounded(0, LogLevel::Info, format!("a{}", "é".repeat(600)));
        assert_eq!(line.text.len(), MAX_LOG_LINE_BYTES - 1);
        assert!(line.text.ends_with('é'));
        let short = LogLine::bounded(5, LogLevel::Warn, "short".into());
        assert_eq!(short.text, "short");
    }

    #[test]
    fn levels_are_lowercase_on_the_wire() {
        let line = LogLine::bounded(1, LogLevel::Warn, "x".into());
        let json = serde_json::to_string(&line).unwrap();
        assert_eq!(json, r#"{"at_ms":1,"level":"warn","text":"x"}"#);
    }
}
