//! Slurm through its own commands: worker jobs are array jobs submitted with `sbatch`,
//! listed with `squeue`, cancelled with `scancel`. Every job carries the name
//! [`JOB_NAME`] and a comment naming the farm it serves ([`marker`]); only the user's own
//! jobs with both are ever listed or cancelled.

use std::io::Write as _;
use std::path::Path;
use std::process::{Command, Stdio};

use anyhow::{bail, Context};

use super::{Engine, JobState, ScaleArgs, WorkerJob};

/// Every worker job's name (`squeue --name`).
pub const JOB_NAME: &str = "tessera-worker";

/// The comment that marks a worker job as this farm's: two provisioners of two farms on
/// one account leave each other's jobs alone.
pub fn marker(server: &str) -> String {
    format!("tessera-scale {}", server.trim_end_matches('/'))
}

/// The batch script of a worker job: the worker named after the job and rendering on the
/// cores Slurm gave it, `exec`'d so that Slurm's signals reach it (SIGUSR1 before the time
/// limit: it drains; SIGTERM at the limit or on `scancel`: it gives its tile back).
pub fn script(tessera: &Path) -> String {
    let program = tessera.to_string_lossy().replace('\'', r"'\''");
    format!(
        "#!/bin/sh\n\
         # A Tessera worker started by `tessera scale slurm`; it leaves the farm after\n\
         # TESSERA_EXIT_WHEN_IDLE seconds without a task.\n\
         export TESSERA_NAME=\"slurm-$SLURM_JOB_ID\"\n\
         export TESSERA_THREADS=\"${{SLURM_CPUS_PER_TASK:-1}}\"\n\
         exec '{program}' worker\n"
    )
}

/// A provisioner's view of Slurm.
pub struct Slurm {
    /// The comment of this farm's worker jobs.
    marker: String,
    /// Where the jobs log.
    log_dir: std::path::PathBuf,
    /// `sbatch` options every submission has (the array's size comes last).
    options: Vec<String>,
    /// The worker's settings, handed to the jobs in the environment (`--export=ALL`).
    env: Vec<(&'static str, String)>,
    script: String,
}

impl Slurm {
    /// Slurm for `args`, after `sbatch --test-only` accepted its options (a wrong
    /// partition or account is refused here, with Slurm's own words, not at every look).
    /// `tessera` is the program the jobs run, `log_dir` where they log.
    pub fn new(args: &ScaleArgs, tessera: &Path, log_dir: &Path) -> anyhow::Result<Slurm> {
        let marker = marker(&args.server);
        let mut options = vec![
            format!("--job-name={JOB_NAME}"),
            format!("--comment={marker}"),
            "--export=ALL".into(),
            format!("--cpus-per-task={}", args.cpus),
            format!(
                "--output={}",
                log_dir.join("tessera-worker-%A_%a.log").display()
            ),
        ];
        let optional = [
            ("--partition", &args.partition),
            ("--account", &args.account),
            ("--time", &args.time),
            ("--mem", &args.mem),
        ];
        for (flag, value) in optional {
            if let Some(value) = value {
                options.push(format!("{flag}={value}"));
            }
        }
        if args.drain_seconds > 0 {
            options.push(format!("--signal=B:USR1@{}", args.drain_seconds));
        }
        options.extend(args.sbatch_arg.iter().cloned());
        let mut env = vec![
            ("TESSERA_SERVER", args.server.clone()),
            ("TESSERA_EXIT_WHEN_IDLE", args.exit_when_idle.to_string()),
        ];
        if let Some(token) = &args.token {
            env.push(("TESSERA_WORKER_TOKEN", token.clone()));
        }
        if let Some(ca) = &args.ca {
            env.push(("TESSERA_CA", ca.display().to_string()));
        }
        let slurm = Slurm {
            marker,
            log_dir: log_dir.to_path_buf(),
            options,
            env,
            script: script(tessera),
        };
        slurm
            .sbatch(&["--test-only".into(), "--array=0-0".into()])
            .context("Slurm refused the worker jobs' options (sbatch --test-only)")?;
        Ok(slurm)
    }

    /// Runs `sbatch` with the options, `extra` and the script on its standard input.
    fn sbatch(&self, extra: &[String]) -> anyhow::Result<String> {
        let mut cmd = Command::new("sbatch");
        cmd.args(&self.options).args(extra);
        for (key, value) in &self.env {
            cmd.env(key, value);
        }
        run(cmd, Some(&self.script))
    }
}

impl Engine for Slurm {
    fn jobs(&mut self) -> anyhow::Result<Vec<WorkerJob>> {
        let mut cmd = Command::new("squeue");
        // Every state: ended jobs too, while the controller remembers them (its
        // MinJobAge, 300 s by default), for the failures.
        cmd.args([
            "--noheader",
            "--array",
            "--states=all",
            "--me",
            &format!("--name={JOB_NAME}"),
            "--format=%i|%T|%k",
        ]);
        Ok(parse_squeue(&run(cmd, None)?, &self.marker))
    }

    fn submit(&mut self, count: u32) -> anyhow::Result<String> {
        let out = self.sbatch(&["--parsable".into(), format!("--array=0-{}", count - 1)])?;
        // `--parsable`: `JOBID` or `JOBID;CLUSTER`.
        let id = out.trim().split(';').next().unwrap_or_default().to_string();
        Ok(id)
    }

    fn cancel(&mut self, ids: &[String]) -> anyhow::Result<()> {
        let mut cmd = Command::new("scancel");
        // Only while still pending: one that started since the look keeps running.
        cmd.arg("--state=PENDING").args(ids);
        run(cmd, None).map(drop)
    }

    fn log_of(&self, id: &str) -> String {
        // `--output=.../tessera-worker-%A_%a.log`; an array element's id is `%A_%a`.
        self.log_dir
            .join(format!("tessera-worker-{id}.log"))
            .display()
            .to_string()
    }
}

/// This farm's worker jobs in `squeue --array --format=%i|%T|%k` output, oldest first.
/// Jobs stopped from outside (a time limit, a preemption, a cancellation) say nothing of
/// their worker and are left out; an ending job (COMPLETING) counts as running.
fn parse_squeue(out: &str, marker: &str) -> Vec<WorkerJob> {
    let mut jobs: Vec<((u64, u64), WorkerJob)> = out
        .lines()
        .filter_map(|line| {
            let mut fields = line.trim().splitn(3, '|');
            let (id, state, comment) = (fields.next()?, fields.next()?, fields.next()?);
            if comment != marker {
                return None;
            }
            let state = job_state(state)?;
            let (job, index) = id.split_once('_').unwrap_or((id, "0"));
            let order = (job.parse().ok()?, index.parse().unwrap_or(0));
            let id = id.to_string();
            Some((order, WorkerJob { id, state }))
        })
        .collect();
    jobs.sort_by_key(|(order, _)| *order);
    jobs.into_iter().map(|(_, job)| job).collect()
}

/// A Slurm job state (`squeue %T`) as the provisioner counts it.
fn job_state(state: &str) -> Option<JobState> {
    Some(match state {
        "PENDING" => JobState::Pending,
        "COMPLETED" => JobState::Succeeded,
        "FAILED" | "BOOT_FAIL" | "NODE_FAIL" | "OUT_OF_MEMORY" => JobState::Failed,
        "CANCELLED" | "TIMEOUT" | "PREEMPTED" | "DEADLINE" | "REVOKED" | "SPECIAL_EXIT" => {
            return None
        }
        // RUNNING, CONFIGURING, SUSPENDED, REQUEUED, RESIZING, ...: the job holds its place.
        // So does COMPLETING: it still holds its node, and whether its worker failed is not
        // known yet; counted as gone, a replacement would be submitted before the failure
        // that should hold the submissions is seen.
        _ => JobState::Running,
    })
}

/// Runs a Slurm command; its standard output, or an error with what it printed.
fn run(mut cmd: Command, stdin: Option<&str>) -> anyhow::Result<String> {
    let program = cmd.get_program().to_string_lossy().into_owned();
    let mut child = cmd
        .stdin(if stdin.is_some() {
            Stdio::piped()
        } else {
            Stdio::null()
        })
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => anyhow::anyhow!(
                "`{program}` is not on the PATH: run this where Slurm's commands are (a \
                 login node; `module load slurm` on some clusters)"
            ),
            _ => anyhow::Error::new(e).context(format!("starting `{program}`")),
        })?;
    if let (Some(text), Some(mut pipe)) = (stdin, child.stdin.take()) {
        pipe.write_all(text.as_bytes())
            .with_context(|| format!("writing the batch script to `{program}`"))?;
    }
    let out = child
        .wait_with_output()
        .with_context(|| format!("running `{program}`"))?;
    if !out.status.success() {
        let said = String::from_utf8_lossy(&out.stderr);
        bail!("`{program}` failed ({}): {}", out.status, said.trim());
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn squeue_lists_only_this_farms_live_jobs_oldest_first() {
        let ours = marker("http://farm:8700/");
        assert_eq!(ours, "tessera-scale http://farm:8700");
        let out = format!(
            "12_10|PENDING|{ours}\n12_2|RUNNING|{ours}\n9|RUNNING|{ours}\n\
             13_0|COMPLETING|{ours}\n14_0|PENDING|tessera-scale http://other:8700\n\
             15_0|PENDING|\n16_0|FAILED|{ours}\n16_1|COMPLETED|{ours}\n16_2|TIMEOUT|{ours}\n"
        );
        let jobs = parse_squeue(&out, &ours);
        let ids: Vec<(&str, JobState)> = jobs.iter().map(|j| (j.id.as_str(), j.state)).collect();
        use JobState::*;
        assert_eq!(
            ids,
            [
                ("9", Running),
                ("12_2", Running),
                ("12_10", Pending),
                ("13_0", Running),
                ("16_0", Failed),
                ("16_1", Succeeded)
            ]
        );
    }

    #[test]
    fn the_script_execs_the_worker_named_after_its_job() {
        let s = script(Path::new("/opt/it's/tessera"));
        assert!(s.starts_with("#!/bin/sh\n"));
        assert!(s.contains("export TESSERA_NAME=\"slurm-$SLURM_JOB_ID\"\n"));
        assert!(s.contains("${SLURM_CPUS_PER_TASK:-1}"));
        assert!(s.ends_with("exec '/opt/it'\\''s/tessera' worker\n"), "{s}");
    }
}
