//! Scenes on disk, content-addressed: `<cache_dir>/<digest>.glb`. A file is trusted only
//! when its SHA-256 equals its name (a truncated or corrupted file is removed and fetched
//! again), and written atomically (temp file in the same folder, fsync, rename) so that a
//! worker killed mid-write, or two workers sharing the folder, never leave half a scene
//! under the final name.
//!
//! The folder has a size limit: after each new scene, the least recently used ones (by
//! modification time, which a read refreshes) are removed until the scenes fit, so a
//! worker that renders job after job for months does not fill its disk. The scene just
//! written always stays, even when it alone is over the limit.

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::SystemTime;

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
    limit_bytes: u64,
}

/// What [`SceneCache::trim`] removed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Trimmed {
    /// Scenes removed.
    pub scenes: usize,
    /// Their bytes.
    pub bytes: u64,
}

impl SceneCache {
    /// A cache in `dir` (created on the first write) holding at most `limit_bytes` of
    /// scenes (see [`SceneCache::trim`]).
    pub fn new(dir: impl Into<PathBuf>, limit_bytes: u64) -> Self {
        SceneCache {
            dir: dir.into(),
            limit_bytes,
        }
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
            // Recently used: the last to go when the folder is trimmed. A file that cannot
            // be touched only risks being trimmed early.
            let _ = fs::File::options()
                .write(true)
                .open(&path)
                .and_then(|f| f.set_modified(SystemTime::now()));
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

    /// Removes the least recently used scenes until the folder's scenes fit in the limit,
    /// never `keep` (the scene in use). Only `<digest>.glb` files count: another worker's
    /// temp file mid-write is left alone, and so is anything else in the folder. A scene
    /// that another worker sharing the folder removed first is skipped.
    pub fn trim(&self, keep: &str) -> io::Result<Trimmed> {
        let mut scenes = Vec::new();
        let mut total = 0u64;
        for entry in fs::read_dir(&self.dir)? {
            let entry = entry?;
            let name = entry.file_name();
            let Some(digest) = name.to_str().and_then(|n| n.strip_suffix(".glb")) else {
                continue;
            };
            if !is_digest(digest) {
                continue;
            }
            let meta = match entry.metadata() {
                Ok(m) if m.is_file() => m,
                Ok(_) => continue,
                Err(e) if e.kind() == io::ErrorKind::NotFound => continue,
                Err(e) => return Err(e),
            };
            total += meta.len();
            if digest != keep {
                let used = meta.modified().unwrap_or(SystemTime::UNIX_EPOCH);
                scenes.push((used, meta.len(), entry.path()));
            }
        }
        scenes.sort();
        let mut trimmed = Trimmed::default();
        for (_, len, path) in scenes {
            if total <= self.limit_bytes {
                break;
            }
            match fs::remove_file(&path) {
                Ok(()) => {
                    trimmed.scenes += 1;
                    trimmed.bytes += len;
                }
                Err(e) if e.kind() == io::ErrorKind::NotFound => {}
                Err(e) => return Err(e),
            }
            total -= len;
        }
        Ok(trimmed)
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
        let cache = SceneCache::new(dir.path().join("scenes"), u64::MAX);
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

    #[test]
    fn trimming_removes_the_least_recently_used_scenes_down_to_the_limit() {
        let dir = tempfile::tempdir().unwrap();
        // Four scenes of 1000 bytes; the limit holds two and a half.
        let cache = SceneCache::new(dir.path(), 2500);
        let scenes: Vec<(String, Vec<u8>)> = (0..4u8)
            .map(|i| {
                let bytes = vec![i; 1000];
                (sha256_hex(&bytes), bytes)
            })
            .collect();
        let hour = std::time::Duration::from_secs(3600);
        let epoch = SystemTime::now() - 10 * hour;
        for (i, (digest, bytes)) in scenes.iter().enumerate() {
            let path = cache.write(digest, bytes).unwrap();
            // Written an hour apart, oldest first.
            let f = fs::File::options().write(true).open(path).unwrap();
            f.set_modified(epoch + hour * i as u32).unwrap();
        }
        // Reading scene 0 makes it the most recently used.
        assert!(matches!(cache.read(&scenes[0].0).unwrap(), Cached::Hit(_)));
        // Someone else's file and a temp file mid-write are not scenes.
        fs::write(dir.path().join("notes.txt"), [0u8; 5000]).unwrap();
        fs::write(dir.path().join(".abc.glb.1-0.tmp"), [0u8; 5000]).unwrap();

        // Scene 3 is in use: scenes 1 and 2 (the least recently used) go.
        let trimmed = cache.trim(&scenes[3].0).unwrap();
        assert_eq!(
            trimmed,
            Trimmed {
                scenes: 2,
                bytes: 2000
            }
        );
        let present = |i: usize| cache.path(&scenes[i].0).exists();
        assert!(present(0) && !present(1) && !present(2) && present(3));
        assert!(dir.path().join("notes.txt").exists());
        assert!(dir.path().join(".abc.glb.1-0.tmp").exists());
        // Within the limit now: nothing more goes.
        assert_eq!(cache.trim(&scenes[3].0).unwrap(), Trimmed::default());

        // A limit below one scene keeps the scene in use and nothing else.
        let tiny = SceneCache::new(dir.path(), 10);
        assert_eq!(tiny.trim(&scenes[0].0).unwrap().scenes, 1);
        assert!(present(0) && !present(3));
    }
}
