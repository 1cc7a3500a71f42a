//! Webhooks: the server tells URLs when a job ends (done, failed, its time budget reached)
//! or a worker is quarantined. What to tell is written to the outbox
//! ([`crate::db::outbox`]) in the transaction that made it happen; the sweeper hands each
//! entry to a delivery task, so the scheduler never waits on a receiver. A delivery is a
//! POST of a [`Notification`] signed with HMAC-SHA256 of its body under the server's
//! webhook secret, tried up to [`ATTEMPTS`] times with doubling waits; the entry is
//! removed once every URL took it or was given up on. A server that stops mid-delivery
//! delivers again after its restart: receivers drop repeats by the notification's id.

use std::collections::HashSet;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use hmac::{Hmac, Mac};
use proto::{JobState, Notification, NotificationKind};
use sha2::Sha256;
use tokio::sync::Semaphore;

use crate::app::{now_ms, AppState};
use crate::db::outbox::{self, Pending, Subject};
use crate::error::{Error, Result};
use crate::store::hex;
use crate::{db, status};

/// Tries per URL and notification.
pub const ATTEMPTS: u32 = 7;
/// The wait before the second try; it doubles after each (1 s, 2 s, ... 32 s: a minute in
/// all).
pub const FIRST_RETRY: Duration = Duration::from_secs(1);
/// How long one try may take.
pub const TIMEOUT: Duration = Duration::from_secs(10);
/// Deliveries under way at once; later notifications wait in the outbox.
pub const CONCURRENT: usize = 16;
/// Length of a webhook URL, bytes.
pub const MAX_URL_BYTES: usize = 2_000;

/// The deliveries under way.
pub struct Webhooks {
    client: reqwest::Client,
    in_flight: Mutex<HashSet<u64>>,
    slots: Arc<Semaphore>,
}

impl Default for Webhooks {
    fn default() -> Self {
        Webhooks {
            client: reqwest::Client::builder()
                .timeout(TIMEOUT)
                .build()
                .expect("a client with a timeout builds"),
            in_flight: Mutex::new(HashSet::new()),
            slots: Arc::new(Semaphore::new(CONCURRENT)),
        }
    }
}

/// Checks a webhook URL: `http://` or `https://`, a host, at most [`MAX_URL_BYTES`].
pub fn check_url(field: &str, url: &str) -> Result<()> {
    let bad = |message: String| {
        Err(Error::Invalid {
            field: field.into(),
            message,
        })
    };
    if url.len() > MAX_URL_BYTES {
        return bad(format!("at most {MAX_URL_BYTES} bytes, got {}", url.len()));
    }
    match reqwest::Url::parse(url) {
        Ok(u) if matches!(u.scheme(), "http" | "https") && u.host().is_some() => Ok(()),
        Ok(_) => bad(format!("`{url}` is not an http:// or https:// URL")),
        Err(e) => bad(format!("`{url}`: {e}")),
    }
}

/// `sha256=` and the hex HMAC-SHA256 of `body` keyed with `secret`.
pub fn signature(secret: &str, body: &[u8]) -> String {
    let mut mac =
        Hmac::<Sha256>::new_from_slice(secret.as_bytes()).expect("HMAC takes keys of any size");
    mac.update(body);
    format!("sha256={}", hex(&mac.finalize().into_bytes()))
}

/// Hands the outbox's entries to delivery tasks (those not already under way).
pub async fn deliver_pending(app: &AppState) {
    let pending = match app
        .db
        .run(|c| outbox::pending(c, CONCURRENT as u32 * 4))
        .await
    {
        Ok(p) => p,
        Err(e) => return tracing::error!("reading the webhook outbox: {e}"),
    };
    for entry in pending {
        if !lock(&app.webhooks.in_flight).insert(entry.id) {
            continue;
        }
        let app = app.clone();
        tokio::spawn(async move {
            let id = entry.id;
            if let Err(e) = deliver(&app, entry).await {
                tracing::error!("webhook notification {id}: {e}");
            }
            lock(&app.webhooks.in_flight).remove(&id);
        });
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Delivers one entry to every URL it goes to, then removes it.
async fn deliver(app: &AppState, entry: Pending) -> Result<()> {
    let a = app.clone();
    let made = app.db.run(move |c| notification(&a, c, entry)).await?;
    if let Some((notification, urls)) = made {
        let body = serde_json::to_vec(&notification)?;
        let secret = app.config.webhook_secret.clone().unwrap_or_default();
        let sign = signature(&secret, &body);
        let tries = urls.into_iter().map(|url| {
            let (app, body, sign) = (app.clone(), body.clone(), sign.clone());
            async move {
                let _slot = app.webhooks.slots.acquire().await;
                send(&app.webhooks.client, &url, notification.id, body, &sign).await
            }
        });
        for (url, delivered) in join_all(tries).await {
            if !delivered {
                tracing::warn!(
                    "webhook {url}: notification {} not taken after {ATTEMPTS} tries; dropped",
                    entry.id
                );
            }
        }
    }
    app.db.run(move |c| outbox::remove(c, entry.id)).await
}

/// Runs the deliveries together; each says its URL and whether it was taken.
async fn join_all<F>(tries: impl Iterator<Item = F>) -> Vec<(String, bool)>
where
    F: std::future::Future<Output = (String, bool)> + Send + 'static,
{
    let handles: Vec<_> = tries.map(tokio::spawn).collect();
    let mut out = Vec::new();
    for h in handles {
        if let Ok(r) = h.await {
            out.push(r);
        }
    }
    out
}

/// The notification of `entry` and the URLs it goes to; `None` when nobody is to be
/// told (no webhooks, a job cancelled, reopened or deleted since).
fn notification(
    app: &AppState,
    c: &rusqlite::Connection,
    entry: Pending,
) -> Result<Option<(Notification, Vec<String>)>> {
    let mut urls = app.config.webhooks.clone();
    let now = now_ms();
    let live_since = app.timing().live_since(now);
    let (event, job, worker) = match entry.subject {
        Subject::JobFinished(id) => {
            let job = match status::job_status(c, id, now, live_since) {
                Ok(job) => job,
                Err(Error::NotFound(_)) => return Ok(None),
                Err(e) => return Err(e),
            };
            let event = match job.state {
                JobState::Done if job.spec.time_budget.is_some() => {
                    NotificationKind::JobBudgetReached
                }
                JobState::Done => NotificationKind::JobDone,
                JobState::Failed => NotificationKind::JobFailed,
                JobState::Cancelled | JobState::Queued | JobState::Running | JobState::Paused => {
                    return Ok(None)
                }
            };
            urls.extend(job.spec.webhook.clone());
            (event, Some(Box::new(job)), None)
        }
        Subject::WorkerQuarantined(id) => {
            let worker = db::workers::info(c, id, now, live_since)?;
            (NotificationKind::WorkerQuarantined, None, Some(worker))
        }
    };
    if urls.is_empty() {
        return Ok(None);
    }
    let notification = Notification {
        id: entry.id,
        event,
        at_ms: entry.at_ms,
        job,
        worker,
    };
    Ok(Some((notification, urls)))
}

/// Posts `body` to `url` until a 2xx answer or [`ATTEMPTS`] tries.
async fn send(
    client: &reqwest::Client,
    url: &str,
    id: u64,
    body: Vec<u8>,
    signature: &str,
) -> (String, bool) {
    let mut wait = FIRST_RETRY;
    for attempt in 1..=ATTEMPTS {
        let answer = client
            .post(url)
            .header(reqwest::header::CONTENT_TYPE, "application/json")
            .header(Notification::SIGNATURE, signature)
            .header(Notification::DELIVERY, id.to_string())
            .body(body.clone())
            .send()
            .await;
        match answer {
            Ok(r) if r.status().is_success() => return (url.to_string(), true),
            Ok(r) => tracing::warn!(
                "webhook {url}: notification {id} answered {} (try {attempt} of {ATTEMPTS})",
                r.status()
            ),
            Err(e) => tracing::warn!(
                "webhook {url}: notification {id}: {e} (try {attempt} of {ATTEMPTS})"
            ),
        }
        if attempt < ATTEMPTS {
            tokio::time::sleep(wait).await;
            wait *= 2;
        }
    }
    (url.to_string(), false)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_signature_is_rfc_4231s_hmac_sha256() {
        // RFC 4231, test case 2.
        assert_eq!(
            signature("Jefe", b"what do ya want for nothing?"),
            "sha256=5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843"
        );
    }

    #[test]
    fn webhook_urls_are_http_with_a_host() {
        assert!(check_url("webhook", "https://hooks.example.com/tessera?x=1").is_ok());
        assert!(check_url("webhook", "http://127.0.0.1:9000/").is_ok());
        for bad in [
            "ftp://example.com/",
            "example.com",
            "http://",
            "file:///etc/passwd",
        ] {
            assert!(check_url("webhook", bad).is_err(), "{bad}");
        }
        let long = format!("https://example.com/{}", "a".repeat(MAX_URL_BYTES));
        assert!(check_url("webhook", &long).is_err());
    }
}
