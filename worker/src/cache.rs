//! Scenes on disk, content-addressed: `<cache_dir>/<digest>.glb`. A file is trusted only
//! when its SHA-256 equals its name (a truncated or corrupted file is removed and fetched
//! again), and written atomically (temp file in the same folder, fsync, rename) so that a
//! worker killed mid-write, or two workers sharing the folder, never leave half a scene
//! under the final name.

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use sha2::{Digest, Sha256};

/// Lower-case hex SHA-256 of `bytes`, the form of scene digests and tile checksums.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Whether `digest` is a SHA-256 as the server writes it: 64 lower-case hex digits. It
/// becomes a file name, so nothing else (no `/`, no `..`) may pass.
pub fn is_digest(digest: &str) -> bool {
    digest.len() == 64
        && digest
            .bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// What reading the cache found.
#[derive(Debug)]
pub enum Cached {
    /// The scene's bytes, verified.
    Hit(Vec<u8>),
    /// No file.
    Miss,
    /// A file whose SHA-256 is not its name; it has been removed.
    Corrupt {
        /// The SHA-256 the file had.
        found: String,
    },
}

/// The scene folder.
#[derive(Clone, Debug)]
pub struct SceneCache {
    dir: PathBuf,
}

impl SceneCache {
    /// A cache in `dir` (created on the first write).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        SceneCache { dir: dir.into() }
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Where the scene `digest` lives. `digest` must pass [`is_digest`].
    pub fn path(&self, digest: &str) -> PathBuf {
        debug_assert!(is_digest(digest));
        self.dir.join(format!("{digest}.glb"))
    }

    /// Reads and verifies the scene `digest`; removes a file that fails verification.
    pub fn read(&self, digest: &str) -> io::Result<Cached> {
        let path = self.path(digest);
        let bytes = match fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Cached::Miss),
            Err(e) => return Err(e),
        };
        let found = sha256_hex(&bytes);
        if found == digest {
            return Ok(Cached::Hit(bytes));
        }
        match fs::remove_file(&path) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
        Ok(Cached::Corrupt { found })
    }

    /// Stores `bytes` as the scene `digest`, atomically; returns the file.
    pub fn write(&self, digest: &str, bytes: &[u8]) -> io::Result<PathBuf> {
        static WRITES: AtomicU64 = AtomicU64::new(0);
        fs::create_dir_all(&self.dir)?;
        let path = self.path(digest);
        let temp = self.dir.join(format!(
            ".{digest}.glb.{}-{}.tmp",
            std::process::id(),
            WRITES.fetch_add(1, Ordering::Relaxed)
        ));
        let written = (|| {
            let mut f = fs::File::create(&temp)?;
            f.write_all(bytes)?;
            f.sync_all()?;
            fs::rename(&temp, &path)
        })();
        if written.is_err() {
            let _ = fs::remove_file(&temp);
        }
        written.map(|()| path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn digests_are_checked_before_they_become_file_names() {
        assert!(is_digest(&sha256_hex(b"scene")));
        assert!(!is_digest(&"A".repeat(64)));
        assert!(!is_digest("../../etc/passwd"));
        assert!(!is_digest(&"0".repeat(63)));
    }

    #[test]
    fn sha256_matches_a_known_answer() {
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn a_written_scene_reads_back_and_a_corrupt_one_is_removed() {
        let dir = tempfile::tempdir().unwrap();
        let cache = SceneCache::new(dir.path().join("scenes"));
        let bytes = b"glTF pretend".to_vec();
        let digest = sha256_hex(&bytes);
        assert!(matches!(cache.read(&digest).unwrap(), Cached::Miss));
        let path = cache.write(&digest, &bytes).unwrap();
        assert!(matches!(cache.read(&digest).unwrap(), Cached::Hit(b) if b == bytes));
        // Nothing but the scene is left in the folder.
        assert_eq!(fs::read_dir(cache.dir()).unwrap().count(), 1);
        fs::write(&path, b"glTF prete").unwrap();
        assert!(matches!(
            cache.read(&digest).unwrap(),
            Cached::Corrupt { .. }
        ));
        assert!(!path.exists());
    }
}
