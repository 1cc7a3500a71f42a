//! A one-node Slurm cluster on this machine, for the provisioner's tests: MUNGE,
//! slurmctld and slurmd in the foreground, with a key, a socket, ports and a
//! configuration of their own in the farm's folder, so that nothing of the machine's own
//! Slurm (if it has one) is touched. Every client command gets `SLURM_CONF`. Dropping the
//! cluster cancels its jobs and stops the daemons it started, by PID.

use std::fs;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use tests::{free_port, wait_until, Farm, Process};

/// The programs the cluster needs (Debian's slurm-wlm and munge).
const PROGRAMS: [&str; 7] = [
    "munged",
    "slurmctld",
    "slurmd",
    "sbatch",
    "squeue",
    "scancel",
    "sinfo",
];

pub struct Cluster {
    /// `slurm.conf`, for `SLURM_CONF`.
    pub conf: PathBuf,
    /// The daemons, started in this order: munged, slurmctld, slurmd.
    daemons: Vec<Process>,
}

impl Cluster {
    /// Why no cluster can run here, if it cannot: a program missing or not root (slurmd
    /// starts jobs as their users).
    pub fn unavailable() -> Option<String> {
        let missing: Vec<&str> = PROGRAMS.into_iter().filter(|p| find(p).is_none()).collect();
        if !missing.is_empty() {
            return Some(format!(
                "{} not installed (scripts/install-slurm.sh installs Slurm and MUNGE)",
                missing.join(", ")
            ));
        }
        // SAFETY: getuid has no preconditions.
        if unsafe { libc::getuid() } != 0 {
            return Some("slurmd must run as root".into());
        }
        None
    }

    /// Starts the daemons in the farm's folder (their logs are `*.log` there, shown with
    /// the farm's when a test fails) and waits until the node is idle.
    pub fn start(farm: &Farm) -> Cluster {
        let dir = farm.path();
        let run = dir.join("slurm");
        for sub in ["state", "spool"] {
            fs::create_dir_all(run.join(sub)).unwrap();
        }
        fs::set_permissions(&run, fs::Permissions::from_mode(0o700)).unwrap();
        let key = run.join("munge.key");
        let bytes: Vec<u8> = (0..1024u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8 ^ std::process::id() as u8)
            .collect();
        fs::write(&key, bytes).unwrap();
        fs::set_permissions(&key, fs::Permissions::from_mode(0o400)).unwrap();
        let socket = run.join("munge.sock");
        let mut munged = Command::new(find("munged").unwrap());
        munged
            .arg("--foreground")
            .arg("--force")
            .arg(format!("--key-file={}", key.display()))
            .arg(format!("--socket={}", socket.display()))
            .arg(format!("--pid-file={}", run.join("munged.pid").display()))
            .arg(format!("--seed-file={}", run.join("munged.seed").display()))
            .arg(format!(
                "--log-file={}",
                dir.join("munged-own.log").display()
            ));
        let mut daemons = vec![Process::spawn("munged", munged, dir)];
        wait_until(
            "munged's socket",
            Duration::from_secs(10),
            || socket.exists(),
            || farm.logs(),
        );

        let host = host_name();
        let conf = run.join("slurm.conf");
        fs::write(&conf, config(&run, &socket, &host)).unwrap();
        let mut slurmctld = Command::new(find("slurmctld").unwrap());
        slurmctld.arg("-D").arg("-f").arg(&conf);
        daemons.push(Process::spawn("slurmctld", slurmctld, dir));
        let mut slurmd = Command::new(find("slurmd").unwrap());
        slurmd.arg("-D").arg("-f").arg(&conf).arg("-N").arg(&host);
        daemons.push(Process::spawn("slurmd", slurmd, dir));
        let cluster = Cluster { conf, daemons };
        wait_until(
            "the Slurm node to be idle",
            Duration::from_secs(60),
            || {
                cluster
                    .output("sinfo", &["--noheader", "--format=%T"])
                    .trim()
                    == "idle"
            },
            || farm.logs(),
        );
        cluster
    }

    /// A Slurm client command of this cluster.
    pub fn command(&self, program: &str) -> Command {
        let mut cmd = Command::new(find(program).unwrap_or_else(|| program.into()));
        cmd.env("SLURM_CONF", &self.conf);
        cmd
    }

    /// What `program args` printed (empty where it failed).
    pub fn output(&self, program: &str, args: &[&str]) -> String {
        self.command(program)
            .args(args)
            .output()
            .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
            .unwrap_or_default()
    }

    /// The cluster's jobs and array elements: `ID STATE NAME` lines.
    pub fn jobs(&self) -> Vec<String> {
        self.output("squeue", &["--noheader", "--array", "--format=%i %T %j"])
            .lines()
            .map(str::to_string)
            .collect()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let ids: Vec<String> = self
            .output("squeue", &["--noheader", "--format=%A"])
            .split_whitespace()
            .map(str::to_string)
            .collect();
        if !ids.is_empty() {
            let _ = self.command("scancel").args(&ids).status();
            let until = Instant::now() + Duration::from_secs(20);
            while !self.jobs().is_empty() && Instant::now() < until {
                std::thread::sleep(Duration::from_millis(200));
            }
        }
        // slurmd first (it ends its job steps), the controller, then MUNGE.
        // (No assertions here: a drop during a failed test's unwinding must not panic.)
        for daemon in self.daemons.iter_mut().rev() {
            if daemon.running() {
                daemon.signal(libc::SIGTERM);
            }
            let until = Instant::now() + Duration::from_secs(10);
            while daemon.running() && Instant::now() < until {
                std::thread::sleep(Duration::from_millis(50));
            }
        }
        // Process's own drop kills with SIGKILL whatever is still running.
    }
}

/// `slurm.conf` for one node at 127.0.0.1 with every CPU and half the memory, on two free
/// ports, authenticated by the MUNGE at `socket`. No cgroups (linuxproc tracks a job's
/// processes), no accounting; a job killed at its limit gets 10 s between SIGTERM and
/// SIGKILL (a worker's goodbye takes at most that).
fn config(run: &Path, socket: &Path, host: &str) -> String {
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    let memory_mb = fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| {
            let line = m.lines().find(|l| l.starts_with("MemTotal:"))?.to_string();
            line.split_whitespace().nth(1)?.parse::<u64>().ok()
        })
        .map_or(1024, |kb| kb / 1024 / 2);
    let (ctld_port, d_port) = (free_port(), free_port());
    let run = run.display();
    format!(
        "ClusterName=tessera-test\n\
         SlurmctldHost={host}(127.0.0.1)\n\
         SlurmctldPort={ctld_port}\n\
         SlurmdPort={d_port}\n\
         AuthType=auth/munge\n\
         AuthInfo=socket={socket}\n\
         CredType=cred/munge\n\
         SlurmUser=root\n\
         SlurmdUser=root\n\
         StateSaveLocation={run}/state\n\
         SlurmdSpoolDir={run}/spool\n\
         SlurmctldPidFile={run}/slurmctld.pid\n\
         SlurmdPidFile={run}/slurmd.pid\n\
         ProctrackType=proctrack/linuxproc\n\
         TaskPlugin=task/none\n\
         JobAcctGatherType=jobacct_gather/none\n\
         SchedulerType=sched/builtin\n\
         SelectType=select/cons_tres\n\
         SelectTypeParameters=CR_Core\n\
         ReturnToService=2\n\
         MpiDefault=none\n\
         KillWait=10\n\
         SlurmctldDebug=info\n\
         SlurmdDebug=info\n\
         NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory={memory_mb} State=UNKNOWN\n\
         PartitionName=test Nodes={host} Default=YES MaxTime=INFINITE State=UP\n",
        socket = socket.display()
    )
}

/// This machine's short host name (what slurmd and slurmctld call it).
fn host_name() -> String {
    let name = fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
    let name = name.trim().split('.').next().unwrap_or_default();
    if name.is_empty() {
        "localhost".into()
    } else {
        name.into()
    }
}

/// `program` on the PATH or in /usr/sbin (not on every user's PATH).
fn find(program: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain([PathBuf::from("/usr/sbin"), PathBuf::from("/sbin")])
        .map(|dir| dir.join(program))
        .find(|p| p.is_file())
}
