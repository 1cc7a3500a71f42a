//! Intel Open Image Denoise, loaded at run time.
//!
//! The library is found in a folder given by the caller (`--oidn DIR`), in the folder
//! `tessera install oidn` fills ([`install_dir`]), or on the system's library path, in that
//! order. Only the dozen C functions the RT filter needs are bound; their signatures are
//! those of OIDN 2's `oidn.h`.

use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::path::{Path, PathBuf};

use glam::{Vec3, Vec4};
use libloading::Library;

/// The OIDN release `tessera install oidn` installs and this binding was written against.
pub const OIDN_VERSION: &str = "2.5.1";

/// What a denoised layer's header names as its denoiser (`tessera/denoiser`).
pub const DENOISER_NAME: &str =
    "Open Image Denoise 2.5.1, RT filter, HDR, guided by albedo and normal";

/// The library's file name (its soname: any 2.x release has the functions used here).
pub const LIBRARY_FILE: &str = "libOpenImageDenoise.so.2";

/// Why OIDN could not be used.
#[derive(Debug, thiserror::Error)]
pub enum OidnError {
    /// No library was found where it was looked for.
    #[error(
        "Open Image Denoise is not installed (looked for {LIBRARY_FILE} in {}, and on the \
         system's library path): run `tessera install oidn`{}",
        looked.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "),
        reason.as_ref().map(|r| format!(" ({r})")).unwrap_or_default()
    )]
    NotInstalled {
        /// The folders looked in.
        looked: Vec<PathBuf>,
        /// What the loader said about the last file it found but could not load.
        reason: Option<String>,
    },
    /// The library loaded but lacks a function this binding calls.
    #[error("{}: not an Open Image Denoise 2 library: {source}", path.display())]
    Symbol {
        /// The library file.
        path: PathBuf,
        /// What the loader said.
        #[source]
        source: libloading::Error,
    },
    /// OIDN reported an error.
    #[error("Open Image Denoise: {what}: {message} (error {code})")]
    Library {
        /// What was being done.
        what: &'static str,
        /// OIDN's error code.
        code: c_int,
        /// OIDN's message.
        message: String,
    },
    /// The images handed to the filter do not agree in size.
    #[error("denoising a {width}x{height} image: {what} has {found} pixels")]
    Shape {
        /// Image width.
        width: usize,
        /// Image height.
        height: usize,
        /// Which image.
        what: &'static str,
        /// Its pixel count.
        found: usize,
    },
}

/// The folder `tessera install oidn` installs into: `$XDG_DATA_HOME/tessera/oidn-2.5.1`,
/// else `~/.local/share/tessera/oidn-2.5.1` (the libraries in its `lib/`).
pub fn install_dir() -> PathBuf {
    data_dir().join(format!("oidn-{OIDN_VERSION}"))
}

/// Where `tessera install` puts what it installs: `$XDG_DATA_HOME/tessera`, else
/// `~/.local/share/tessera`.
pub(crate) fn data_dir() -> PathBuf {
    std::env::var_os("XDG_DATA_HOME")
        .filter(|d| !d.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/share")))
        .unwrap_or_else(|| PathBuf::from("."))
        .join("tessera")
}

// OIDN's C enums, as `oidn.h` numbers them.
const DEVICE_TYPE_CPU: c_int = 1;
const FORMAT_FLOAT3: c_int = 3;
const ERROR_NONE: c_int = 0;

type Handle = *mut c_void;

/// The C functions used, copied out of the library (valid while `Oidn::_library` lives).
struct Api {
    new_device: unsafe extern "C" fn(c_int) -> Handle,
    set_device_int: unsafe extern "C" fn(Handle, *const c_char, c_int),
    commit_device: unsafe extern "C" fn(Handle),
    device_error: unsafe extern "C" fn(Handle, *mut *const c_char) -> c_int,
    release_device: unsafe extern "C" fn(Handle),
    new_filter: unsafe extern "C" fn(Handle, *const c_char) -> Handle,
    set_shared_image: unsafe extern "C" fn(
        Handle,
        *const c_char,
        *mut c_void,
        c_int,
        usize,
        usize,
        usize,
        usize,
        usize,
    ),
    set_filter_bool: unsafe extern "C" fn(Handle, *const c_char, bool),
    commit_filter: unsafe extern "C" fn(Handle),
    execute_filter: unsafe extern "C" fn(Handle),
    release_filter: unsafe extern "C" fn(Handle),
}

/// A loaded Open Image Denoise library.
pub struct Oidn {
    api: Api,
    path: PathBuf,
    // Declared last: dropped after nothing can call into it any more.
    _library: Library,
}

impl std::fmt::Debug for Oidn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Oidn").field("path", &self.path).finish()
    }
}

/// One image the RT filter reads or writes: `width * height` pixels of three `f32`s,
/// `stride` bytes apart.
struct Plane {
    data: *mut c_void,
    pixels: usize,
    stride: usize,
}

impl Plane {
    fn of_vec3(v: &[Vec3]) -> Plane {
        Plane {
            data: v.as_ptr() as *mut c_void,
            pixels: v.len(),
            stride: std::mem::size_of::<Vec3>(),
        }
    }

    /// The RGB of RGBA pixels: the alpha is skipped by the stride.
    fn of_vec4_rgb(v: &[Vec4]) -> Plane {
        Plane {
            data: v.as_ptr() as *mut c_void,
            pixels: v.len(),
            stride: std::mem::size_of::<Vec4>(),
        }
    }
}

/// The inputs of one denoising: the noisy beauty and its guides, one value per pixel in
/// rows of `width`.
#[derive(Clone, Copy, Debug)]
pub struct NoisyImage<'a> {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Linear HDR radiance (alpha ignored).
    pub beauty: &'a [Vec4],
    /// Albedo of the first non-specular hit, 0 to 1.
    pub albedo: &'a [Vec3],
    /// Shading normal, unit length or zero where nothing was hit.
    pub normal: &'a [Vec3],
}

impl Oidn {
    /// Loads the library: from `dir` when given (the folder itself or its `lib/`), else
    /// from [`install_dir`], else from the system's library path.
    pub fn load(dir: Option<&Path>) -> Result<Oidn, OidnError> {
        let folder = dir.map_or_else(install_dir, Path::to_path_buf);
        let mut looked = vec![folder.join("lib"), folder.clone()];
        let mut reason = None;
        for candidate in looked.iter().map(|d| d.join(LIBRARY_FILE)) {
            if candidate.is_file() {
                match Self::open(&candidate) {
                    Ok(oidn) => return Ok(oidn),
                    Err(OidnError::NotInstalled { reason: r, .. }) => reason = r,
                    Err(e) => return Err(e),
                }
            }
        }
        if dir.is_none() {
            // A distribution's package, found by the dynamic loader.
            if let Ok(oidn) = Self::open(Path::new(LIBRARY_FILE)) {
                return Ok(oidn);
            }
        }
        looked.dedup();
        Err(OidnError::NotInstalled { looked, reason })
    }

    fn open(path: &Path) -> Result<Oidn, OidnError> {
        // SAFETY: loading runs the library's initialisers; OIDN's only set up its device
        // registry.
        let library = unsafe { Library::new(path) }.map_err(|e| OidnError::NotInstalled {
            looked: Vec::new(),
            reason: Some(e.to_string()),
        })?;
        let symbol_error = |source| OidnError::Symbol {
            path: path.to_path_buf(),
            source,
        };
        macro_rules! bind {
            ($name:literal) => {
                // SAFETY: the type each field is declared with is the function's C
                // signature in OIDN 2's oidn.h.
                *unsafe { library.get(concat!($name, "\0").as_bytes()) }.map_err(symbol_error)?
            };
        }
        let api = Api {
            new_device: bind!("oidnNewDevice"),
            set_device_int: bind!("oidnSetDeviceInt"),
            commit_device: bind!("oidnCommitDevice"),
            device_error: bind!("oidnGetDeviceError"),
            release_device: bind!("oidnReleaseDevice"),
            new_filter: bind!("oidnNewFilter"),
            set_shared_image: bind!("oidnSetSharedFilterImage"),
            set_filter_bool: bind!("oidnSetFilterBool"),
            commit_filter: bind!("oidnCommitFilter"),
            execute_filter: bind!("oidnExecuteFilter"),
            release_filter: bind!("oidnReleaseFilter"),
        };
        Ok(Oidn {
            api,
            path: path.to_path_buf(),
            _library: library,
        })
    }

    /// The file the library was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Denoises `image` with the RT filter on the CPU with `threads` threads (0: all
    /// cores), guided by its albedo and normal as they are. The guides are noisy where a
    /// pixel's samples saw different surfaces (edges, motion blur); OIDN can denoise them
    /// first (`cleanAux`), but on the demo that took 6 times as long (2.3 s against 0.38 s
    /// at 640x360) for no better error (relative MSE against 4096 spp 1.11e-2 against
    /// 1.17e-2 at 4 spp, 5.2e-3 against 4.6e-3 at 16). Returns the denoised RGB.
    pub fn denoise(&self, image: &NoisyImage, threads: u32) -> Result<Vec<Vec3>, OidnError> {
        let (width, height) = (image.width, image.height);
        let pixels = width * height;
        for (what, found) in [
            ("the beauty", image.beauty.len()),
            ("the albedo", image.albedo.len()),
            ("the normal", image.normal.len()),
        ] {
            if found != pixels {
                return Err(OidnError::Shape {
                    width,
                    height,
                    what,
                    found,
                });
            }
        }
        let device = Device::new(self, threads)?;
        let mut out = vec![Vec3::ZERO; pixels];
        device.run(
            (width, height),
            &[
                ("color", Plane::of_vec4_rgb(image.beauty)),
                ("albedo", Plane::of_vec3(image.albedo)),
                ("normal", Plane::of_vec3(image.normal)),
            ],
            &mut out,
            &[("hdr", true)],
            "denoising the beauty",
        )?;
        Ok(out)
    }
}

/// An OIDN CPU device, released when dropped.
struct Device<'a> {
    oidn: &'a Oidn,
    handle: Handle,
}

impl<'a> Device<'a> {
    fn new(oidn: &'a Oidn, threads: u32) -> Result<Device<'a>, OidnError> {
        let api = &oidn.api;
        // SAFETY: OIDN's C API, called as oidn.h documents; the handle is released once.
        unsafe {
            let handle = (api.new_device)(DEVICE_TYPE_CPU);
            if handle.is_null() {
                return Err(error(api, std::ptr::null_mut(), "creating a CPU device"));
            }
            let device = Device { oidn, handle };
            if threads > 0 {
                let n = c_int::try_from(threads).unwrap_or(c_int::MAX);
                (api.set_device_int)(handle, c"numThreads".as_ptr(), n);
            }
            // A worker's render threads are not pinned; neither are the denoiser's.
            (api.set_device_int)(handle, c"setAffinity".as_ptr(), 0);
            (api.commit_device)(handle);
            device.check("creating a CPU device")?;
            Ok(device)
        }
    }

    fn check(&self, what: &'static str) -> Result<(), OidnError> {
        // SAFETY: the handle is this live device.
        match unsafe { error(&self.oidn.api, self.handle, what) } {
            OidnError::Library { code, .. } if code == ERROR_NONE => Ok(()),
            e => Err(e),
        }
    }

    /// Runs one RT filter over `inputs` into `output` (RGB, `width * height`).
    fn run(
        &self,
        (width, height): (usize, usize),
        inputs: &[(&str, Plane)],
        output: &mut [Vec3],
        flags: &[(&str, bool)],
        what: &'static str,
    ) -> Result<(), OidnError> {
        let api = &self.oidn.api;
        debug_assert!(inputs.iter().all(|(_, p)| p.pixels == width * height));
        // SAFETY: every image pointer is valid for `width * height` pixels of its stride
        // until the filter is released at the end of this call; OIDN writes only `output`.
        unsafe {
            let filter = (api.new_filter)(self.handle, c"RT".as_ptr());
            if filter.is_null() {
                return Err(error(api, self.handle, what));
            }
            let set = |name: &str, plane: &Plane| {
                let name = CString::new(name).expect("image names have no NUL");
                (api.set_shared_image)(
                    filter,
                    name.as_ptr(),
                    plane.data,
                    FORMAT_FLOAT3,
                    width,
                    height,
                    0,
                    plane.stride,
                    plane.stride * width,
                );
            };
            for (name, plane) in inputs {
                set(name, plane);
            }
            let out = Plane {
                data: output.as_mut_ptr() as *mut c_void,
                pixels: output.len(),
                stride: std::mem::size_of::<Vec3>(),
            };
            set("output", &out);
            for (name, value) in flags {
                let name = CString::new(*name).expect("flag names have no NUL");
                (api.set_filter_bool)(filter, name.as_ptr(), *value);
            }
            (api.commit_filter)(filter);
            (api.execute_filter)(filter);
            (api.release_filter)(filter);
        }
        self.check(what)
    }
}

impl Drop for Device<'_> {
    fn drop(&mut self) {
        // SAFETY: the handle came from oidnNewDevice and is released once.
        unsafe { (self.oidn.api.release_device)(self.handle) }
    }
}

/// The device's pending error (code 0 when there is none), as an [`OidnError`].
///
/// # Safety
/// `device` is null or a live device of `api`'s library.
unsafe fn error(api: &Api, device: Handle, what: &'static str) -> OidnError {
    let mut message: *const c_char = std::ptr::null();
    let code = (api.device_error)(device, &mut message);
    let message = if message.is_null() {
        String::new()
    } else {
        CStr::from_ptr(message).to_string_lossy().into_owned()
    };
    OidnError::Library {
        what,
        code,
        message,
    }
}
