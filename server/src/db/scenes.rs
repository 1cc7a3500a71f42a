//! The `scenes` table: each uploaded scene's digest, size and summary (its bytes are in
//! the store, named by the digest).

use proto::SceneInfo;
use rusqlite::{params, Connection, OptionalExtension, Transaction};

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

/// Records a checked scene; uploaded again, only its upload time changes (retention keeps
/// a scene no job uses for a while after its last upload).
pub fn insert(
    conn: &Connection,
    digest: &str,
    size: u64,
    info: &SceneInfo,
    now: i64,
) -> Result<()> {
    conn.exec(
        "INSERT INTO scenes (digest, size, info, created_ms) VALUES (?1, ?2, ?3, ?4)
         ON CONFLICT (digest) DO UPDATE SET created_ms = excluded.created_ms",
        params![digest, size as i64, serde_json::to_string(info)?, now],
    )?;
    Ok(())
}

/// Scenes last uploaded before `before`, with their sizes.
pub fn uploaded_before(conn: &Connection, before: i64) -> Result<Vec<(String, u64)>> {
    let mut stmt =
        conn.prepare_cached("SELECT digest, size FROM scenes WHERE created_ms < ?1 ORDER BY 1")?;
    let rows = stmt.query_map([before], |r| Ok((r.get(0)?, r.get(1)?)))?;
    Ok(rows.collect::<rusqlite::Result<_>>()?)
}

/// Deletes a scene's row unless a job uses it; whether it went.
pub fn delete_unused(tx: &Transaction, digest: &str) -> Result<bool> {
    Ok(tx.exec(
        "DELETE FROM scenes WHERE digest = ?1
           AND NOT EXISTS (SELECT 1 FROM jobs WHERE scene = ?1)",
        [digest],
    )? == 1)
}
