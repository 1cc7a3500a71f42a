//! Retention: `POST /gc` removes what the farm no longer needs (finished jobs past the
//! server's `--keep-jobs`, scenes no job uses, events past the log's bound) and says what
//! went, or with `dry_run` what would go.

use serde::{Deserialize, Serialize};

/// `POST /gc` body.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct GcRequest {
    /// Only say what would go.
    #[serde(default)]
    pub dry_run: bool,
    /// Keep finished jobs by this rule instead of the server's `--keep-jobs`: an age
    /// (`30d`, `12h`, `90m`, `45s`) or a count (`50`: the 50 finished last).
    #[serde(default)]
    pub keep_jobs: Option<String>,
}

/// A finished job that retention removes.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct GcJob {
    /// Its id.
    pub id: u64,
    /// Its name.
    pub name: String,
    /// When it finished, Unix ms.
    pub finished_ms: i64,
}

/// What retention removed (or, on a dry run, would remove).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct GcReport {
    /// Nothing was removed: this is what would go.
    pub dry_run: bool,
    /// The rule finished jobs were kept by, as given (`all` when every job is kept).
    pub keep_jobs: String,
    /// Finished jobs, with their frames and tiles.
    pub jobs: Vec<GcJob>,
    /// Scenes no remaining job uses, uploaded more than a day ago (digests).
    pub scenes: Vec<String>,
    /// Event log entries: of jobs that are gone, and the oldest past the log's bound.
    pub events: u64,
    /// Bytes of files freed in the data folder.
    pub bytes: u64,
}
