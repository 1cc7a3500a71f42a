//! What a farm that runs for a season lets go of: finished jobs past `--keep-jobs` (with
//! their frames and tiles), scenes no job uses a day after their last upload, and events
//! past the log's bound. The sweeper runs it every [`GC_INTERVAL`]; `POST /gc` runs it
//! at once or, as a dry run, says what would go. A job with work left is never touched:
//! only jobs with nothing left to run (done, failed, cancelled) are finished.

use std::collections::HashSet;
use std::fmt;
use std::str::FromStr;
use std::time::Duration;

use proto::{GcJob, GcReport};

use crate::app::AppState;
use crate::db;
use crate::error::Result;
use crate::limits::{MAX_EVENTS, UNUSED_SCENE_GRACE_MS};
use crate::store::disk_use;

/// How often the sweeper collects.
pub const GC_INTERVAL: Duration = Duration::from_secs(600);

/// Which finished jobs are kept.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum KeepJobs {
    /// Every job (the default: results are the user's to delete).
    #[default]
    All,
    /// The `n` finished last.
    Newest(u64),
    /// Those that finished within this time.
    For(Duration),
}

impl FromStr for KeepJobs {
    type Err = String;

    /// `all`, a count (`50`), or an age with its unit: `45s`, `90m`, `12h`, `30d`.
    fn from_str(s: &str) -> Result<KeepJobs, String> {
        let s = s.trim();
        if s == "all" {
            return Ok(KeepJobs::All);
        }
        if let Ok(n) = s.parse::<u64>() {
            return Ok(KeepJobs::Newest(n));
        }
        let unit = |c: char| match c {
            's' => Some(1),
            'm' => Some(60),
            'h' => Some(3600),
            'd' => Some(86_400),
            _ => None,
        };
        let bad = || {
            format!(
                "`{s}`: expected `all`, a count of jobs (`50`) or an age (`45s`, `90m`, `12h`, \
                 `30d`)"
            )
        };
        let (number, seconds) = s
            .char_indices()
            .last()
            .and_then(|(i, c)| Some((&s[..i], unit(c)?)))
            .ok_or_else(bad)?;
        let n: u64 = number.parse().map_err(|_| bad())?;
        // Ten years at most: the age is added to and compared with Unix milliseconds.
        match n.checked_mul(seconds) {
            Some(total) if total <= 10 * 365 * 86_400 => {
                Ok(KeepJobs::For(Duration::from_secs(total)))
            }
            _ => Err(format!("`{s}`: at most ten years")),
        }
    }
}

impl fmt::Display for KeepJobs {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            KeepJobs::All => write!(f, "all"),
            KeepJobs::Newest(n) => write!(f, "{n}"),
            KeepJobs::For(age) => {
                let s = age.as_secs();
                match [(86_400, 'd'), (3600, 'h'), (60, 'm')]
                    .into_iter()
                    .find(|(unit, _)| s > 0 && s % unit == 0)
                {
                    Some((unit, c)) => write!(f, "{}{c}", s / unit),
                    None => write!(f, "{s}s"),
                }
            }
        }
    }
}

impl KeepJobs {
    /// Of the finished jobs (the last finished first), those this rule lets go at `now`.
    fn going(self, finished: Vec<GcJob>, now: i64) -> Vec<GcJob> {
        match self {
            KeepJobs::All => Vec::new(),
            KeepJobs::Newest(n) => finished.into_iter().skip(n as usize).collect(),
            KeepJobs::For(age) => {
                let before = now - age.as_millis() as i64;
                finished
                    .into_iter()
                    .filter(|j| j.finished_ms < before)
                    .collect()
            }
        }
    }
}

/// Collects by `keep` at `now` (blocking: call it on a blocking thread), or on a dry run
/// only says what would go.
pub fn collect(app: &AppState, keep: KeepJobs, dry_run: bool, now: i64) -> Result<GcReport> {
    let (jobs, scenes, events) = app.db.with(|c| -> Result<_> {
        let jobs = keep.going(db::jobs::finished(c)?, now);
        let going: HashSet<u64> = jobs.iter().map(|j| j.id).collect();
        let in_use: HashSet<String> = db::jobs::scenes(c)?
            .into_iter()
            .filter(|(job, _)| !going.contains(job))
            .map(|(_, scene)| scene)
            .collect();
        let scenes: Vec<String> = db::scenes::uploaded_before(c, now - UNUSED_SCENE_GRACE_MS)?
            .into_iter()
            .filter(|digest| !in_use.contains(digest))
            .collect();
        let ids: Vec<u64> = going.into_iter().collect();
        let events = db::events::to_trim(c, &ids, MAX_EVENTS)?;
        Ok((jobs, scenes, events))
    })?;
    let store = &app.store;
    let mut report = GcReport {
        dry_run,
        keep_jobs: keep.to_string(),
        jobs: Vec::new(),
        scenes: Vec::new(),
        events,
        bytes: 0,
    };
    for job in jobs {
        let bytes = disk_use(&store.job_dir(job.id)) + disk_use(&store.tile_dir(job.id));
        if !dry_run {
            let why = format!("retention: finished jobs kept: {keep}");
            app.db
                .with(|c| crate::controls::delete(c, job.id, now, &why))?;
            store.remove_job(job.id)?;
            app.events.send(proto::Event::JobDeleted { job_id: job.id });
        }
        report.bytes += bytes;
        report.jobs.push(job);
    }
    for digest in scenes {
        let bytes = disk_use(&store.scene(&digest));
        if !dry_run {
            let gone = app.db.with(|c| -> Result<bool> {
                let tx = c.transaction()?;
                let gone = db::scenes::delete_unused(&tx, &digest)?;
                tx.commit()?;
                Ok(gone)
            })?;
            if !gone {
                continue;
            }
            store.remove_scene(&digest)?;
        }
        report.bytes += bytes;
        report.scenes.push(digest);
    }
    if !dry_run {
        report.events = app.db.with(|c| -> Result<u64> {
            let tx = c.transaction()?;
            let n = db::events::trim(&tx, MAX_EVENTS)?;
            tx.commit()?;
            Ok(n)
        })?;
    }
    if !dry_run && (!report.jobs.is_empty() || !report.scenes.is_empty()) {
        tracing::info!(
            "retention removed {} job(s), {} scene(s) and {} event(s): {} bytes freed",
            report.jobs.len(),
            report.scenes.len(),
            report.events,
            report.bytes
        );
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keep_rules_parse_and_print_back() {
        for (text, rule) in [
            ("all", KeepJobs::All),
            ("50", KeepJobs::Newest(50)),
            ("0", KeepJobs::Newest(0)),
            ("30d", KeepJobs::For(Duration::from_secs(30 * 86_400))),
            ("12h", KeepJobs::For(Duration::from_secs(12 * 3600))),
            ("90m", KeepJobs::For(Duration::from_secs(90 * 60))),
            ("45s", KeepJobs::For(Duration::from_secs(45))),
        ] {
            assert_eq!(text.parse::<KeepJobs>(), Ok(rule), "{text}");
            assert_eq!(rule.to_string(), text);
        }
        assert_eq!(
            "120m".parse::<KeepJobs>().unwrap().to_string(),
            "2h",
            "printed in the largest whole unit"
        );
        for bad in ["", "d", "30w", "-5", "1.5d", "99999999999d", "3 d"] {
            assert!(bad.parse::<KeepJobs>().is_err(), "{bad}");
        }
    }

    #[test]
    fn a_rule_lets_go_of_the_oldest_finished_jobs_only() {
        let job = |id, finished_ms| GcJob {
            id,
            name: format!("job {id}"),
            finished_ms,
        };
        // The last finished first, as the database lists them.
        let finished = || vec![job(3, 9_000), job(1, 5_000), job(2, 1_000)];
        let ids = |jobs: Vec<GcJob>| jobs.into_iter().map(|j| j.id).collect::<Vec<_>>();
        assert_eq!(ids(KeepJobs::All.going(finished(), 10_000)), [0u64; 0]);
        assert_eq!(ids(KeepJobs::Newest(1).going(finished(), 10_000)), [1, 2]);
        assert_eq!(
            ids(KeepJobs::Newest(5).going(finished(), 10_000)),
            [0u64; 0]
        );
        let four_seconds = KeepJobs::For(Duration::from_secs(4));
        assert_eq!(ids(four_seconds.going(finished(), 10_000)), [1, 2]);
    }
}
