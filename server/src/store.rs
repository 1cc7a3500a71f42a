//! Files on disk beside the database: scenes content-addressed by SHA-256, accepted tiles
//! until their frame is assembled, and each job's output folder.
//!
//! ```text
//! data/tessera.db            SQLite (WAL)
//! data/scenes/<sha256>.glb
//! data/tiles/<job>/<task>.<attempt>.exr
//! data/jobs/<job>/frame_0001.exr, frame_0001.png
//! ```

use std::collections::HashSet;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

/// Where everything lives under the data folder.
#[derive(Clone, Debug)]
pub struct Store {
    root: PathBuf,
}

impl Store {
    /// Creates the folders under `root` when missing.
    pub fn open(root: &Path) -> io::Result<Store> {
        for sub in ["scenes", "tiles", "jobs"] {
            fs::create_dir_all(root.join(sub))?;
        }
        Ok(Store {
            root: root.to_owned(),
        })
    }

    /// Removes the temp files that writes cut short by a crash left (hidden files in the
    /// scene, tile and job folders: every atomic write's temp file is one), which can be
    /// as large as a frame. Call it before anything writes. Returns how many went.
    pub fn remove_temp_files(&self) -> io::Result<usize> {
        let mut folders = vec![self.root.join("scenes")];
        for area in ["tiles", "jobs"] {
            for entry in fs::read_dir(self.root.join(area))? {
                folders.push(entry?.path());
            }
        }
        let mut removed = 0;
        for folder in folders.iter().filter(|f| f.is_dir()) {
            for entry in fs::read_dir(folder)? {
                let entry = entry?;
                if entry.file_name().to_string_lossy().starts_with('.') && entry.path().is_file() {
                    fs::remove_file(entry.path())?;
                    removed += 1;
                }
            }
        }
        Ok(removed)
    }

    /// A store rooted at `root` without touching the disk.
    pub fn unopened(root: &Path) -> Store {
        Store {
            root: root.to_owned(),
        }
    }

    /// The database file.
    pub fn database(&self) -> PathBuf {
        self.root.join("tessera.db")
    }

    /// The GLB of the scene `digest` (a checked hex digest).
    pub fn scene(&self, digest: &str) -> PathBuf {
        self.root.join("scenes").join(format!("{digest}.glb"))
    }

    /// The tile one attempt at a task uploaded. Each attempt has its own file, so a stale
    /// upload cannot overwrite the accepted one; the task's done attempt names the tile
    /// that counts.
    pub fn tile(&self, job: u64, task: u64, attempt: u32) -> PathBuf {
        self.tile_dir(job).join(format!("{task}.{attempt}.exr"))
    }

    /// Renames the tiles of a data folder written before tiles were named by attempt
    /// (`<task>.exr`) to their task's current attempt, which for a done task is the
    /// accepted one; a tile whose task is gone is removed. `attempt_of` reads the
    /// database. Returns how many were renamed.
    pub fn name_tiles_by_attempt(
        &self,
        mut attempt_of: impl FnMut(u64) -> crate::error::Result<Option<u32>>,
    ) -> crate::error::Result<usize> {
        let mut renamed = 0;
        for job in fs::read_dir(self.root.join("tiles"))? {
            let job = job?.path();
            let Some(job_id) = job
                .file_name()
                .and_then(|n| n.to_str()?.parse::<u64>().ok())
            else {
                continue;
            };
            for entry in fs::read_dir(&job)? {
                let entry = entry?;
                let name = entry.file_name();
                let Some(task) = name
                    .to_str()
                    .and_then(|n| n.strip_suffix(".exr")?.parse().ok())
                else {
                    continue;
                };
                match attempt_of(task)? {
                    Some(attempt) => {
                        fs::rename(entry.path(), self.tile(job_id, task, attempt))?;
                        renamed += 1;
                    }
                    None => fs::remove_file(entry.path())?,
                }
            }
        }
        Ok(renamed)
    }

    /// Removes a job's output and tile folders.
    pub fn remove_job(&self, job: u64) -> io::Result<()> {
        for dir in [self.job_dir(job), self.tile_dir(job)] {
            match fs::remove_dir_all(&dir) {
                Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(e),
                _ => {}
            }
        }
        Ok(())
    }

    /// Removes a frame's files (EXR and PNG) from a job's output folder.
    pub fn remove_frame(&self, job: u64, frame: i32, last: i32) -> io::Result<()> {
        for extension in ["exr", "png"] {
            remove_if_there(&self.frame(job, frame, last, extension))?;
        }
        Ok(())
    }

    /// Removes a scene's file.
    pub fn remove_scene(&self, digest: &str) -> io::Result<()> {
        remove_if_there(&self.scene(digest))
    }

    /// Removes the tile files of `tasks` in a job's tile folder, of every attempt.
    pub fn remove_tiles(&self, job: u64, tasks: &HashSet<u64>) {
        let Ok(entries) = fs::read_dir(self.tile_dir(job)) else {
            return;
        };
        for entry in entries.flatten() {
            let name = entry.file_name();
            let task = name
                .to_str()
                .and_then(|n| n.split_once('.')?.0.parse().ok());
            if task.is_some_and(|t| tasks.contains(&t)) {
                // The frame holds them now; a leftover tile only costs disk.
                let _ = fs::remove_file(entry.path());
            }
        }
    }

    /// Every layer of a time-budget job's frame as assembled so far, with the passes it
    /// holds: the next pass of the frame merges into it (its tiles are gone by then).
    pub fn merged_frame(&self, job: u64, frame: i32) -> PathBuf {
        self.tile_dir(job)
            .join(proto::job::frame_file_name(frame, frame, "merged.exr"))
    }

    /// The folder holding a job's accepted tiles.
    pub fn tile_dir(&self, job: u64) -> PathBuf {
        self.root.join("tiles").join(job.to_string())
    }

    /// The job's output folder.
    pub fn job_dir(&self, job: u64) -> PathBuf {
        self.root.join("jobs").join(job.to_string())
    }

    /// A frame file of a job whose last frame is `last` (`frame_0001.exr`,
    /// `frame_0001.png`: [`proto::job::frame_file_name`]).
    pub fn frame(&self, job: u64, frame: i32, last: i32, extension: &str) -> PathBuf {
        self.job_dir(job)
            .join(proto::job::frame_file_name(frame, last, extension))
    }
}

/// Lower-case hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// `bytes` as lower-case hex digits.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The shortest start of a digest that names a scene: what the CLI prints is 12.
pub const MIN_DIGEST_PREFIX: usize = 8;

/// Whether `s` is the start of a digest, [`MIN_DIGEST_PREFIX`] to 64 lower-case hex digits.
pub fn is_digest_prefix(s: &str) -> bool {
    (MIN_DIGEST_PREFIX..=64).contains(&s.len())
        && s.bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// Whether `s` looks like a digest this server wrote (64 lower-case hex digits), so it
/// can be used as a file name safely.
pub fn is_digest(s: &str) -> bool {
    s.len() == 64
        && s.bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// Writes `bytes` to `path` atomically (the tracer's [`tracer::output::write_atomic`]),
/// creating its folder when missing. A reader (or a restarted server) sees the old file or
/// the new one, never half of one; a full or read-only disk stays
/// [`Error::Storage`](crate::error::Error::Storage).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> crate::error::Result<()> {
    fs::create_dir_all(path.parent().unwrap_or(Path::new(".")))?;
    Ok(tracer::output::write_atomic(path, bytes)?)
}

/// Removes the file at `path`; one that is not there is fine.
fn remove_if_there(path: &Path) -> io::Result<()> {
    match fs::remove_file(path) {
        Err(e) if e.kind() != io::ErrorKind::NotFound => Err(e),
        _ => Ok(()),
    }
}

/// Bytes of the files under `path` (0 when it is missing); what cannot be read counts 0.
pub fn disk_use(path: &Path) -> u64 {
    let Ok(meta) = fs::symlink_metadata(path) else {
        return 0;
    };
    if !meta.is_dir() {
        return meta.len();
    }
    fs::read_dir(path)
        .map(|entries| entries.flatten().map(|e| disk_use(&e.path())).sum())
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sha256_of_abc_is_the_known_digest() {
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert!(is_digest(&sha256_hex(b"abc")));
        assert!(!is_digest("../../etc/passwd"));
        assert!(!is_digest(&"A".repeat(64)));
    }

    #[test]
    fn temp_files_left_by_a_crash_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(dir.path()).unwrap();
        let frame = store.frame(3, 1, 1, "exr");
        fs::create_dir_all(frame.parent().unwrap()).unwrap();
        fs::write(&frame, b"frame").unwrap();
        let temp = frame.with_file_name(".frame_0001.exr.tmp-123-0");
        fs::write(&temp, b"half a frame").unwrap();
        let tile = store.tile(3, 9, 1).with_file_name(".9.1.exr.123.0.tmp");
        fs::create_dir_all(tile.parent().unwrap()).unwrap();
        fs::write(&tile, b"half a tile").unwrap();
        assert_eq!(store.remove_temp_files().unwrap(), 2);
        assert!(frame.is_file() && !temp.exists() && !tile.exists());
    }

    #[test]
    fn tiles_named_before_attempts_take_their_tasks_attempt() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(dir.path()).unwrap();
        let folder = store.tile_dir(4);
        fs::create_dir_all(&folder).unwrap();
        for name in ["7.exr", "8.exr", "9.2.exr", "frame_0001.merged.exr"] {
            fs::write(folder.join(name), name).unwrap();
        }
        // Task 7 is at attempt 3; task 8 is gone.
        let attempt_of = |task| Ok((task == 7).then_some(3));
        assert_eq!(store.name_tiles_by_attempt(attempt_of).unwrap(), 1);
        assert_eq!(fs::read(store.tile(4, 7, 3)).unwrap(), b"7.exr");
        let mut left: Vec<_> = fs::read_dir(&folder)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        left.sort();
        assert_eq!(left, ["7.3.exr", "9.2.exr", "frame_0001.merged.exr"]);
        store.remove_tiles(4, &HashSet::from([7, 9]));
        assert_eq!(fs::read_dir(&folder).unwrap().count(), 1);
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temp_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub").join("f.bin");
        write_atomic(&path, b"one").unwrap();
        write_atomic(&path, b"two").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"two");
        let names: Vec<_> = fs::read_dir(path.parent().unwrap()).unwrap().collect();
        assert_eq!(names.len(), 1);
    }
}
