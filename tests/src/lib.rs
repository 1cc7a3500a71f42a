//! A farm of real `tessera` processes on 127.0.0.1, for the end-to-end tests in
//! `tests/tests/`: a server, workers and the client commands, each its own process, as a
//! user runs them.
//!
//! The tests run the `tessera` binary that `cargo test --workspace` builds for the `cli`
//! package's own tests (`target/<profile>/tessera`, beside this test binary's `deps`
//! folder). Every process logs to a file in the farm's folder; a failed assertion prints
//! those logs. `http` speaks raw HTTP/1.1 for tests that act as a misbehaving worker.

pub mod http;

use std::fs;
use std::io::Write;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use proto::{FrameStatus, JobStatus, WorkerList};
use tracer::film::Layers;
use tracer::output::read_exr;

/// Small enough for CI's two cores: 32x24 pixels, tiles of 16 (four per frame), motion
/// blur on, so the moving demo objects take the motion path.
pub const SIZE: &str = "32x24";
/// The frames most jobs render.
pub const FRAMES: &str = "1-4";
const SHUTTER: &str = "-0.25,0.25";
const MAX_DEPTH: &str = "4";
const SEED: &str = "7";

/// The render settings both a farm job and `tessera render` get, at `spp` samples.
pub fn settings(spp: &str) -> Vec<&str> {
    vec![
        "--fps",
        "24",
        "--size",
        SIZE,
        "--spp",
        spp,
        "--shutter",
        SHUTTER,
        "--max-depth",
        MAX_DEPTH,
        "--seed",
        SEED,
    ]
}

/// `tessera render` of `frame` of `scene` with [`settings`], as the reference a farm's
/// frame must match.
pub fn render_directly(scene: &Path, frame: i32, spp: &str, dir: &Path) -> Layers {
    let out = dir.join(format!("direct_{frame}_{spp}.exr"));
    let frame = frame.to_string();
    let mut args = vec![
        "render",
        scene.to_str().unwrap(),
        "--frame",
        &frame,
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend(settings(spp));
    tessera_ok(&args, dir);
    read_exr(&out).unwrap().layers
}

/// The `tessera` binary next to this test executable.
pub fn tessera_bin() -> PathBuf {
    let exe = std::env::current_exe().expect("the test knows its own path");
    // target/<profile>/deps/<test> -> target/<profile>/tessera
    let bin = exe
        .parent()
        .and_then(Path::parent)
        .expect("the test binary lies in target/<profile>/deps")
        .join(format!("tessera{}", std::env::consts::EXE_SUFFIX));
    let built = fs::metadata(&bin).and_then(|m| m.modified());
    let Ok(built) = built else {
        panic!(
            "{} is missing: run the end-to-end tests with `cargo test --workspace` (which \
             builds the binary), or `cargo build -p cli` first",
            bin.display()
        );
    };
    // `cargo test -p tests` alone does not rebuild the binary: refuse to test an old one.
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    if let Some(newer) = newest_source(workspace).filter(|(t, _)| *t > built) {
        panic!(
            "{} is older than {}: run the end-to-end tests with `cargo test --workspace`, or \
             `cargo build -p cli` first",
            bin.display(),
            newer.1.display()
        );
    }
    bin
}

/// The most recently modified file the binary is built from, with its time.
fn newest_source(workspace: &Path) -> Option<(std::time::SystemTime, PathBuf)> {
    fn walk(path: &Path, newest: &mut Option<(std::time::SystemTime, PathBuf)>) {
        if let Ok(entries) = fs::read_dir(path) {
            for entry in entries.flatten() {
                walk(&entry.path(), newest);
            }
        } else if let Ok(t) = fs::metadata(path).and_then(|m| m.modified()) {
            if newest.as_ref().is_none_or(|(n, _)| t > *n) {
                *newest = Some((t, path.to_path_buf()));
            }
        }
    }
    let mut newest = None;
    for krate in ["cli", "server", "worker", "tracer", "proto"] {
        walk(&workspace.join(krate).join("src"), &mut newest);
        walk(&workspace.join(krate).join("Cargo.toml"), &mut newest);
    }
    walk(&workspace.join("server").join("assets"), &mut newest);
    newest
}

/// A loopback port nothing listens on right now, below the kernel's ephemeral range.
///
/// Tests leave the port unbound for a while: a worker started before its server, a server
/// killed and started again on the same port. A port the kernel hands out for `:0` could
/// meanwhile go to another test's server, which the worker would then talk to (CI saw
/// that once). Ports below the ephemeral range are only ever bound by name, and a counter
/// keeps this process's tests apart; the start depends on the process id, so test
/// binaries run one after another do not reuse each other's ports either.
pub fn free_port() -> u16 {
    static NEXT: AtomicU32 = AtomicU32::new(0);
    const FIRST: u32 = 10_000;
    let span = ephemeral_ports_start().saturating_sub(FIRST).max(1);
    let start = std::process::id().wrapping_mul(7919) % span;
    for _ in 0..span.min(1000) {
        let port = FIRST + (start + NEXT.fetch_add(1, Ordering::Relaxed)) % span;
        if TcpListener::bind(("127.0.0.1", port as u16)).is_ok() {
            return port as u16;
        }
    }
    panic!("no free loopback port between {FIRST} and {}", FIRST + span)
}

/// The first port the kernel hands out for `:0` (Linux's range, else its default).
fn ephemeral_ports_start() -> u32 {
    fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or(32768)
        .min(u32::from(u16::MAX))
}

/// A file of the test certificates (`tests/fixtures/tls/`).
pub fn tls_fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/tls")
        .join(name)
}

/// Runs `tessera args` in `dir` to completion.
pub fn tessera(args: &[&str], dir: &Path) -> Output {
    Command::new(tessera_bin())
        .args(args)
        .current_dir(dir)
        .output()
        .expect("tessera runs")
}

/// Runs `tessera args` in `dir` and panics with its output unless it succeeds; returns
/// its standard output.
pub fn tessera_ok(args: &[&str], dir: &Path) -> String {
    let o = tessera(args, dir);
    assert!(
        o.status.success(),
        "tessera {} failed ({}):\n{}\n{}",
        args.join(" "),
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A long-running `tessera` process (server or worker) whose output goes to a log file.
/// Dropping it kills it, so a failing test leaves no process behind.
pub struct Process {
    name: String,
    child: Child,
    log: PathBuf,
    status: Option<ExitStatus>,
}

impl Process {
    /// Starts `tessera args` in `dir`, logging to `dir/<name>.log`.
    pub fn start(name: &str, args: &[&str], dir: &Path) -> Process {
        let mut command = Command::new(tessera_bin());
        command.args(args);
        Process::spawn(name, command, dir)
    }

    /// Starts `command` (which must end up exec'ing `tessera`, so that the pid is the
    /// farm process's) in `dir`, logging to `dir/<name>.log`.
    pub fn spawn(name: &str, mut command: Command, dir: &Path) -> Process {
        let log = dir.join(format!("{name}.log"));
        let out = fs::File::create(&log).expect("creating a log file");
        let err = out.try_clone().unwrap();
        let child = command
            .current_dir(dir)
            .env("RUST_LOG", "info")
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(err)
            .spawn()
            .expect("starting tessera");
        Process {
            name: name.into(),
            child,
            log,
            status: None,
        }
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The most memory it has held so far (its peak resident set, `VmHWM`), bytes.
    pub fn peak_memory_bytes(&self) -> u64 {
        let status = fs::read_to_string(format!("/proc/{}/status", self.pid()))
            .expect("reading /proc/<pid>/status of a running process");
        let kib: u64 = status
            .lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            .expect("/proc/<pid>/status has VmHWM");
        kib << 10
    }

    /// What it has logged so far.
    pub fn log(&self) -> String {
        fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Whether it is still running.
    pub fn running(&mut self) -> bool {
        if self.status.is_none() {
            self.status = self.child.try_wait().expect("polling a child");
        }
        self.status.is_none()
    }

    /// Sends `signal` (a `libc::SIG*` number).
    pub fn signal(&self, signal: i32) {
        // SAFETY: kill(2) with the pid of our own child; no memory is involved.
        let rc = unsafe { libc::kill(self.child.id() as i32, signal) };
        assert_eq!(rc, 0, "signalling {}", self.name);
    }

    /// Sends SIGTERM and waits up to `timeout` for it to exit; returns how it exited.
    pub fn terminate(&mut self, timeout: Duration) -> ExitStatus {
        self.signal(libc::SIGTERM);
        self.wait(timeout)
    }

    /// Kills it with SIGKILL (`kill -9`): no chance to clean up.
    pub fn kill9(&mut self) {
        self.signal(libc::SIGKILL);
        self.wait(Duration::from_secs(10));
    }

    /// Waits up to `timeout` for it to exit.
    pub fn wait(&mut self, timeout: Duration) -> ExitStatus {
        let until = Instant::now() + timeout;
        while self.running() {
            assert!(
                Instant::now() < until,
                "{} did not exit within {timeout:?}; its log:\n{}",
                self.name,
                self.log()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        self.status.unwrap()
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        if self.running() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Polls `done` every 100 ms until it holds; panics after `timeout` naming `what`, with
/// `logs()` for context.
pub fn wait_until(
    what: &str,
    timeout: Duration,
    mut done: impl FnMut() -> bool,
    logs: impl Fn() -> String,
) {
    let until = Instant::now() + timeout;
    while !done() {
        assert!(
            Instant::now() < until,
            "timed out after {timeout:?} waiting for {what}\n{}",
            logs()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A farm on one loopback port with its folder: the server's data, the workers' caches,
/// the logs, scenes and downloaded frames all live under it.
pub struct Farm {
    /// The folder (removed when the farm is dropped).
    pub dir: tempfile::TempDir,
    /// The server's port.
    pub port: u16,
    /// The server process, while one runs.
    pub server: Option<Process>,
    /// Worker processes started so far.
    pub workers: Vec<Process>,
    /// The client token the farm's client commands send, when the server wants one.
    pub client_token: Option<String>,
    /// The CA that signed the server's certificate, when it serves HTTPS
    /// ([`Farm::start_tls_server`]): the URL is https:// and clients and workers get `--ca`.
    pub tls_ca: Option<PathBuf>,
    servers_started: usize,
    /// The server's data folder lies on a small disk of its own: see
    /// [`Farm::use_small_disk`].
    small_disk: Option<SmallDisk>,
}

/// A tmpfs over the farm's `data/` in a mount namespace of its own, held by a sleeping
/// process so that it outlives server restarts; servers enter it with `nsenter`.
struct SmallDisk {
    /// Holds the namespace; killed (and the tmpfs gone) when the farm is dropped.
    holder: Process,
    /// The namespaces a server enters (`nsenter` flags).
    enter: &'static [&'static str],
}

impl Default for Farm {
    fn default() -> Self {
        Self::new()
    }
}

impl Farm {
    /// A farm with nothing running yet.
    pub fn new() -> Farm {
        Farm {
            dir: tempfile::tempdir().expect("a temp folder"),
            port: free_port(),
            server: None,
            workers: vec![],
            client_token: None,
            tls_ca: None,
            servers_started: 0,
            small_disk: None,
        }
    }

    /// The farm's folder.
    pub fn path(&self) -> &Path {
        self.dir.path()
    }

    /// The server's base URL.
    pub fn url(&self) -> String {
        let scheme = if self.tls_ca.is_some() {
            "https"
        } else {
            "http"
        };
        format!("{scheme}://127.0.0.1:{}", self.port)
    }

    /// [`Farm::start_server_with`] serving HTTPS with the test certificate of
    /// `tests/fixtures/tls` (signed by its CA for 127.0.0.1 and localhost).
    pub fn start_tls_server(&mut self, lease_seconds: u64, extra: &[&str]) {
        let tls = tls_fixture("");
        let (cert, key) = (tls_fixture("server.pem"), tls_fixture("server.key"));
        assert!(
            tls.is_dir(),
            "{} holds the test certificates",
            tls.display()
        );
        self.tls_ca = Some(tls_fixture("ca.pem"));
        let mut args = vec![
            "--tls-cert",
            cert.to_str().expect("a UTF-8 path"),
            "--tls-key",
            key.to_str().expect("a UTF-8 path"),
        ];
        args.extend(extra);
        self.start_server_with(lease_seconds, &args);
    }

    /// Starts `tessera server` (data in `data/`, leases of `lease_seconds`) and waits until
    /// it answers.
    pub fn start_server(&mut self, lease_seconds: u64) {
        self.start_server_with(lease_seconds, &[]);
    }

    /// [`Farm::start_server`] with more flags (tokens, limits).
    pub fn start_server_with(&mut self, lease_seconds: u64, extra: &[&str]) {
        self.start_server_limited(lease_seconds, extra, None);
    }

    /// [`Farm::start_server_with`], the server's data segment limited to `memory_bytes`
    /// when given (`RLIMIT_DATA`: its heap and private writable mappings; an allocation
    /// past it fails, and Rust aborts the process on it).
    pub fn start_server_limited(
        &mut self,
        lease_seconds: u64,
        extra: &[&str],
        memory_bytes: Option<u64>,
    ) {
        self.servers_started += 1;
        let listen = format!("127.0.0.1:{}", self.port);
        let lease = lease_seconds.to_string();
        let name = format!("server-{}", self.servers_started);
        // Absolute: a server in the small disk's namespace must find the tmpfs.
        let data = self.path().join("data");
        let data = data.to_str().expect("a UTF-8 temp path");
        let mut args = vec![
            "server",
            "--listen",
            &listen,
            "--data",
            data,
            "--lease-seconds",
            &lease,
        ];
        args.extend(extra);
        let mut command = match &self.small_disk {
            Some(disk) => {
                let mut c = Command::new("nsenter");
                c.args(["--target", &disk.holder.pid().to_string()])
                    .args(disk.enter)
                    .arg("--")
                    .arg(tessera_bin());
                c
            }
            None => Command::new(tessera_bin()),
        };
        command.args(&args);
        if let Some(limit) = memory_bytes {
            use std::os::unix::process::CommandExt;
            let rlimit = libc::rlimit {
                rlim_cur: limit,
                rlim_max: limit,
            };
            // SAFETY: setrlimit(2) is async-signal-safe and touches only the child.
            unsafe {
                command.pre_exec(move || {
                    if libc::setrlimit(libc::RLIMIT_DATA, &rlimit) == 0 {
                        Ok(())
                    } else {
                        Err(std::io::Error::last_os_error())
                    }
                });
            }
        }
        self.server = Some(Process::spawn(&name, command, self.path()));
        self.wait_for_server();
    }

    fn wait_for_server(&mut self) {
        let status = self.client_args(&["status"]);
        let status: Vec<&str> = status.iter().map(String::as_str).collect();
        let dir = self.dir.path().to_owned();
        let logs = self.logs_fn();
        let server = self.server.as_mut().expect("a server was started");
        wait_until(
            "the server to answer",
            Duration::from_secs(30),
            || {
                assert!(server.running(), "the server exited:\n{}", logs());
                tessera(&status, &dir).status.success()
            },
            &logs,
        );
    }

    /// Puts the server's data folder on a tmpfs of `size_bytes` that only the farm's
    /// servers see (a mount namespace of their own, through `unshare`, held by a sleeping
    /// process so that the disk outlives server restarts), so a test can fill it; call it
    /// before the first server starts. The test reaches the folder at [`Farm::data_dir`].
    /// `Err` says why this machine cannot arrange it (no `unshare` or `nsenter`,
    /// namespaces or mounts not permitted): the caller skips, saying so.
    pub fn use_small_disk(&mut self, size_bytes: u64) -> Result<(), String> {
        assert!(
            self.server.is_none(),
            "a small disk is set up before the server"
        );
        let data = self.path().join("data");
        fs::create_dir_all(&data).expect("creating the data mount point");
        let data = data.to_str().expect("a UTF-8 temp path").to_owned();
        let size = size_bytes.to_string();
        // A user namespace lets a non-root user mount a tmpfs; as root it may be refused
        // (seccomp in some containers) where a plain mount namespace works.
        let mut refusals = Vec::new();
        let ways: [(&[&str], &'static [&'static str]); 2] = [
            (
                &["--user", "--map-root-user", "--mount"],
                &["--user", "--mount"],
            ),
            (&["--mount"], &["--mount"]),
        ];
        for (flags, enter) in ways {
            let mut command = Command::new("unshare");
            command.args(flags).args([
                "sh",
                "-c",
                MOUNT_TMPFS,
                "sh",
                &size,
                &data,
                "sleep",
                "1000000",
            ]);
            let mut holder = Process::spawn("small-disk", command, self.path());
            let pid = holder.pid();
            let mounted = || {
                fs::read_to_string(format!("/proc/{pid}/mounts"))
                    .is_ok_and(|m| m.contains("tessera-data"))
            };
            let until = Instant::now() + Duration::from_secs(10);
            while holder.running() && !mounted() && Instant::now() < until {
                std::thread::sleep(Duration::from_millis(20));
            }
            let probe = Command::new("nsenter")
                .args(["--target", &pid.to_string()])
                .args(enter)
                .args(["--", "true"])
                .output();
            match probe {
                Ok(o) if mounted() && o.status.success() => {
                    self.small_disk = Some(SmallDisk { holder, enter });
                    return Ok(());
                }
                Ok(o) => refusals.push(format!(
                    "`unshare {} sh -c 'mount -t tmpfs ...'` then `nsenter {}`: {}{}",
                    flags.join(" "),
                    enter.join(" "),
                    holder.log().trim(),
                    String::from_utf8_lossy(&o.stderr).trim()
                )),
                Err(e) => {
                    refusals.push(format!("running `nsenter`: {e}"));
                    break;
                }
            }
        }
        Err(refusals.join("; "))
    }

    /// The server's data folder as this process sees it: `data/` in the farm's folder,
    /// or, on a small disk, the same path inside its mount namespace (through
    /// `/proc/<pid>/root` of the process holding it).
    pub fn data_dir(&self) -> PathBuf {
        let data = self.path().join("data");
        match &self.small_disk {
            Some(disk) => {
                let inside = data.strip_prefix("/").expect("an absolute temp path");
                Path::new(&format!("/proc/{}/root", disk.holder.pid())).join(inside)
            }
            None => data,
        }
    }

    /// Fills the server's disk with the file `name` in its data folder until the disk
    /// says it is full; returns how many bytes went in. Removing the file frees the space.
    pub fn fill_disk(&self, name: &str) -> u64 {
        let path = self.data_dir().join(name);
        let mut f = fs::File::create(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let block = vec![0xa5u8; 64 << 10];
        let mut written = 0;
        loop {
            match f.write(&block) {
                Ok(n) => written += n as u64,
                Err(e) if e.kind() == std::io::ErrorKind::StorageFull => return written,
                Err(e) => panic!("filling {}: {e}", path.display()),
            }
        }
    }

    /// `args` with `--server` and, when set, `--token` and `--ca`.
    fn client_args(&self, args: &[&str]) -> Vec<String> {
        let mut all: Vec<String> = args.iter().map(|a| a.to_string()).collect();
        all.extend(["--server".into(), self.url()]);
        if let Some(ca) = &self.tls_ca {
            all.extend(["--ca".into(), ca.display().to_string()]);
        }
        if let Some(t) = &self.client_token {
            all.extend(["--token".into(), t.clone()]);
        }
        all
    }

    /// Starts `tessera worker` named `name` with `threads` render threads; returns its
    /// index in [`Farm::workers`].
    pub fn start_worker(&mut self, name: &str, threads: u32) -> usize {
        self.start_worker_with(name, threads, &[])
    }

    /// [`Farm::start_worker`] with more flags (`--inject-fault ...`).
    pub fn start_worker_with(&mut self, name: &str, threads: u32, extra: &[&str]) -> usize {
        let url = self.url();
        let threads = threads.to_string();
        let cache = format!("cache-{name}");
        let ca = self.tls_ca.as_ref().map(|ca| ca.display().to_string());
        let mut args = vec![
            "worker",
            "--server",
            &url,
            "--threads",
            &threads,
            "--cache",
            &cache,
            "--name",
            name,
        ];
        if let Some(ca) = &ca {
            args.extend(["--ca", ca]);
        }
        args.extend(extra);
        let worker = Process::start(name, &args, self.path());
        self.workers.push(worker);
        self.workers.len() - 1
    }

    /// Runs a client command against this farm's server (`--server` and the client token
    /// added).
    pub fn client(&self, args: &[&str]) -> String {
        let all = self.client_args(args);
        let all: Vec<&str> = all.iter().map(String::as_str).collect();
        let o = tessera(&all, self.path());
        assert!(
            o.status.success(),
            "tessera {} failed ({}):\n{}\n{}\n{}",
            all.join(" "),
            o.status,
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr),
            self.logs()
        );
        String::from_utf8_lossy(&o.stdout).into_owned()
    }

    /// `tessera submit args...` (with `--server`); returns the job id it prints.
    pub fn submit(&self, args: &[&str]) -> u64 {
        let mut all = vec!["submit"];
        all.extend(args);
        let out = self.client(&all);
        job_id_in(&out).unwrap_or_else(|| panic!("no job id in the output of submit:\n{out}"))
    }

    /// The job's status, through `tessera status JOB --json`.
    pub fn job(&self, id: u64) -> JobStatus {
        self.job_and_frames(id).0
    }

    /// The job's status and its frames, through `tessera status JOB --json`
    /// (`{"job": ..., "frames": ...}`).
    pub fn job_and_frames(&self, id: u64) -> (JobStatus, Vec<FrameStatus>) {
        #[derive(serde::Deserialize)]
        struct Detail {
            job: JobStatus,
            frames: Vec<FrameStatus>,
        }
        let id = id.to_string();
        let out = self.client(&["status", &id, "--json"]);
        let detail: Detail =
            serde_json::from_str(&out).unwrap_or_else(|e| panic!("status --json: {e}:\n{out}"));
        (detail.job, detail.frames)
    }

    /// The workers, through `tessera workers --json`.
    pub fn worker_list(&self) -> WorkerList {
        let out = self.client(&["workers", "--json"]);
        serde_json::from_str(&out).unwrap_or_else(|e| panic!("workers --json: {e}:\n{out}"))
    }

    /// Waits until job `id` has ended (done, failed or cancelled); returns its status.
    pub fn wait_for_job(&self, id: u64, timeout: Duration) -> JobStatus {
        let mut last = None;
        wait_until(
            &format!("job {id} to end"),
            timeout,
            || {
                let st = self.job(id);
                let ended = st.finished_ms.is_some();
                last = Some(st);
                ended
            },
            || self.logs(),
        );
        last.unwrap()
    }

    /// Every log of the farm's processes, for failure messages.
    pub fn logs(&self) -> String {
        farm_logs(self.path())
    }

    /// [`Farm::logs`] as a closure that does not borrow the farm.
    fn logs_fn(&self) -> impl Fn() -> String {
        let dir = self.path().to_owned();
        move || farm_logs(&dir)
    }

    /// The frame the server assembled for `job`, read from its data folder.
    pub fn server_frame(&self, job: u64, frame: i32) -> Layers {
        let frames = self
            .job(job)
            .spec
            .frames
            .expect("a planned job names its frames");
        let path = self
            .data_dir()
            .join("jobs")
            .join(job.to_string())
            .join(frames.file_name(frame, "exr"));
        read_exr(&path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            .layers
    }

    /// Writes the built-in animated demo scene as `demo.glb` in the farm's folder.
    pub fn demo_scene(&self) -> PathBuf {
        let glb = tracer::export::scene_to_glb(&tracer::demo::animated_demo_scene())
            .expect("the demo scene exports");
        let path = self.path().join("demo.glb");
        fs::write(&path, glb).unwrap();
        path
    }
}

/// The last 40 lines of every `*.log` in `dir` (a farm's folder).
fn farm_logs(dir: &Path) -> String {
    let mut out = String::new();
    let mut entries: Vec<_> = fs::read_dir(dir)
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    entries.sort();
    for path in entries {
        if path.extension().is_some_and(|e| e == "log") {
            let text = fs::read_to_string(&path).unwrap_or_default();
            let tail: Vec<&str> = text.lines().rev().take(40).collect();
            out += &format!("--- {} (last 40 lines)\n", path.display());
            for line in tail.into_iter().rev() {
                out += line;
                out.push('\n');
            }
        }
    }
    out
}

/// The shell step that mounts a tmpfs of size `$1` on `$2`, then execs the rest
/// (`unshare` itself execs without forking, so the pid stays the farm process's).
const MOUNT_TMPFS: &str =
    r#"mount -t tmpfs -o size="$1" tessera-data "$2" && shift 2 && exec "$@""#;

/// The first number after the word "job" in `text` (how `tessera submit` names the job).
pub fn job_id_in(text: &str) -> Option<u64> {
    text.split("job").skip(1).find_map(|rest| {
        let digits: String = rest
            .trim_start_matches([' ', '#', ':'])
            .chars()
            .take_while(char::is_ascii_digit)
            .collect();
        digits.parse().ok()
    })
}

#[cfg(test)]
mod tests {
    use super::job_id_in;

    #[test]
    fn finds_the_job_id() {
        assert_eq!(job_id_in("submitted job 12 (3 frames)"), Some(12));
        assert_eq!(job_id_in("scene abc\njob #7 queued"), Some(7));
        assert_eq!(job_id_in("no id here"), None);
    }
}
