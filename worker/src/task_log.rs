//! The lines this worker logs while it holds a task, kept until they are sent with the
//! task's next heartbeat, its failure report or (once rendered) the next lease request, so that `tessera logs JOB --task N` shows
//! what the worker saw. A [`TaskLogLayer`] in the process's subscriber copies every event
//! logged inside a `task{id}` span into the buffer of an open [`TaskLog`] with that id.
//! Events of tasks with no open log (the server's own `task` spans) are not kept.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::{LazyLock, Mutex};
use std::time::{SystemTime, UNIX_EPOCH};

use proto::log::MAX_TASK_LOG_LINES;
use proto::{LogLevel, LogLine};
use tracing::field::{Field, Visit};
use tracing::span::{Attributes, Id};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::layer::Context;
use tracing_subscriber::registry::LookupSpan;
use tracing_subscriber::Layer;

/// The lines of one task not yet sent, and how many were sent before.
#[derive(Default)]
struct Buffer {
    lines: Vec<LogLine>,
    sent: usize,
}

/// Open task logs by task id.
static OPEN: LazyLock<Mutex<HashMap<u64, Buffer>>> = LazyLock::new(Default::default);

fn open_logs() -> std::sync::MutexGuard<'static, HashMap<u64, Buffer>> {
    // A panic while holding the lock leaves the map consistent (one push or take).
    OPEN.lock().unwrap_or_else(|p| p.into_inner())
}

/// The log of a task while this worker holds it: lines are kept from [`TaskLog::open`]
/// until it is dropped. At most one past [`MAX_TASK_LOG_LINES`] is kept in all, so that
/// the server knows later ones were dropped.
pub struct TaskLog {
    task: u64,
}

impl TaskLog {
    /// Starts keeping the lines logged in `task{id = task}` spans.
    pub fn open(task: u64) -> TaskLog {
        open_logs().insert(task, Buffer::default());
        TaskLog { task }
    }

    /// The lines kept since the last take.
    pub fn take(&self) -> Vec<LogLine> {
        take(self.task)
    }
}

impl Drop for TaskLog {
    fn drop(&mut self) {
        open_logs().remove(&self.task);
    }
}

/// The lines of `task` kept since the last take (none when its log is not open).
pub fn take(task: u64) -> Vec<LogLine> {
    let mut logs = open_logs();
    let Some(buffer) = logs.get_mut(&task) else {
        return Vec::new();
    };
    buffer.sent += buffer.lines.len();
    std::mem::take(&mut buffer.lines)
}

fn keep(task: u64, line: impl FnOnce() -> LogLine) {
    let mut logs = open_logs();
    if let Some(buffer) = logs.get_mut(&task) {
        if buffer.sent + buffer.lines.len() <= MAX_TASK_LOG_LINES {
            buffer.lines.push(line());
        }
    }
}

/// The subscriber layer that feeds open [`TaskLog`]s.
pub fn layer() -> TaskLogLayer {
    TaskLogLayer
}

/// See [`layer`].
pub struct TaskLogLayer;

/// The task id of a `task{id}` span, kept in its extensions.
struct TaskId(u64);

impl<S: Subscriber + for<'a> LookupSpan<'a>> Layer<S> for TaskLogLayer {
    fn on_new_span(&self, attrs: &Attributes<'_>, id: &Id, ctx: Context<'_, S>) {
        if attrs.metadata().name() != "task" {
            return;
        }
        let mut visitor = IdField(None);
        attrs.record(&mut visitor);
        if let (Some(task), Some(span)) = (visitor.0, ctx.span(id)) {
            span.extensions_mut().insert(TaskId(task));
        }
    }

    fn on_event(&self, event: &Event<'_>, ctx: Context<'_, S>) {
        let Some(scope) = ctx.event_scope(event) else {
            return;
        };
        let Some(task) = scope
            .into_iter()
            .find_map(|span| span.extensions().get::<TaskId>().map(|t| t.0))
        else {
            return;
        };
        keep(task, || {
            let mut text = Text::default();
            event.record(&mut text);
            LogLine::bounded(now_ms(), level(*event.metadata().level()), text.finish())
        });
    }
}

fn level(level: Level) -> LogLevel {
    match level {
        Level::ERROR => LogLevel::Error,
        Level::WARN => LogLevel::Warn,
        Level::INFO => LogLevel::Info,
        Level::DEBUG => LogLevel::Debug,
        Level::TRACE => LogLevel::Trace,
    }
}

fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

/// Reads the `id` field of a `task` span.
struct IdField(Option<u64>);

impl Visit for IdField {
    fn record_u64(&mut self, field: &Field, value: u64) {
        if field.name() == "id" {
            self.0 = Some(value);
        }
    }

    fn record_i64(&mut self, field: &Field, value: i64) {
        if field.name() == "id" {
            self.0 = u64::try_from(value).ok();
        }
    }

    fn record_debug(&mut self, _: &Field, _: &dyn std::fmt::Debug) {}
}

/// An event as one line: its message, then its other fields as `name=value`.
#[derive(Default)]
struct Text {
    message: String,
    fields: String,
}

impl Text {
    fn finish(self) -> String {
        match (self.message.is_empty(), self.fields.is_empty()) {
            (_, true) => self.message,
            (true, false) => self.fields,
            (false, false) => format!("{} {}", self.message, self.fields),
        }
    }
}

impl Visit for Text {
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.message.push_str(value);
        } else {
            self.record_debug(field, &value);
        }
    }

    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            let _ = write!(self.message, "{value:?}");
        } else {
            if !self.fields.is_empty() {
                self.fields.push(' ');
            }
            let _ = write!(self.fields, "{}={value:?}", field.name());
        }
    }
}

#[cfg(test)]
mod tests {
    use tracing_subscriber::layer::SubscriberExt;

    use super::*;

    #[test]
    fn lines_inside_an_open_task_span_are_kept_bounded_and_taken_once() {
        // Ids no other test's server hands out: the open logs are per process.
        const TASK: u64 = 1 << 60;
        let subscriber = tracing_subscriber::registry().with(layer());
        tracing::subscriber::with_default(subscriber, || {
            let log = TaskLog::open(TASK);
            let span = tracing::info_span!("task", id = TASK, job = 3u64);
            span.in_scope(|| {
                tracing::info!("lease taken");
                let inner = tracing::info_span!("scene");
                inner.in_scope(|| tracing::warn!(bytes = 12, "scene fetched"));
            });
            // Outside the span, and inside a task span with no open log: not kept.
            tracing::info!("idle");
            tracing::info_span!("task", id = TASK + 1).in_scope(|| tracing::info!("other"));

            let lines = log.take();
            let texts: Vec<&str> = lines.iter().map(|l| &l.text[..]).collect();
            assert_eq!(texts, ["lease taken", "scene fetched bytes=12"]);
            assert_eq!(lines[1].level, LogLevel::Warn);
            assert!(log.take().is_empty(), "taken lines are not taken again");

            // At most one line past the bound is kept, over every take.
            span.in_scope(|| {
                for i in 0..MAX_TASK_LOG_LINES + 10 {
                    tracing::info!("line {i}");
                }
            });
            assert_eq!(log.take().len(), MAX_TASK_LOG_LINES + 1 - 2);
            drop(log);
            span.in_scope(|| tracing::info!("after close"));
            assert!(take(TASK).is_empty());
        });
    }
}
