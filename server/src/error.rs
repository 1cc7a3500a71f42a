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
    /// The request conflicts with the resource's state (409): cancel a finished job, ...
    #[error("{0}")]
    Conflict(String),
    /// The fencing token is stale: the lease was revoked, expired or finished (409).
    #[error("{0}")]
    LeaseGone(String),
    /// The storage failed (500); the message is logged, the client gets a summary.
    #[error("{0}")]
    Internal(String),
}

impl From<rusqlite::Error> for Error {
    fn from(e: rusqlite::Error) -> Self {
        Error::Internal(format!("database: {e}"))
    }
}

impl From<std::io::Error> for Error {
    fn from(e: std::io::Error) -> Self {
        Error::Internal(format!("storage: {e}"))
    }
}

impl From<serde_json::Error> for Error {
    fn from(e: serde_json::Error) -> Self {
        Error::Internal(format!("stored JSON: {e}"))
    }
}

impl From<crate::state::InvalidTransition> for Error {
    fn from(e: crate::state::InvalidTransition) -> Self {
        Error::Conflict(e.to_string())
    }
}

/// The server's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;
