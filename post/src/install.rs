//! Installing the optional native parts from the Python package index's wheels, so that no
//! download from outside the registries and no root is needed: a wheel is a zip archive,
//! pinned here by URL and SHA-256, and only the files Tessera uses are unpacked.

use std::io::Read;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use crate::{oidn, video};

/// A pinned wheel and the files taken from it.
#[derive(Clone, Copy, Debug)]
pub struct Package {
    /// What it is, for messages (`Open Image Denoise 2.5.1`).
    pub name: &'static str,
    /// Where to download it.
    pub url: &'static str,
    /// The lower-case hex SHA-256 the download must have.
    pub sha256: &'static str,
    /// Paths inside the archive, each with where it is unpacked to inside the install
    /// folder.
    pub files: &'static [(&'static str, &'static str)],
    /// The install folder the programs look in when not told another.
    pub default_dir: fn() -> PathBuf,
}

/// Open Image Denoise 2.5.1 for x86-64 Linux: the `pyoidn` 2.5.1 wheel ships the library,
/// its core, its CPU device and the TBB it runs on (their run paths point at each other
/// in one `lib/` folder).
pub const OIDN: Package = Package {
    name: "Open Image Denoise 2.5.1",
    url: "https://files.pythonhosted.org/packages/80/f7/40c72360d5ee831ad1048427202b4c7bca41b28c7caffea0df4d2dc8158e/pyoidn-2.5.1.0-py3-none-manylinux2014_x86_64.whl",
    sha256: "32ad13368f8de1ef63001942ad05b02a00cd732d1206d97f352d3a3f606d823e",
    files: &[
        (
            "pyoidn/oidn/lib/libOpenImageDenoise.so.2",
            "lib/libOpenImageDenoise.so.2",
        ),
        (
            "pyoidn/oidn/lib/libOpenImageDenoise_core.so.2.5.1",
            "lib/libOpenImageDenoise_core.so.2.5.1",
        ),
        (
            "pyoidn/oidn/lib/libOpenImageDenoise_device_cpu.so.2.5.1",
            "lib/libOpenImageDenoise_device_cpu.so.2.5.1",
        ),
        ("pyoidn/oidn/lib/libtbb.so.12", "lib/libtbb.so.12"),
    ],
    default_dir: oidn::install_dir,
};

/// FFmpeg 9.0.2 for x86-64 Linux, a static build with libx264: the `imageio-ffmpeg`
/// 0.8.1 wheel ships it as one executable.
pub const FFMPEG: Package = Package {
    name: "FFmpeg 9.0.2",
    url: "https://files.pythonhosted.org/packages/de/0f/49292fbef69ee10ebcf97bb741602521caafcc6966d5fa1a2b868cc15655/imageio_ffmpeg-0.8.1-py3-none-manylinux_2_28_x86_64.whl",
    sha256: "050d6850601c3b3890bd2b28306f3b842b3daea390a561101174375a1c460bda",
    files: &[(
        "imageio_ffmpeg/binaries/ffmpeg-linux-x86_64-v9.0.2",
        "bin/ffmpeg",
    )],
    default_dir: video::install_dir,
};

/// Why a package could not be installed.
#[derive(Debug, thiserror::Error)]
pub enum InstallError {
    /// The download is not the pinned file.
    #[error("{name}: the download's SHA-256 is {found}, not the pinned {expected}: refusing it")]
    Digest {
        /// The package.
        name: &'static str,
        /// The pinned digest.
        expected: &'static str,
        /// The download's digest.
        found: String,
    },
    /// The archive is not a readable zip, or lacks a file.
    #[error("{name}: {detail}")]
    Archive {
        /// The package.
        name: &'static str,
        /// What is wrong.
        detail: String,
    },
    /// Writing the files failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
}

/// Lower-case hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Checks `wheel` against `package`'s digest and unpacks its files into `dest`,
/// replacing what `dest` held: they are written into a folder beside it first, so a
/// failure half way leaves the old install (or none) in place. Returns the files written.
pub fn install(package: &Package, wheel: &[u8], dest: &Path) -> Result<Vec<PathBuf>, InstallError> {
    let found = sha256_hex(wheel);
    if found != package.sha256 {
        return Err(InstallError::Digest {
            name: package.name,
            expected: package.sha256,
            found,
        });
    }
    let mut archive =
        zip::ZipArchive::new(std::io::Cursor::new(wheel)).map_err(|e| InstallError::Archive {
            name: package.name,
            detail: format!("not a readable wheel: {e}"),
        })?;

    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| InstallError::Io { path, source }
    };
    let parent = dest.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(io(parent))?;
    let staging = parent.join(format!(
        ".{}.partial-{}",
        dest.file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("install"),
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&staging);
    let unpacked = unpack(package, &mut archive, &staging);
    if unpacked.is_err() {
        let _ = std::fs::remove_dir_all(&staging);
    }
    unpacked?;
    if dest.exists() {
        std::fs::remove_dir_all(dest).map_err(io(dest))?;
    }
    std::fs::rename(&staging, dest).map_err(io(dest))?;
    Ok(package.files.iter().map(|(_, to)| dest.join(to)).collect())
}

/// Unpacks `package`'s files from `archive` into `folder`.
fn unpack(
    package: &Package,
    archive: &mut zip::ZipArchive<std::io::Cursor<&[u8]>>,
    folder: &Path,
) -> Result<(), InstallError> {
    let archive_error = |detail: String| InstallError::Archive {
        name: package.name,
        detail,
    };
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| InstallError::Io { path, source }
    };
    for &(member, to) in package.files {
        let mut entry = archive
            .by_name(member)
            .map_err(|e| archive_error(format!("`{member}`: {e}")))?;
        let mut bytes = Vec::with_capacity(entry.size() as usize);
        entry
            .read_to_end(&mut bytes)
            .map_err(|e| archive_error(format!("`{member}`: {e}")))?;
        let path = folder.join(to);
        let parent = path.parent().unwrap_or(folder);
        std::fs::create_dir_all(parent).map_err(io(parent))?;
        std::fs::write(&path, &bytes).map_err(io(&path))?;
        executable(&path).map_err(io(&path))?;
    }
    Ok(())
}

#[cfg(unix)]
fn executable(path: &Path) -> std::io::Result<()> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755))
}

#[cfg(not(unix))]
fn executable(_: &Path) -> std::io::Result<()> {
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn wheel(files: &[(&str, &[u8])]) -> Vec<u8> {
        let mut out = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        for (name, bytes) in files {
            out.start_file(*name, zip::write::SimpleFileOptions::default())
                .unwrap();
            out.write_all(bytes).unwrap();
        }
        out.finish().unwrap().into_inner()
    }

    #[test]
    fn a_wheel_with_another_digest_is_refused_and_changes_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("oidn");
        let err = install(&OIDN, b"not the wheel", &dest).unwrap_err();
        assert!(matches!(err, InstallError::Digest { .. }), "{err}");
        assert!(err.to_string().contains(OIDN.sha256), "{err}");
        assert!(!dest.exists());
    }

    #[test]
    fn the_pinned_files_are_unpacked_into_lib_and_replace_the_old_install() {
        let bytes = wheel(&[
            ("a/lib/libx.so.1", b"x one"),
            ("a/lib/liby.so", b"y"),
            ("a/other.py", b"left out"),
        ]);
        let digest: &'static str = Box::leak(sha256_hex(&bytes).into_boxed_str());
        let package = Package {
            name: "test package",
            url: "",
            sha256: digest,
            files: &[
                ("a/lib/libx.so.1", "lib/libx.so.1"),
                ("a/lib/liby.so", "bin/y"),
            ],
            default_dir: PathBuf::new,
        };
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("pkg");
        std::fs::create_dir_all(dest.join("lib")).unwrap();
        std::fs::write(dest.join("lib/stale.so"), b"old").unwrap();

        let written = install(&package, &bytes, &dest).unwrap();
        assert_eq!(
            written,
            vec![dest.join("lib/libx.so.1"), dest.join("bin/y")]
        );
        assert_eq!(std::fs::read(dest.join("lib/libx.so.1")).unwrap(), b"x one");
        assert!(!dest.join("lib/stale.so").exists());
        assert!(!dest.join("lib/other.py").exists());
        let leftovers: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(leftovers, vec![std::ffi::OsString::from("pkg")]);
    }

    #[test]
    fn a_wheel_missing_a_file_names_it() {
        let bytes = wheel(&[("a/lib/libx.so.1", b"x")]);
        let digest: &'static str = Box::leak(sha256_hex(&bytes).into_boxed_str());
        let package = Package {
            name: "test package",
            url: "",
            sha256: digest,
            files: &[
                ("a/lib/libx.so.1", "lib/libx.so.1"),
                ("a/lib/missing.so", "lib/missing.so"),
            ],
            default_dir: PathBuf::new,
        };
        let dir = tempfile::tempdir().unwrap();
        let err = install(&package, &bytes, &dir.path().join("pkg")).unwrap_err();
        assert!(err.to_string().contains("a/lib/missing.so"), "{err}");
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            0,
            "nothing is left"
        );
    }
}
