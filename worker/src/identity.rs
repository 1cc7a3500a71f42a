//! Who this worker is to a server, kept across restarts: the credential its registration
//! answered, in a file beside the scene cache. A worker that comes back with it is the
//! same worker to the server, so a quarantine or a job block follows the machine through
//! a restart instead of being shed by it.
//!
//! The file is named after the server and the worker's name, so several workers may share
//! a cache folder, and one worker may work for several servers, without taking each
//! other's identity. Only the owner may read it (mode 0600): the credential lets whoever
//! holds it act as this worker.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// What the file holds.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Identity {
    /// The server's base URL.
    pub server: String,
    /// The worker's name.
    pub name: String,
    /// The worker id the server gave.
    pub worker_id: u64,
    /// The worker's credential.
    pub credential: String,
}

/// The identity file of worker `name` of `server` in `dir`.
pub fn path(dir: &Path, server: &str, name: &str) -> PathBuf {
    let key = Sha256::digest(format!("{}\n{name}", server.trim_end_matches('/')));
    let hex: String = key[..8].iter().map(|b| format!("{b:02x}")).collect();
    dir.join(format!("identity-{hex}.json"))
}

/// The credential kept for worker `name` of `server`, if a readable file holds one for
/// exactly them (anything else is as if there were none: the worker registers anew).
pub fn load(dir: &Path, server: &str, name: &str) -> Option<Identity> {
    let text = std::fs::read_to_string(path(dir, server, name)).ok()?;
    let identity: Identity = serde_json::from_str(&text).ok()?;
    (identity.server == server.trim_end_matches('/') && identity.name == name).then_some(identity)
}

/// Keeps `identity` (replacing the file atomically, readable by the owner only).
pub fn save(dir: &Path, identity: &Identity) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let target = path(dir, &identity.server, &identity.name);
    let json = serde_json::to_vec_pretty(identity).map_err(std::io::Error::other)?;
    // tempfile creates the file with mode 0600.
    let mut temp = tempfile::NamedTempFile::new_in(dir)?;
    std::io::Write::write_all(&mut temp, &json)?;
    temp.as_file().sync_all()?;
    temp.persist(target).map_err(|e| e.error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_identity_is_kept_per_server_and_name() {
        let dir = tempfile::tempdir().unwrap();
        let me = Identity {
            server: "https://farm:8700".into(),
            name: "w1".into(),
            worker_id: 7,
            credential: "c".repeat(64),
        };
        assert_eq!(load(dir.path(), &me.server, "w1"), None);
        save(dir.path(), &me).unwrap();
        assert_eq!(
            load(dir.path(), "https://farm:8700/", "w1"),
            Some(me.clone())
        );
        assert_eq!(load(dir.path(), &me.server, "w2"), None);
        assert_eq!(load(dir.path(), "http://other:8700", "w1"), None);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let file = path(dir.path(), &me.server, "w1");
            let mode = std::fs::metadata(file).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        let again = Identity {
            worker_id: 9,
            ..me.clone()
        };
        save(dir.path(), &again).unwrap();
        assert_eq!(load(dir.path(), &me.server, "w1").unwrap().worker_id, 9);
    }
}
