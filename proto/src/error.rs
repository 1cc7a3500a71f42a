//! The JSON body of every error answer.

use serde::{Deserialize, Serialize};

/// What went wrong, for a person to act on: `message` says what and, where it can, how to
/// fix it; `field` names the job-spec field (or header) at fault.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ErrorBody {
    /// A stable machine-readable kind: `invalid_field`, `not_found`, `lease_gone`,
    /// `bad_scene`, `bad_tile`, `too_large`, `conflict`, `unauthorized`, `internal`.
    pub error: String,
    /// A sentence for a person.
    pub message: String,
    /// The field or header at fault, when one is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
}
