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

/// What a digest or a digest's start names: `Ok(None)` when no scene, `Err` with the
/// matches when more than one.
pub fn resolve(conn: &Connection, prefix: &str) -> Result<Result<Option<String>, Vec<String>>> {
    // Hex digits sort before 'g': the range is the prefix's, and uses the primary key.
    let mut stmt = conn.prepare_cached(
        "SELECT digest FROM scenes WHERE digest >= ?1 AND digest < ?1 || 'g'
         ORDER BY digest LIMIT 3",
    )?;
    let found: Vec<String> = stmt
        .query_map([prefix], |r| r.get(0))?
        .collect::<rusqlite::Result<_>>()?;
    Ok(match found.len() {
        0 => Ok(None),
        1 => Ok(found.into_iter().next()),
        _ => Err(found),
    })
}

/// The digests of the scenes last uploaded before `before`.
pub fn uploaded_before(conn: &Connection, before: i64) -> Result<Vec<String>> {
    let mut stmt =
        conn.prepare_cached("SELECT digest FROM scenes WHERE created_ms < ?1 ORDER BY 1")?;
    let rows = stmt.query_map([before], |r| r.get(0))?;
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
