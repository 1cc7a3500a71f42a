//! Bit-for-bit verification. A tile is a pure function of its task, so two healthy workers
//! render it identically; a worker with bad memory or a broken build does not.
//!
//! A fraction of the render tasks (`--verify-fraction`) is rendered again by another
//! worker: a check task, with the same frame, tile and samples and `check_of` naming the
//! task. Its tile is compared, bit for bit, with every render of the group so far:
//!
//! - it agrees with an earlier render: those renders are right, the others wrong; the
//!   workers of the wrong ones are quarantined (no more work until an operator clears
//!   them) and the agreed tile is the one the frame is assembled from;
//! - it agrees with none: every worker involved becomes a suspect and the tile is rendered
//!   again by a worker not yet involved, up to [`MAX_CHECKS`] times.
//!
//! Checks count as tasks of their frame, so a frame is assembled only once its checks are
//! decided. A quarantined worker's other unchecked tiles in frames not yet assembled are
//! checked too.

use rusqlite::{Connection, Transaction};
use tracer::film::Layers;

use crate::db::events::log;
pub use crate::db::tasks::Render;
use crate::db::tasks::{self, NewTask, TaskRow};
use crate::db::{frames, outbox, workers};
use crate::error::{Error, Result};

/// The most check renders of one task: with the first render, four chances for two
/// workers to agree.
pub const MAX_CHECKS: u32 = 3;

/// Whether task `id` is among the `fraction` sampled for a check. A hash of the id, so the
/// choice survives a restart and spreads evenly over frames and tiles.
pub fn sampled(id: u64, fraction: f64) -> bool {
    if fraction <= 0.0 {
        return false;
    }
    // splitmix64's finaliser: consecutive ids give unrelated values.
    let mut z = id.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    ((z >> 11) as f64 / (1u64 << 53) as f64) < fraction
}

/// Whether two tiles are identical bit for bit, every layer (`0.0` and `-0.0` differ).
pub fn identical(a: &Layers, b: &Layers) -> bool {
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    a.rect == b.rect
        && a.beauty.len() == b.beauty.len()
        && a.beauty
            .iter()
            .zip(&b.beauty)
            .all(|(x, y)| bits(&x.to_array()) == bits(&y.to_array()))
        && a.albedo
            .iter()
            .zip(&b.albedo)
            .all(|(x, y)| bits(&x.to_array()) == bits(&y.to_array()))
        && a.normal
            .iter()
            .zip(&b.normal)
            .all(|(x, y)| bits(&x.to_array()) == bits(&y.to_array()))
        && bits(&a.depth) == bits(&b.depth)
}

/// What a check's tile says about its group, decided before the tile is accepted.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// It agrees with these earlier renders (task ids): they are right, the rest wrong.
    Agrees(Vec<u64>),
    /// It agrees with none, but every earlier render came from a quarantined worker: it
    /// stands as the tile.
    Stands,
    /// It agrees with none: every worker involved is a suspect; render again.
    Disagrees,
}

impl Verdict {
    /// From the group's earlier renders and those the new tile is identical to.
    pub fn new(group: &[Render], matching: &[u64]) -> Verdict {
        if !matching.is_empty() {
            Verdict::Agrees(matching.to_vec())
        } else if group.iter().all(|r| r.quarantined) {
            Verdict::Stands
        } else {
            Verdict::Disagrees
        }
    }

    /// Whether the task's own tile (`original`) is found wrong, so the check's tile must
    /// take its place before the frame is assembled.
    pub fn replaces(&self, original: u64) -> bool {
        match self {
            Verdict::Agrees(with) => !with.contains(&original),
            Verdict::Stands => true,
            Verdict::Disagrees => false,
        }
    }
}

/// The finished renders of the task `original` and its checks.
pub fn group(conn: &Connection, original: u64) -> Result<Vec<Render>> {
    tasks::renders_of(conn, original)
}

/// Queues a check of the render task `task`; its frame now waits for it.
fn add_check(tx: &Transaction, task: &TaskRow, now: i64, why: &str) -> Result<()> {
    tasks::insert(tx, &NewTask::check_of(task))?;
    frames::add_tasks(tx, task.job_id, task.frame, 1)?;
    log(
        tx,
        now,
        Some(task.job_id),
        "check_queued",
        &format!("task {} ({why})", task.id),
    )
}

/// After a render task is accepted: queue its check if it is sampled and another worker
/// (live, not quarantined) could render it. Whether it queued one.
pub fn sample(
    tx: &Transaction,
    task: &TaskRow,
    worker: u64,
    fraction: f64,
    live_since: i64,
    now: i64,
) -> Result<bool> {
    if task.check_of.is_some() || !sampled(task.id, fraction) {
        return Ok(false);
    }
    if !workers::another_live(tx, task.job_id, worker, live_since)? {
        return Ok(false);
    }
    add_check(tx, task, now, "sampled")?;
    Ok(true)
}

/// After a check task is accepted: acts on its verdict. Whether it queued a task (another
/// check; the tasks of a worker it quarantined, leased or to be checked).
pub fn record(
    tx: &Transaction,
    check: &TaskRow,
    worker: u64,
    verdict: &Verdict,
    now: i64,
) -> Result<bool> {
    let original_id = check
        .check_of
        .ok_or_else(|| Error::Internal(format!("task {} is not a check", check.id)))?;
    let original = tasks::load(tx, original_id)?
        .ok_or_else(|| Error::Internal(format!("checked task {original_id} vanished")))?;
    let earlier: Vec<Render> = group(tx, original_id)?
        .into_iter()
        .filter(|r| r.task != check.id)
        .collect();
    // Who rendered what, on which machine and build: a mismatch between two platforms may
    // be the platforms', not a broken machine's.
    let mut renders: Vec<(u64, u64)> = earlier.iter().map(|r| (r.task, r.worker)).collect();
    renders.push((check.id, worker));
    let platforms = platforms(tx, &renders)?;
    match verdict {
        Verdict::Agrees(with) => {
            let right = |r: &Render| with.contains(&r.task);
            let mut queued = false;
            for r in earlier.iter().filter(|r| !right(r)) {
                let reason = format!(
                    "its tile of task {original_id} (job {}, frame {}, tile {}) differs from \
                     the identical tiles of {} other render(s); {platforms}",
                    check.job_id,
                    check.frame,
                    check.tile,
                    with.len() + 1
                );
                queued |= quarantine(tx, r.worker, &reason, now)?;
            }
            for w in earlier
                .iter()
                .filter(|r| right(r))
                .map(|r| r.worker)
                .chain([worker])
            {
                workers::unsuspect(tx, w)?;
            }
            log(
                tx,
                now,
                Some(check.job_id),
                "check_agreed",
                &format!(
                    "task {original_id}: check {} agrees with {with:?}",
                    check.id
                ),
            )?;
            Ok(queued)
        }
        Verdict::Stands => {
            log(
                tx,
                now,
                Some(check.job_id),
                "check_replaced",
                &format!(
                    "task {original_id}: check {} replaces the tile of a quarantined worker",
                    check.id
                ),
            )?;
            Ok(false)
        }
        Verdict::Disagrees => {
            for w in earlier.iter().map(|r| r.worker).chain([worker]) {
                workers::suspect(tx, w, now)?;
            }
            log(
                tx,
                now,
                Some(check.job_id),
                "check_disagreed",
                &format!(
                    "task {original_id}: check {} differs from every earlier render; \
                     {platforms}",
                    check.id
                ),
            )?;
            // `earlier` is the task and every check before this one.
            if (earlier.len() as u32) < MAX_CHECKS {
                add_check(tx, &original, now, "renders disagree")?;
                Ok(true)
            } else {
                log(
                    tx,
                    now,
                    Some(check.job_id),
                    "check_undecided",
                    &format!(
                        "task {original_id}: no two of {} renders agree; its first tile is kept",
                        earlier.len() + 1
                    ),
                )?;
                Ok(false)
            }
        }
    }
}

/// "renders: task 12 by worker 3 on <platform>, ..." for `(task, worker)` pairs.
fn platforms(tx: &Transaction, renders: &[(u64, u64)]) -> Result<String> {
    let mut parts = Vec::with_capacity(renders.len());
    for &(task, worker) in renders {
        let (name, platform) = workers::name_and_platform(tx, worker)?;
        let platform = platform.unwrap_or_else(|| "a platform it did not report".into());
        parts.push(format!(
            "task {task} by worker {worker} ({name}) on {platform}"
        ));
    }
    Ok(format!("renders: {}", parts.join("; ")))
}

/// Quarantines `worker`: its leases go back to the queue, it gets no more work, and its
/// unchecked tiles in frames not yet assembled are checked.
fn quarantine(tx: &Transaction, worker: u64, reason: &str, now: i64) -> Result<bool> {
    if !workers::quarantine(tx, worker, reason, now)? {
        return Ok(false);
    }
    let leased = tasks::leased_by(tx, worker)?;
    for task in &leased {
        tasks::revoke(tx, task)?;
    }
    let unchecked = tasks::unchecked_unmerged_of(tx, worker)?;
    for task in &unchecked {
        add_check(tx, task, now, &format!("worker {worker} quarantined"))?;
    }
    let assembled = tasks::merged_count_of(tx, worker)?;
    outbox::add(tx, outbox::Subject::WorkerQuarantined(worker), now)?;
    log(
        tx,
        now,
        None,
        "worker_quarantined",
        &format!(
            "{worker}: {reason}; {} unchecked tiles sent for checks, {assembled} tiles already \
             in assembled frames",
            unchecked.len()
        ),
    )?;
    Ok(!leased.is_empty() || !unchecked.is_empty())
}

/// An operator clears a worker: it is no longer quarantined or suspect and gets work again.
pub fn clear(conn: &mut Connection, worker: u64, now: i64) -> Result<()> {
    let tx = conn.transaction()?;
    if !workers::clear(&tx, worker)? {
        return Err(Error::NotFound(format!(
            "worker {worker} is not registered"
        )));
    }
    log(&tx, now, None, "worker_cleared", &worker.to_string())?;
    tx.commit()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tracer::film::TileRect;

    #[test]
    fn sampling_takes_about_the_fraction_asked_and_is_stable() {
        let taken = (0..100_000).filter(|&id| sampled(id, 0.05)).count();
        assert!((4_500..5_500).contains(&taken), "{taken}");
        assert_eq!((0..1000).filter(|&id| sampled(id, 1.0)).count(), 1000);
        assert_eq!((0..1000).filter(|&id| sampled(id, 0.0)).count(), 0);
        assert_eq!(sampled(12_345, 0.3), sampled(12_345, 0.3));
    }

    #[test]
    fn identical_means_every_bit_of_every_layer() {
        let a = Layers::new(TileRect::new(0, 0, 2, 2));
        let mut b = a.clone();
        assert!(identical(&a, &b));
        b.depth[3] = f32::from_bits(b.depth[3].to_bits() + 1);
        assert!(!identical(&a, &b));
        let mut c = a.clone();
        c.beauty[0].x = -0.0;
        assert!(!identical(&a, &c), "-0.0 is not 0.0 bit for bit");
        assert!(!identical(&a, &Layers::new(TileRect::new(2, 0, 2, 2))));
    }

    #[test]
    fn verdicts_from_agreement_and_quarantine() {
        let r = |task, worker, quarantined| Render {
            task,
            attempt: 1,
            worker,
            quarantined,
        };
        let group = [r(1, 10, false), r(5, 11, false)];
        assert_eq!(Verdict::new(&group, &[5]), Verdict::Agrees(vec![5]));
        assert!(Verdict::new(&group, &[5]).replaces(1));
        assert!(!Verdict::new(&group, &[1]).replaces(1));
        assert_eq!(Verdict::new(&group, &[]), Verdict::Disagrees);
        assert!(!Verdict::Disagrees.replaces(1));
        let convicted = [r(1, 10, true)];
        assert_eq!(Verdict::new(&convicted, &[]), Verdict::Stands);
        assert!(Verdict::Stands.replaces(1));
    }
}
