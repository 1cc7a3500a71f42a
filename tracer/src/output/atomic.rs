//! Atomic file writes: a reader of `path` sees the old file or the new one, never half of
//! one, and after a crash the new file is either complete on disk or absent.

use std::fs::{self, File, OpenOptions};
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use super::OutputError;

/// Writes `bytes` to `path` atomically (see `AtomicFile`).
pub fn write(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    let mut file = AtomicFile::create(path)?;
    file.write_all(bytes).map_err(|e| file.error(e))?;
    file.commit()
}

/// A file that appears at its path whole or not at all: written into a temp file in the
/// same folder (a rename is atomic only within one file system), then fsynced, renamed
/// over `path`, and the folder fsynced so that the rename itself is durable. Dropped
/// before [`commit`](Self::commit), it removes its temp file. A `path` that exists but is
/// not a regular file (`/dev/null`, a socket, a pipe) is refused: the rename would
/// replace it.
pub struct AtomicFile {
    path: PathBuf,
    temp: PathBuf,
    file: Option<BufWriter<File>>,
}

impl AtomicFile {
    /// Creates the temp file for `path`.
    pub fn create(path: &Path) -> Result<AtomicFile, OutputError> {
        let io = |source| OutputError::Io {
            path: path.to_path_buf(),
            source,
        };
        if fs::metadata(path).is_ok_and(|m| !m.is_file()) {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "exists and is not a regular file; only files are replaced",
            )));
        }
        let file_name = path.file_name().ok_or_else(|| {
            io(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "not a file name",
            ))
        })?;
        let temp = folder(path).join(temp_name(file_name));
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temp)
            .map_err(io)?;
        Ok(AtomicFile {
            path: path.to_path_buf(),
            temp,
            file: Some(BufWriter::new(file)),
        })
    }

    /// The error of a failed write, naming the file it was to become.
    pub fn error(&self, source: std::io::Error) -> OutputError {
        OutputError::Io {
            path: self.path.clone(),
            source,
        }
    }

    /// Flushes, fsyncs and renames the file into place.
    pub fn commit(mut self) -> Result<(), OutputError> {
        let file = self.file.take().expect("committed once");
        let synced = file
            .into_inner()
            .map_err(|e| e.into_error())
            .and_then(|f| f.sync_all())
            .and_then(|()| fs::rename(&self.temp, &self.path));
        if let Err(source) = synced {
            // Best effort: the first error is the one to tell.
            let _ = fs::remove_file(&self.temp);
            return Err(self.error(source));
        }
        sync_dir(folder(&self.path)).map_err(|e| self.error(e))
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.file.as_mut().expect("not committed").write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.as_mut().expect("not committed").flush()
    }
}

impl Seek for AtomicFile {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.file.as_mut().expect("not committed").seek(pos)
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.file.take().is_some() {
            let _ = fs::remove_file(&self.temp);
        }
    }
}

/// The folder of `path` (`.` for a bare file name).
fn folder(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// `.name.tmp-<pid>-<n>`: hidden, unique within this process and across processes, so
/// that two writers of one path never share a temp file.
fn temp_name(file_name: &std::ffi::OsStr) -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let mut name = std::ffi::OsString::from(".");
    name.push(file_name);
    name.push(format!(".tmp-{}-{n}", std::process::id()));
    PathBuf::from(name)
}

/// Makes a rename inside `dir` durable. Only Unix can open and fsync a folder; elsewhere
/// the rename is atomic but its durability is up to the file system.
fn sync_dir(dir: &Path) -> std::io::Result<()> {
    if cfg!(unix) {
        File::open(dir)?.sync_all()
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn refuses_to_replace_what_is_not_a_regular_file() {
        let dir = std::env::temp_dir().join(format!("tessera-atomic-sock-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        // A socket stands in for a device such as /dev/null: not a file, yet renamable over.
        let path = dir.join("socket");
        let _listener = std::os::unix::net::UnixListener::bind(&path).unwrap();
        let err = write(&path, b"frame").unwrap_err().to_string();
        assert!(err.contains("not a regular file"), "{err}");
        assert!(
            !fs::metadata(&path).unwrap().is_file(),
            "the socket is still there"
        );
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn replaces_the_file_and_leaves_no_temp_file() {
        let dir = std::env::temp_dir().join(format!("tessera-atomic-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("frame.bin");
        write(&path, b"old").unwrap();
        write(&path, b"new").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"new");
        let names: Vec<_> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["frame.bin"]);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_missing_folder_is_an_error_naming_the_file() {
        let path = std::env::temp_dir().join("tessera-no-such-folder/x/frame.bin");
        let err = write(&path, b"x").unwrap_err();
        assert!(err.to_string().contains("frame.bin"), "{err}");
    }
}
