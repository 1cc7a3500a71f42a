//! What a worker needs to know: where the server is, how to prove who it is, how many
//! threads to render with, where to cache scenes, what to be called, and how to compress
//! the tiles it uploads.

use std::net::IpAddr;
use std::path::PathBuf;
use std::time::Duration;

use serde::Serialize;
use tracer::output::ExrCompression;

/// Settings of one worker daemon.
#[derive(Clone, Debug)]
pub struct WorkerConfig {
    /// The server's base URL, like `http://127.0.0.1:8700` (the `/api/v1` prefix is
    /// added; a URL that already ends in it is used as it is).
    pub server: String,
    /// Bearer token for the worker routes, when the server requires one.
    pub token: Option<String>,
    /// A PEM file of certificate authorities trusted besides the public ones: the private
    /// CA that signed an https:// server's certificate.
    pub ca: Option<PathBuf>,
    /// Render threads (the rayon pool's size); at least 1.
    pub threads: usize,
    /// Folder for downloaded scenes (`<digest>.glb`), created when missing.
    pub cache_dir: PathBuf,
    /// Most bytes of scenes the folder keeps: the least recently used go first.
    pub cache_limit_bytes: u64,
    /// A name for people: shown in `GET /workers` and the dashboard.
    pub name: String,
    /// What this machine offers (`gpu`, `studio-a`): it takes only the jobs whose every
    /// required tag it has.
    pub tags: Vec<String>,
    /// How uploaded tiles are compressed.
    pub upload_compression: UploadCompression,
    /// Whether to take denoise tasks when Open Image Denoise is found.
    pub denoise: bool,
    /// Where Open Image Denoise is installed (`None`: where `tessera install oidn` puts
    /// it, then the system's library path).
    pub oidn: Option<PathBuf>,
    /// Whether to take encode tasks when FFmpeg is found.
    pub encode: bool,
    /// The FFmpeg program, or the folder it is installed in (`None`: where `tessera
    /// install ffmpeg` puts it, then `ffmpeg` on the PATH).
    pub ffmpeg: Option<PathBuf>,
    /// A fault to inject, for testing how the farm copes with a bad worker; `None` for
    /// every real worker.
    pub fault: Option<Fault>,
    /// When it leaves by itself (a pilot job): after so long idle, after so many tasks.
    pub pilot: PilotLimits,
}

/// When a worker leaves by itself; both off by default (a long-running daemon).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PilotLimits {
    /// Leave after this long without a task.
    pub exit_when_idle: Option<Duration>,
    /// Leave once this many tasks were worked on (done, failed or taken back).
    pub max_tasks: Option<u64>,
}

/// How a worker compresses the tiles it uploads (`tessera worker --upload-compression`).
/// The server reads either; a tile's pixels are the same bits both ways.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum UploadCompression {
    /// None for a server on this machine (a loopback address), where bytes cost nothing
    /// and ZIP's time would come out of rendering; ZIP for any other.
    #[default]
    Auto,
    /// ZIP: a rendered tile in about a third of its bytes, for about 25 ms of one core per
    /// 128x128 tile (the render threads' core, unless the machine has one to spare).
    Zip,
    /// The raw values: about 2 ms per 128x128 tile, 850 KB.
    #[serde(rename = "none")]
    Uncompressed,
}

impl UploadCompression {
    /// The compression used for uploads to `server` (a base URL).
    pub fn for_server(self, server: &str) -> ExrCompression {
        match self {
            UploadCompression::Zip => ExrCompression::Zip,
            UploadCompression::Uncompressed => ExrCompression::Uncompressed,
            UploadCompression::Auto if is_loopback(server) => ExrCompression::Uncompressed,
            UploadCompression::Auto => ExrCompression::Zip,
        }
    }
}

impl std::str::FromStr for UploadCompression {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(UploadCompression::Auto),
            "zip" => Ok(UploadCompression::Zip),
            "none" => Ok(UploadCompression::Uncompressed),
            _ => Err(format!(
                "unknown upload compression `{s}` (known: auto, zip, none)"
            )),
        }
    }
}

/// Whether the URL's host is this machine: `localhost`, 127.0.0.0/8 or `[::1]`.
fn is_loopback(url: &str) -> bool {
    let Ok(url) = reqwest::Url::parse(url) else {
        return false;
    };
    // An IPv6 host comes in brackets, which `IpAddr` does not take.
    let host = url.host_str().unwrap_or_default();
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host.eq_ignore_ascii_case("localhost") || host.parse().is_ok_and(|ip: IpAddr| ip.is_loopback())
}

/// A fault a worker can be told to inject (`tessera worker --inject-fault`, hidden from
/// its help): the farm's defences are tested against real processes that misbehave.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// Report every task of this job as failed, without rendering it.
    FailJob(u64),
    /// Render every tile, then change one pixel a little before sending it: a machine
    /// with bad memory or a broken build, which only a second render can catch.
    Perturb,
}

impl std::str::FromStr for Fault {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.split_once('=') {
            Some(("fail-job", job)) => job
                .parse()
                .map(Fault::FailJob)
                .map_err(|_| format!("fail-job takes a job id, not `{job}`")),
            None if s == "perturb" => Ok(Fault::Perturb),
            _ => Err(format!(
                "unknown fault `{s}` (known: fail-job=JOB, perturb)"
            )),
        }
    }
}

impl WorkerConfig {
    /// The API root: `server` without a trailing slash, plus [`proto::API_PREFIX`].
    pub fn api_base(&self) -> String {
        let base = self.server.trim_end_matches('/');
        if base.ends_with(proto::API_PREFIX) {
            base.to_string()
        } else {
            format!("{base}{}", proto::API_PREFIX)
        }
    }
}

/// This machine and build, as a worker reports them when it registers: architecture and
/// OS, CPU model and the vector features that could matter to floating point, Tessera's
/// version and build profile. E.g. `x86_64 linux, AMD EPYC 7B13 (avx2 fma), tessera 0.1.0
/// release`.
pub fn platform() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|info| {
            info.lines()
                .find(|l| l.starts_with("model name") || l.starts_with("Model"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.split_whitespace().collect::<Vec<_>>().join(" "))
        })
        .unwrap_or_else(|| "unknown CPU".into());
    #[allow(unused_mut)]
    let mut features: Vec<&str> = Vec::new();
    #[cfg(target_arch = "x86_64")]
    {
        for (name, has) in [
            ("avx2", std::arch::is_x86_feature_detected!("avx2")),
            ("fma", std::arch::is_x86_feature_detected!("fma")),
            ("avx512f", std::arch::is_x86_feature_detected!("avx512f")),
        ] {
            if has {
                features.push(name);
            }
        }
    }
    let features = if features.is_empty() {
        String::new()
    } else {
        format!(" ({})", features.join(" "))
    };
    let profile = if cfg!(debug_assertions) {
        "debug"
    } else {
        "release"
    };
    format!(
        "{} {}, {cpu}{features}, tessera {} {profile}",
        std::env::consts::ARCH,
        std::env::consts::OS,
        env!("CARGO_PKG_VERSION")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(server: &str) -> WorkerConfig {
        WorkerConfig {
            server: server.into(),
            token: None,
            ca: None,
            threads: 1,
            cache_dir: PathBuf::from("cache"),
            cache_limit_bytes: u64::MAX,
            name: "w".into(),
            tags: vec![],
            upload_compression: UploadCompression::Auto,
            denoise: true,
            oidn: None,
            encode: true,
            ffmpeg: None,
            fault: None,
            pilot: Default::default(),
        }
    }

    #[test]
    fn faults_parse_or_say_what_is_known() {
        assert_eq!("fail-job=7".parse(), Ok(Fault::FailJob(7)));
        assert_eq!("perturb".parse(), Ok(Fault::Perturb));
        assert!("fail-job=x"
            .parse::<Fault>()
            .unwrap_err()
            .contains("job id"));
        assert!("melt".parse::<Fault>().unwrap_err().contains("fail-job"));
    }

    #[test]
    fn auto_compression_skips_zip_only_for_this_machine() {
        let auto = |url: &str| UploadCompression::Auto.for_server(url);
        for local in [
            "http://127.0.0.1:8700",
            "http://127.8.0.3",
            "http://localhost:8700/api/v1",
            "http://LocalHost",
            "http://[::1]:8700",
        ] {
            assert_eq!(auto(local), ExrCompression::Uncompressed, "{local}");
        }
        for remote in [
            "http://192.168.1.20:8700",
            "https://farm.example.org",
            "http://[2001:db8::1]:8700",
            "http://localhost.example.org",
            "not a url",
        ] {
            assert_eq!(auto(remote), ExrCompression::Zip, "{remote}");
        }
        let local = "http://127.0.0.1:8700";
        assert_eq!(
            UploadCompression::Zip.for_server(local),
            ExrCompression::Zip
        );
        assert_eq!(
            UploadCompression::Uncompressed.for_server("https://farm.example.org"),
            ExrCompression::Uncompressed
        );
        assert_eq!("none".parse(), Ok(UploadCompression::Uncompressed));
        assert_eq!("zip".parse(), Ok(UploadCompression::Zip));
        assert!("lz4"
            .parse::<UploadCompression>()
            .unwrap_err()
            .contains("auto, zip, none"));
    }

    #[test]
    fn api_base_adds_the_prefix_once() {
        assert_eq!(config("http://h:8700").api_base(), "http://h:8700/api/v1");
        assert_eq!(config("http://h:8700/").api_base(), "http://h:8700/api/v1");
        assert_eq!(
            config("http://h:8700/api/v1/").api_base(),
            "http://h:8700/api/v1"
        );
    }
}
