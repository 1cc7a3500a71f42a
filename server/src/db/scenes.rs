//! The `scenes` table: each uploaded scene's digest, size and summary (its bytes are in
//! the store, named by the digest).

use proto::SceneInfo;
use rusqlite::{params, Connection, OptionalExtension};

use super::Cached;
use crate::error::Result;

/// The summary of the scene with `digest`, if it was uploaded.
pub fn info(conn: &Connection, digest: &str) -> Result<Option<SceneInfo>> {
    let json: Option<String> = conn
        .row("SELECT info FROM scenes WHERE digest = ?1", [digest], |r| {
            r.get(0)
        })
        .optional()?;
    Ok(json.map(|j| serde_json::from_str(&j)).transpose()?)
}

/// Records a checked scene (nothing when it is already there).
pub fn insert(
    conn: &Connection,
    digest: &str,
    size: u64,
    info: &SceneInfo,
    now: i64,
) -> Result<()> {
    conn.exec(
        "INSERT OR IGNORE INTO scenes (digest, size, info, created_ms) VALUES (?1, ?2, ?3, ?4)",
        params![digest, size as i64, serde_json::to_string(info)?, now],
    )?;
    Ok(())
}
