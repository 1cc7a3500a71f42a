//! Who a worker is: joining the farm as a new worker, or as an earlier one come back (by
//! the credential it kept, or by the name of a worker that is gone), and the credentials
//! that prove it on every later call. The database keeps only each credential's SHA-256.

use rusqlite::Connection;

use crate::db::events::log;
use crate::db::tasks;
use crate::db::workers::{self, Profile};
use crate::error::{Error, Result};
use crate::store::sha256_hex;

/// A worker asking to join: [`proto::WorkerRegistration`], checked.
#[derive(Clone, Copy, Debug)]
pub struct Joining<'a> {
    /// What it says of itself (its name no two live workers share).
    pub profile: Profile<'a>,
    /// The credential it kept from an earlier registration.
    pub credential: Option<&'a str>,
}

/// Who a joining worker turned out to be.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Joined {
    /// Its id: an earlier worker's when it came back.
    pub id: u64,
    /// The credential to use from now on.
    pub credential: String,
    /// It is an earlier worker come back (`false`: a new one).
    pub returned: bool,
}

/// Registers a worker, or takes an earlier one back: the worker whose credential it
/// presents, else the last worker of its name when that one is gone (left, or not seen
/// for two lease periods: seen before `live_since`). A name a live worker holds is
/// refused (409). A returning worker's leases are queued again (its previous process is
/// gone) and it gets a fresh credential unless it presented its own; its quarantine and
/// job blocks stay. Only the credential's SHA-256 is stored.
pub fn join(conn: &mut Connection, joining: &Joining, now: i64, live_since: i64) -> Result<Joined> {
    let tx = conn.transaction()?;
    let by_credential = match joining.credential {
        Some(c) => worker_of_credential(&tx, c)?,
        None => None,
    };
    let holder = workers::newest_named(&tx, joining.profile.name, live_since)?;
    let (returning, credential) = match (by_credential, holder) {
        (Some(id), Some((other, true))) if other != id => {
            return Err(name_in_use(joining.profile.name, other))
        }
        (Some(id), _) => (Some(id), joining.credential.unwrap_or_default().to_string()),
        (None, Some((other, true))) => return Err(name_in_use(joining.profile.name, other)),
        (None, Some((gone, false))) => (Some(gone), new_credential()?),
        (None, None) => (None, new_credential()?),
    };
    let hash = sha256_hex(credential.as_bytes());
    let id = match returning {
        Some(id) => {
            let held = tasks::give_back(&tx, id)?;
            workers::set_returned(&tx, id, &joining.profile, &hash, now)?;
            log(
                &tx,
                now,
                None,
                "worker_returned",
                &format!(
                    "{id} {}, {} leases given back",
                    joining.profile.name,
                    held.len()
                ),
            )?;
            id
        }
        None => {
            let id = workers::insert(&tx, &joining.profile, &hash, now)?;
            log(
                &tx,
                now,
                None,
                "worker_registered",
                &format!("{id} {}", joining.profile.name),
            )?;
            id
        }
    };
    tx.commit()?;
    Ok(Joined {
        id,
        credential,
        returned: returning.is_some(),
    })
}

/// The refusal of a name a live worker holds.
fn name_in_use(name: &str, holder: u64) -> Error {
    Error::Conflict(format!(
        "the name `{name}` belongs to worker {holder}, which is live: give this worker \
         another --name, or start it once that one has left or gone silent for two lease \
         periods"
    ))
}

/// A new worker credential: 32 random bytes from the OS, in hex.
fn new_credential() -> Result<String> {
    let mut bytes = [0u8; 32];
    getrandom::fill(&mut bytes)
        .map_err(|e| Error::Internal(format!("drawing a worker credential: {e}")))?;
    Ok(crate::store::hex(&bytes))
}

/// The worker `credential` belongs to, if any.
pub fn worker_of_credential(conn: &Connection, credential: &str) -> Result<Option<u64>> {
    workers::of_credential_hash(conn, &sha256_hex(credential.as_bytes()))
}
