//! The server's error type: every way a request can fail, each mapped to one HTTP status
//! and a JSON [`proto::ErrorBody`] in `api/error.rs`.

/// Why a request failed.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The thing named does not exist (404).
    #[error("{0}")]
    NotFound(String),
    /// A request field is out of bounds or malformed (422); `field` names it.
    #[error("{field}: {message}")]
    Invalid {
        /// The field or header.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// The request body is not valid JSON for its type, or is otherwise unreadable (400).
    #[error("{0}")]
    BadRequest(String),
    /// The uploaded scene is not a scene the tracer can render (422).
    #[error("{0}")]
    BadScene(String),
    /// The uploaded tile is refused (422): not EXR, wrong size or channels, bad checksum,
    /// non-finite values.
    #[error("{0}")]
    BadTile(String),
    /// The request body is over the route's limit (413).
    #[error("{0}")]
    TooLarge(String),
    /// The caller proved who it is, and it is not who may do this (403): a worker acting
    /// for another.
    #[error("{0}")]
    Forbidden(String),
    /// The request conflicts with the resource's state (409): cancel a finished job, ...
    #[error("{0}")]
    Conflict(String),
    /// The fencing token is stale: the lease was revoked, expired or finished (409).
    #[error("{0}")]
    LeaseGone(String),
    /// The data folder takes no more writes (507 when full, 503 when read-only): nothing
    /// was stored, and the same request may succeed once the operator fixes the disk.
    #[error("{problem}: {detail}")]
    Storage {
        /// Full or read-only.
        problem: StorageProblem,
        /// What the OS or SQLite said (logged; the client gets only `problem`).
        detail: String,
    },
    /// The storage failed (500); the message is logged, the client gets a summary.
    #[error("{0}")]
    Internal(String),
    /// A frame cannot be assembled from what is stored for it (a tile unreadable or not
    /// what its task says, a frame over the server's assembly memory): trying again would
    /// fail again, so the frame is marked failed with this reason (500 if it ever reaches
    /// a client).
    #[error("{0}")]
    BadFrame(String),
}

/// Why the data folder takes no more writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StorageProblem {
    /// No space left, or the quota is used up (ENOSPC, EDQUOT, SQLITE_FULL).
    Full,
    /// The file system is read-only (EROFS, SQLITE_READONLY).
    ReadOnly,
}

impl std::fmt::Display for StorageProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            StorageProblem::Full => "the server's disk is full",
            StorageProblem::ReadOnly => "the data folder is read-only",
        })
    }
}

impl StorageProblem {
    /// The problem behind an OS error, if it is one an operator fixes on the disk.
    pub fn of_io(e: &std::io::Error) -> Option<StorageProblem> {
        use std::io::ErrorKind;
        match e.kind() {
            ErrorKind::StorageFull | ErrorKind::QuotaExceeded => Some(StorageProblem::Full),
            ErrorKind::ReadOnlyFilesystem => Some(StorageProblem::ReadOnly),
            _ => None,
        }
    }
}

impl From<rusqlite::Error> for Error {
    fn from(e: rusqlite::Error) -> Self {
        use rusqlite::ffi::ErrorCode;
        // SQLite rolls the statement (or the whole transaction) back on these; the
        // `Transaction` guard rolls back the rest, so the database stays as it was.
        let problem = match e.sqlite_error_code() {
            Some(ErrorCode::DiskFull) => Some(StorageProblem::Full),
            Some(ErrorCode::ReadOnly) => Some(StorageProblem::ReadOnly),
            _ => None,
        };
        match problem {
            Some(problem) => Error::Storage {
                problem,
                detail: format!("database: {e}"),
            },
            None => Error::Internal(format!("database: {e}")),
        }
    }
}

impl From<std::io::Error> for Error {
    fn from(e: std::io::Error) -> Self {
        match StorageProblem::of_io(&e) {
            Some(problem) => Error::Storage {
                problem,
                detail: format!("storage: {e}"),
            },
            None => Error::Internal(format!("storage: {e}")),
        }
    }
}

impl From<tracer::output::OutputError> for Error {
    /// A full or read-only disk is the operator's to fix, not a bug: it stays a
    /// [`Error::Storage`] (507/503); anything else is internal.
    fn from(e: tracer::output::OutputError) -> Self {
        let problem = match &e {
            tracer::output::OutputError::Io { source, .. } => StorageProblem::of_io(source),
            _ => None,
        };
        match problem {
            Some(problem) => Error::Storage {
                problem,
                detail: e.to_string(),
            },
            None => Error::Internal(e.to_string()),
        }
    }
}

impl Error {
    /// The same error with `what` (what was being done) before its message.
    pub fn context(self, what: impl std::fmt::Display) -> Error {
        match self {
            Error::NotFound(m) => Error::NotFound(format!("{what}: {m}")),
            Error::Invalid { field, message } => Error::Invalid {
                field,
                message: format!("{what}: {message}"),
            },
            Error::BadRequest(m) => Error::BadRequest(format!("{what}: {m}")),
            Error::BadScene(m) => Error::BadScene(format!("{what}: {m}")),
            Error::BadTile(m) => Error::BadTile(format!("{what}: {m}")),
            Error::TooLarge(m) => Error::TooLarge(format!("{what}: {m}")),
            Error::Forbidden(m) => Error::Forbidden(format!("{what}: {m}")),
            Error::Conflict(m) => Error::Conflict(format!("{what}: {m}")),
            Error::LeaseGone(m) => Error::LeaseGone(format!("{what}: {m}")),
            Error::Storage { problem, detail } => Error::Storage {
                problem,
                detail: format!("{what}: {detail}"),
            },
            Error::Internal(m) => Error::Internal(format!("{what}: {m}")),
            Error::BadFrame(m) => Error::BadFrame(format!("{what}: {m}")),
        }
    }
}

impl From<serde_json::Error> for Error {
    fn from(e: serde_json::Error) -> Self {
        Error::Internal(format!("stored JSON: {e}"))
    }
}

impl From<crate::spec::FieldError> for Error {
    fn from(e: crate::spec::FieldError) -> Self {
        Error::Invalid {
            field: e.field,
            message: e.message,
        }
    }
}

impl From<crate::state::InvalidTransition> for Error {
    fn from(e: crate::state::InvalidTransition) -> Self {
        Error::Conflict(e.to_string())
    }
}

/// The server's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

#[cfg(test)]
mod tests {
    use std::io;

    use axum::http::StatusCode;

    use super::*;

    fn sqlite(code: i32) -> rusqlite::Error {
        rusqlite::Error::SqliteFailure(rusqlite::ffi::Error::new(code), None)
    }

    #[test]
    fn a_full_disk_answers_507_and_says_so() {
        let full = [
            Error::from(io::Error::from(io::ErrorKind::StorageFull)),
            Error::from(io::Error::from(io::ErrorKind::QuotaExceeded)),
            Error::from(sqlite(rusqlite::ffi::SQLITE_FULL)),
        ];
        for e in full {
            assert_eq!(
                e.status(),
                (StatusCode::INSUFFICIENT_STORAGE, "storage_full")
            );
            let body = e.body();
            assert!(
                body.message.starts_with("the server's disk is full"),
                "{body:?}"
            );
        }
    }

    #[test]
    fn a_read_only_data_folder_answers_503_and_says_so() {
        let read_only = [
            Error::from(io::Error::from(io::ErrorKind::ReadOnlyFilesystem)),
            Error::from(sqlite(rusqlite::ffi::SQLITE_READONLY)),
        ];
        for e in read_only {
            assert_eq!(
                e.status(),
                (StatusCode::SERVICE_UNAVAILABLE, "storage_read_only")
            );
            let body = e.body();
            assert!(
                body.message.starts_with("the data folder is read-only"),
                "{body:?}"
            );
        }
    }

    #[test]
    fn the_os_error_behind_a_full_disk_stays_in_the_log() {
        // ENOSPC, as write(2) reports it on Linux.
        let e = Error::from(io::Error::from_raw_os_error(28));
        assert!(e.to_string().contains("storage: "), "{e}");
        assert!(!e.body().message.contains("os error"), "{:?}", e.body());
    }

    #[test]
    fn other_storage_errors_stay_500() {
        let others = [
            Error::from(io::Error::from(io::ErrorKind::PermissionDenied)),
            Error::from(sqlite(rusqlite::ffi::SQLITE_CORRUPT)),
        ];
        for e in others {
            assert_eq!(e.status(), (StatusCode::INTERNAL_SERVER_ERROR, "internal"));
        }
    }
}
