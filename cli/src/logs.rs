//! Logging of the long-running commands: human-readable lines, or one JSON object per line
//! (`--log-format json`) for a log collector. Spans carry the ids: the server wraps every
//! request in `request{request_id}` and task calls in `task{id}`, the worker each lease in
//! `task{id, job, attempt}`, so every line logged inside them names them.

use std::io::IsTerminal;

use clap::ValueEnum;
use serde::Serialize;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::{fmt, EnvFilter};
use worker::task_log::TaskLogLayer;

/// How log lines are written.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    /// Lines for people: time, level, spans with their ids, message.
    #[default]
    Human,
    /// One JSON object per line, for a log collector: the message, and each enclosing
    /// span with its ids under "spans".
    Json,
}

/// Installs the global subscriber: `RUST_LOG` when set, else `default_filter`. A worker
/// also keeps each task's lines for the server (`task_log`).
pub fn init(format: LogFormat, default_filter: &str, task_log: Option<TaskLogLayer>) {
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| default_filter.into());
    let registry = tracing_subscriber::registry().with(filter).with(task_log);
    match format {
        // Colours only on a terminal: journald and `docker logs` would keep the escapes.
        LogFormat::Human => registry
            .with(fmt::layer().with_ansi(std::io::stdout().is_terminal()))
            .init(),
        // The message beside the level rather than under "fields", and every enclosing
        // span (request, then task) with its fields.
        LogFormat::Json => registry
            .with(
                fmt::layer()
                    .json()
                    .flatten_event(true)
                    .with_current_span(false)
                    .with_span_list(true),
            )
            .init(),
    }
}
