//! The dashboard in a real headless Chromium (Debian's `chromium`, installed here when
//! missing), driven over the DevTools protocol: the page is loaded during a job, the job
//! finishes while it is open, and the DOM must show what only the live event stream could
//! have told it. A screenshot is kept in the target folder as an artifact.

use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use base64::Engine;
use proto::{FrameRange, JobSpec};
use reqwest::StatusCode;
use serde_json::{json, Value};
use tungstenite::stream::MaybeTlsStream;
use tungstenite::{Message, WebSocket};

use crate::common::*;

/// The Chromium binary, installing Debian's package when it is missing. The tests of
/// this binary that open a browser run at once: one installs and the others wait for it
/// (two apt-get runs at once fail on the package system's lock).
fn chromium() -> PathBuf {
    static INSTALL: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one_at_a_time = INSTALL.lock().unwrap_or_else(|e| e.into_inner());
    let found = || {
        Command::new("sh")
            .args(["-c", "command -v chromium"])
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| PathBuf::from(String::from_utf8_lossy(&o.stdout).trim()))
    };
    if let Some(p) = found() {
        return p;
    }
    let status = Command::new("sh")
        .args([
            "-c",
            "apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium",
        ])
        .status()
        .expect("running apt-get");
    assert!(
        status.success(),
        "installing Debian's chromium package failed"
    );
    found().expect("chromium on PATH after installing it")
}

/// A headless Chromium and a DevTools session on one page.
struct Browser {
    child: Child,
    ws: WebSocket<MaybeTlsStream<TcpStream>>,
    session: String,
    next_id: u64,
    _profile: tempfile::TempDir,
}

impl Browser {
    fn open(url: &str) -> Browser {
        let profile = tempfile::tempdir().unwrap();
        let mut child = Command::new(chromium())
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-dev-shm-usage",
                "--no-first-run",
                "--hide-scrollbars",
                "--remote-debugging-port=0",
                "--window-size=1200,900",
            ])
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .arg("about:blank")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Chromium prints where its DevTools endpoint listens.
        let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
        let endpoint = loop {
            let line = lines
                .next()
                .expect("chromium exited before listening")
                .unwrap();
            if let Some(url) = line.strip_prefix("DevTools listening on ") {
                break url.trim().to_string();
            }
        };
        // Keep draining stderr so Chromium never blocks on a full pipe.
        std::thread::spawn(move || for _ in lines {});
        let (ws, _) = tungstenite::connect(endpoint.as_str()).unwrap();
        let mut b = Browser {
            child,
            ws,
            session: String::new(),
            next_id: 0,
            _profile: profile,
        };
        let target = b.call(None, "Target.createTarget", json!({"url": url}));
        let target_id = target["targetId"].as_str().unwrap().to_string();
        let attached = b.call(
            None,
            "Target.attachToTarget",
            json!({"targetId": target_id, "flatten": true}),
        );
        b.session = attached["sessionId"].as_str().unwrap().to_string();
        b
    }

    /// Sends a DevTools command and waits for its answer (skipping events).
    fn call(&mut self, session: Option<&str>, method: &str, params: Value) -> Value {
        self.next_id += 1;
        let id = self.next_id;
        let mut msg = json!({"id": id, "method": method, "params": params});
        if let Some(s) = session {
            msg["sessionId"] = json!(s);
        }
        self.ws.send(Message::text(msg.to_string())).unwrap();
        loop {
            let Message::Text(text) = self.ws.read().unwrap() else {
                continue;
            };
            let v: Value = serde_json::from_str(text.as_str()).unwrap();
            if v["id"] == json!(id) {
                assert!(v.get("error").is_none(), "{method}: {v}");
                return v["result"].clone();
            }
        }
    }

    /// Evaluates `expr` in the page and returns its JSON value (a promise's, once it
    /// settles).
    fn eval(&mut self, expr: &str) -> Value {
        let session = self.session.clone();
        let r = self.call(
            Some(&session),
            "Runtime.evaluate",
            json!({"expression": expr, "returnByValue": true, "awaitPromise": true}),
        );
        r["result"]["value"].clone()
    }

    /// Evaluates `expr` until it is true (the page updates asynchronously); panics with
    /// `what` after a generous bound, since a page that never gets there is the failure.
    fn wait_for(&mut self, expr: &str, what: &str) {
        for _ in 0..600 {
            if self.eval(expr) == json!(true) {
                return;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        panic!(
            "the page never showed {what}; body: {}",
            self.eval("document.body.innerText")
        );
    }

    fn screenshot(&mut self) -> Vec<u8> {
        let session = self.session.clone();
        let r = self.call(
            Some(&session),
            "Page.captureScreenshot",
            json!({"format": "png"}),
        );
        base64::engine::general_purpose::STANDARD
            .decode(r["data"].as_str().unwrap())
            .unwrap()
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// What the page shows of the job and the worker, as JSON.
const SUMMARY: &str = r#"JSON.stringify((() => {
  const card = document.querySelector('.job');
  const row = document.querySelector('#workers tbody tr');
  return {
    state: card && card.dataset.state,
    name: card && card.querySelector('.name').textContent,
    bar: card && card.querySelector('.bar > div').style.width,
    stats: card && card.querySelector('.stats').textContent,
    frames: card ? [...card.querySelectorAll('.frames figure')].map(f => [Number(f.dataset.frame), f.dataset.state]) : [],
    thumbs: card ? [...card.querySelectorAll('.frames img')].map(i => i.complete ? i.naturalWidth : 0) : [],
    worker: row ? [...row.children].map(td => td.textContent) : [],
    failures: card ? [...card.querySelectorAll('.failures li')].map(li => li.textContent) : [],
    live: document.getElementById('live').className,
  };
})())"#;

fn summary(b: &mut Browser) -> Value {
    serde_json::from_str(b.eval(SUMMARY).as_str().unwrap()).unwrap()
}

/// What the job's flipbook shows, as JSON.
const FLIPBOOK: &str = r#"JSON.stringify((() => {
  const b = document.querySelector('.flipbook');
  const img = b.querySelector('.screen img');
  const pending = b.querySelector('.pending');
  return {
    frame: b.dataset.frame,
    caption: b.querySelector('.flip-frame').textContent,
    pending: pending.hidden ? null : pending.textContent,
    picture: img.hidden ? 0 : (img.complete ? img.naturalWidth : -1),
    last: Number(b.querySelector('input').max),
    playing: b.querySelector('button').textContent,
    video: b.querySelector('.video').hidden ? null : b.querySelector('.video').getAttribute('href'),
  };
})())"#;

fn flipbook(b: &mut Browser) -> Value {
    serde_json::from_str(b.eval(FLIPBOOK).as_str().unwrap()).unwrap()
}

/// Moves the flipbook's scrubber to the `index`th frame, as a drag would.
fn scrub(b: &mut Browser, index: u32) {
    b.eval(&format!(
        "(() => {{ const s = document.querySelector('.flipbook input'); s.value = {index}; \
         s.dispatchEvent(new Event('input')); return true; }})()"
    ));
}

/// The reason a worker gives for a failed attempt.
const REASON: &str = "preparing frame 1: texture 2 <img> cannot be decoded";

#[tokio::test(flavor = "multi_thread")]
async fn dashboard_shows_jobs_frames_failures_and_workers_live_in_chromium() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(config(dir.path()));
    let c = client();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let mut spec = JobSpec::new(scene.digest.clone());
    spec.name = Some("hallway".into());
    spec.frames = Some(FrameRange {
        start: 1,
        end: 2,
        step: 1,
    });
    (spec.width, spec.height, spec.tile_size, spec.spp) = (64, 48, Some(32), 4);
    spec.video = true;
    let job = create_job(&s, &c, &spec).await;
    let mut w = SimWorker::register(&s, "render-node-7").await;
    // One attempt fails, with a reason the page must show word for word (the task is
    // tried again: no other worker could take it).
    let first = w.lease(&s).await.unwrap();
    assert_eq!(w.fail(&s, &first, REASON).await.status(), StatusCode::OK);
    // Frame 1 done before the page loads; frame 2's tiles rendered but held back, their
    // leases live, so the worker has a current task.
    let mut held = vec![];
    while let Some(lease) = w.lease(&s).await {
        let (exr, _) = w.render(&s, &lease).await;
        if lease.frame == 1 {
            assert_eq!(w.upload(&s, &lease, exr).await.status(), StatusCode::OK);
        } else {
            held.push((lease, exr));
        }
    }
    assert_eq!(held.len(), 4);

    let url = format!("{}/", s.base);
    let (mut browser, before) = tokio::task::spawn_blocking(move || {
        let mut b = Browser::open(&url);
        b.wait_for("document.body.dataset.loaded === 'true' && document.getElementById('live').className === 'on'", "the loaded, live page");
        b.wait_for("document.querySelectorAll('.frames img').length === 1 && [...document.querySelectorAll('.frames img')].every(i => i.complete && i.naturalWidth > 0)", "the thumbnail");
        b.wait_for("document.querySelectorAll('.failures li').length === 1", "the failure");
        let before = summary(&mut b);
        // The flipbook: frame 1's preview, frame 2 said to be still rendering.
        b.wait_for("document.querySelector('.flipbook .screen img').naturalWidth === 64", "the flipbook's first frame");
        let first = flipbook(&mut b);
        scrub(&mut b, 1);
        let second = flipbook(&mut b);
        scrub(&mut b, 0);
        (b, (before, first, second))
    })
    .await
    .unwrap();
    let (before, first, second) = before;
    assert_eq!(
        (
            &first["frame"],
            &first["caption"],
            &first["picture"],
            &first["last"]
        ),
        (
            &json!("1"),
            &json!("frame 0001 · done"),
            &json!(64),
            &json!(1)
        ),
        "{first}"
    );
    assert_eq!(
        first["video"],
        json!(null),
        "no video before the frames are in"
    );
    assert_eq!(
        (&second["frame"], &second["pending"], &second["picture"]),
        (
            &json!("2"),
            &json!("frame 0002: not rendered yet (rendering)"),
            &json!(0)
        ),
        "{second}"
    );
    assert_eq!(before["state"], json!("running"), "{before}");
    assert_eq!(before["name"], json!(format!("#{} hallway", job.id)));
    assert_eq!(before["bar"], json!("50%"), "{before}");
    assert_eq!(
        before["frames"],
        json!([[1, "done"], [2, "rendering"]]),
        "{before}"
    );
    assert_eq!(
        before["failures"],
        json!([format!(
            "1 failed attempt(s) of 1 task(s) on render-node-7 (reported): {REASON}"
        )]),
        "{before}"
    );
    assert_eq!(before["thumbs"], json!([64]), "{before}");
    let worker = before["worker"].as_array().unwrap();
    assert_eq!(worker[0], json!("render-node-7"));
    assert_eq!(worker[1], json!("2"));
    assert!(
        worker[3]
            .as_str()
            .unwrap()
            .starts_with(&format!("job {} · frame 2", job.id)),
        "{before}"
    );
    assert!(
        before["stats"].as_str().unwrap().contains("frames 1/2"),
        "{before}"
    );

    // Finish the job while the page is open: only the event stream can tell it. Its
    // video comes from a worker with an encoder (a stand-in MP4: an `ftyp` box).
    for (lease, exr) in held {
        assert_eq!(w.upload(&s, &lease, exr).await.status(), StatusCode::OK);
    }
    let encoder = SimWorker::register_encoder(&s, "encoder", "FFmpeg with libx264").await;
    let encode = encoder.lease(&s).await.expect("the encode task");
    let mut mp4 = vec![0, 0, 0, 16];
    mp4.extend_from_slice(b"ftypisom\0\0\x02\0");
    let meta = proto::ResultMetadata {
        attempt: encode.token.attempt,
        sha256: server::store::sha256_hex(&mp4),
        samples: 0,
        rays: 0,
        render_ms: 5,
    };
    let res = encoder.upload_with(&s, &encode, mp4, &meta).await;
    assert_eq!(res.status(), StatusCode::OK);
    let results = tokio::task::spawn_blocking(move || {
        browser.wait_for("document.querySelector('.job').dataset.state === 'done'", "the job done");
        browser.wait_for("document.querySelectorAll('.frames img').length === 2 && [...document.querySelectorAll('.frames img')].every(i => i.complete && i.naturalWidth > 0)", "both thumbnails");
        browser.wait_for("document.querySelector('#workers tbody tr').children[3].textContent === 'idle'", "the worker idle");
        let after = summary(&mut browser);
        // The video is offered, and it plays: the frames follow each other at the job's fps.
        browser.wait_for("!document.querySelector('.flipbook .video').hidden", "the MP4 link");
        let book = flipbook(&mut browser);
        browser.eval("document.querySelector('.flipbook button').click()");
        browser.wait_for("document.querySelector('.flipbook').dataset.frame === '2'", "the flipbook playing on");
        browser.wait_for("document.querySelector('.flipbook').dataset.frame === '1'", "the flipbook looping");
        let playing = flipbook(&mut browser);
        browser.eval("document.querySelector('.flipbook button').click()");
        let fetched = browser.eval(
            "fetch(document.querySelector('.flipbook .video').href).then(r => r.status)",
        );
        (after, (book, playing, fetched), browser.screenshot())
    })
    .await
    .unwrap();
    let (after, (book, playing, fetched), png) = results;
    assert_eq!(
        book["video"],
        json!(format!("/api/v1/jobs/{}/video", job.id)),
        "{book}"
    );
    assert_eq!(playing["playing"], json!("Pause"), "{playing}");
    assert_eq!(fetched, json!(200));
    assert_eq!(after["bar"], json!("100%"), "{after}");
    assert_eq!(
        after["frames"],
        json!([[1, "done"], [2, "done"]]),
        "{after}"
    );
    assert_eq!(after["thumbs"], json!([64, 64]), "{after}");
    assert!(
        after["stats"].as_str().unwrap().contains("frames 2/2"),
        "{after}"
    );
    assert_eq!(after["worker"][4], json!("8"), "{after}");
    assert_eq!(after["live"], json!("on"));

    let shot = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("dashboard.png");
    std::fs::write(&shot, &png).unwrap();
    assert!(png.starts_with(b"\x89PNG"));
    eprintln!("dashboard screenshot: {}", shot.display());
}

const TOKEN: &str = "dashboard-client-token";

/// A client that sends the client token.
fn authed() -> reqwest::Client {
    let mut headers = reqwest::header::HeaderMap::new();
    headers.insert(
        reqwest::header::AUTHORIZATION,
        format!("Bearer {TOKEN}").parse().unwrap(),
    );
    reqwest::Client::builder()
        .default_headers(headers)
        .timeout(Duration::from_secs(60))
        .build()
        .unwrap()
}

/// Runs `script` in the page (a blocking DevTools call, off the async runtime).
async fn run(browser: Browser, script: &str) -> Browser {
    let script = script.to_string();
    tokio::task::spawn_blocking(move || {
        let mut b = browser;
        b.eval(&script);
        b
    })
    .await
    .unwrap()
}

/// Waits, off the async runtime, until `expr` is true in the page.
async fn page_shows(browser: Browser, expr: &str, what: &str) -> Browser {
    let (expr, what) = (expr.to_string(), what.to_string());
    tokio::task::spawn_blocking(move || {
        let mut b = browser;
        b.wait_for(&expr, &what);
        b
    })
    .await
    .unwrap()
}

/// Clicks a job card's control.
async fn click(browser: Browser, job: u64, action: &str) -> Browser {
    run(
        browser,
        &format!(
            "document.querySelector('.job[data-job-id=\"{job}\"] button[data-action=\"{action}\"]').click()"
        ),
    )
    .await
}

/// Polls the API until `check` holds for the job (or it is gone: `None`).
async fn api_shows(
    c: &reqwest::Client,
    s: &TestServer,
    job: u64,
    what: &str,
    check: impl Fn(Option<&proto::JobStatus>) -> bool,
) {
    let mut last = None;
    for _ in 0..300 {
        let res = c.get(s.url(&format!("/jobs/{job}"))).send().await.unwrap();
        let status = match res.status() {
            StatusCode::NOT_FOUND => None,
            _ => Some(res.json::<proto::JobStatus>().await.unwrap()),
        };
        if check(status.as_ref()) {
            return;
        }
        last = status;
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    panic!("the API never showed {what} for job {job}: {last:?}");
}

#[tokio::test(flavor = "multi_thread")]
async fn dashboard_controls_change_what_the_api_reports_in_chromium() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.client_token = Some(TOKEN.into());
    let s = TestServer::start(cfg);
    let c = authed();
    let scene = upload_scene(&s, &c, quad_scene()).await;
    let spec = |name: &str, frames: i32| {
        let mut spec = JobSpec::new(scene.digest.clone());
        spec.name = Some(name.into());
        spec.frames = Some(FrameRange {
            start: 1,
            end: frames,
            step: 1,
        });
        (spec.width, spec.height, spec.tile_size, spec.spp) = (16, 16, Some(16), 1);
        spec
    };
    // A job nobody renders (no worker asks), one whose task failed for good, and one of a
    // thousand frames; a hundred workers, one of them quarantined.
    let mut broken = spec("broken", 1);
    broken.max_attempts = 1;
    let broken = create_job(&s, &c, &broken).await.id;
    let open = create_job(&s, &c, &spec("open", 3)).await.id;
    let mut workers = Vec::new();
    for i in 0..100 {
        workers.push(SimWorker::register(&s, &format!("node-{i:03}")).await);
    }
    let lease = workers[0].lease(&s).await.unwrap();
    assert_eq!(lease.job_id, broken, "the older job goes first");
    workers[0].fail(&s, &lease, "out of memory").await;
    let long = create_job(&s, &c, &spec("long", 1000)).await.id;
    let quarantined = workers[1].id;
    rusqlite::Connection::open(dir.path().join("data/tessera.db"))
        .unwrap()
        .execute(
            "UPDATE workers SET quarantined_ms = 1, quarantine_reason = 'its tile of task 3 \
             differs' WHERE id = ?1",
            [quarantined],
        )
        .unwrap();

    // The page asks for the token, keeps it for the session only, and then shows the farm.
    let url = format!("{}/", s.base);
    let b = tokio::task::spawn_blocking(move || Browser::open(&url))
        .await
        .unwrap();
    let b = page_shows(
        b,
        "!document.getElementById('login').hidden",
        "the token prompt",
    )
    .await;
    let b = run(
        b,
        &format!(
            "document.getElementById('token-input').value = '{TOKEN}'; \
             document.getElementById('login').requestSubmit()"
        ),
    )
    .await;
    let b = page_shows(
        b,
        "document.body.dataset.loaded === 'true' && document.getElementById('live').className === 'on' \
         && document.querySelectorAll('#workers tbody tr').length === 100 \
         && sessionStorage.getItem('tessera-token') !== null && localStorage.length === 0",
        "the farm after signing in",
    )
    .await;
    // A thousand frames: the grid is made when opened, every frame in it.
    let b = run(
        b,
        &format!("document.querySelector('.job[data-job-id=\"{long}\"] details').open = true"),
    )
    .await;
    let mut b = page_shows(
        b,
        &format!(
            "document.querySelectorAll('.job[data-job-id=\"{long}\"] .frames figure[data-state=\"queued\"]').length === 1000"
        ),
        "the thousand frames",
    )
    .await;

    // Pause, resume, priority.
    b = click(b, open, "pause").await;
    api_shows(&c, &s, open, "paused", |j| {
        j.is_some_and(|j| j.state == proto::JobState::Paused)
    })
    .await;
    b = page_shows(
        b,
        &format!(
            "document.querySelector('.job[data-job-id=\"{open}\"]').dataset.state === 'paused'"
        ),
        "the paused job",
    )
    .await;
    b = click(b, open, "resume").await;
    api_shows(&c, &s, open, "resumed", |j| {
        j.is_some_and(|j| j.state == proto::JobState::Queued)
    })
    .await;
    b = run(
        b,
        &format!(
            "const input = document.querySelector('.job[data-job-id=\"{open}\"] .priority input'); \
             input.value = 7; input.dispatchEvent(new Event('input'))"
        ),
    )
    .await;
    b = click(b, open, "priority").await;
    api_shows(&c, &s, open, "priority 7", |j| {
        j.is_some_and(|j| j.spec.priority == 7)
    })
    .await;

    // Clone: a new job with the same settings (once the page knows the new priority).
    b = page_shows(
        b,
        &format!("document.querySelector('.job[data-job-id=\"{open}\"] .priority input').value === '7' && !document.querySelector('.job[data-job-id=\"{open}\"] .priority input').dataset.edited"),
        "the new priority",
    )
    .await;
    b = click(b, open, "clone").await;
    let clone = loop {
        let list: proto::JobList = c
            .get(s.url("/jobs"))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        if let Some(j) = list.jobs.iter().find(|j| j.id > long) {
            break j.clone();
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(
        (clone.spec.frames, clone.spec.priority),
        (
            Some(FrameRange {
                start: 1,
                end: 3,
                step: 1
            }),
            7
        )
    );
    assert_eq!(clone.name, format!("job {}", clone.id));

    // Watch, then cancel: the browser says the watched job ended.
    b = run(
        b,
        "window.told = []; window.Notification = class { constructor(t) { told.push(t); } \
         static requestPermission() { return Promise.resolve('granted'); } }; \
         Notification.permission = 'granted'; window.confirm = () => true;",
    )
    .await;
    b = click(b, open, "watch").await;
    b = click(b, open, "cancel").await;
    api_shows(&c, &s, open, "cancelled", |j| {
        j.is_some_and(|j| j.state == proto::JobState::Cancelled)
    })
    .await;
    b = page_shows(
        b,
        &format!("window.told.length === 1 && window.told[0] === 'Tessera: job #{open} open is cancelled'"),
        "the notification",
    )
    .await;

    // Retry the failed job; delete the clone.
    b = click(b, broken, "retry").await;
    api_shows(&c, &s, broken, "retried", |j| {
        j.is_some_and(|j| j.tasks.failed == 0 && j.state == proto::JobState::Queued)
    })
    .await;
    b = click(b, clone.id, "delete").await;
    api_shows(&c, &s, clone.id, "deleted", |j| j.is_none()).await;
    b = page_shows(
        b,
        &format!(
            "!document.querySelector('.job[data-job-id=\"{}\"]')",
            clone.id
        ),
        "the deleted job gone",
    )
    .await;

    // Clear the quarantined worker.
    b = page_shows(
        b,
        &format!("document.querySelector('tr[data-worker-id=\"{quarantined}\"]').children[8].textContent.startsWith('quarantined: its tile of task 3 differs')"),
        "the quarantined worker",
    )
    .await;
    b = run(
        b,
        &format!("document.querySelector('tr[data-worker-id=\"{quarantined}\"] button[data-action=\"clear\"]').click()"),
    )
    .await;
    for _ in 0..300 {
        let list: proto::WorkerList = c
            .get(s.url("/workers"))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        if list
            .workers
            .iter()
            .any(|w| w.id == quarantined && w.quarantined.is_none())
        {
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let b = page_shows(
        b,
        &format!("document.querySelector('tr[data-worker-id=\"{quarantined}\"]').children[8].textContent.startsWith('ok')"),
        "the cleared worker",
    )
    .await;
    let error = run(b, "")
        .await
        .eval("document.getElementById('error').hidden");
    assert_eq!(error, json!(true), "the page showed an error");
}
