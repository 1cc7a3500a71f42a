//! A shot is done and somebody is told: a real `tessera server --webhook URL
//! --webhook-secret KEY` posts a signed notification to a receiver on loopback when the
//! job ends, and tries again when the receiver first fails.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpListener;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use hmac::{Hmac, Mac};
use proto::{JobState, Notification, NotificationKind};
use tests::{settings, Farm};

const KEY: &str = "e2e-webhook-key";

/// One request a receiver got: its headers (lower-case names) and body.
#[derive(Clone, Debug)]
struct Delivery {
    headers: Vec<(String, String)>,
    body: Vec<u8>,
}

impl Delivery {
    fn header(&self, name: &str) -> &str {
        self.headers
            .iter()
            .find(|(n, _)| n == name)
            .map_or("", |(_, v)| v.as_str())
    }
}

/// A receiver on loopback answering 500 to its first `failures` requests, then 204.
fn receiver(failures: usize) -> (String, Arc<Mutex<Vec<Delivery>>>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}/done", listener.local_addr().unwrap());
    let got: Arc<Mutex<Vec<Delivery>>> = Arc::default();
    let seen = got.clone();
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut stream) = stream else { continue };
            let mut reader = BufReader::new(stream.try_clone().unwrap());
            let mut headers = Vec::new();
            let mut line = String::new();
            reader.read_line(&mut line).unwrap();
            loop {
                line.clear();
                reader.read_line(&mut line).unwrap();
                let Some((name, value)) = line.trim_end().split_once(':') else {
                    break;
                };
                headers.push((name.to_lowercase(), value.trim().to_string()));
            }
            let length: usize = headers
                .iter()
                .find(|(n, _)| n == "content-length")
                .map_or(0, |(_, v)| v.parse().unwrap());
            let mut body = vec![0; length];
            reader.read_exact(&mut body).unwrap();
            let n = {
                let mut seen = seen.lock().unwrap();
                seen.push(Delivery { headers, body });
                seen.len()
            };
            let status = if n <= failures {
                "500 Internal Server Error"
            } else {
                "204 No Content"
            };
            let _ = write!(
                stream,
                "HTTP/1.1 {status}\r\ncontent-length: 0\r\nconnection: close\r\n\r\n"
            );
        }
    });
    (url, got)
}

#[test]
fn a_real_server_tells_a_webhook_when_a_job_is_done_signed_and_again_after_a_failure() {
    let (url, got) = receiver(1);
    let mut farm = Farm::new();
    farm.start_server_with(60, &["--webhook", &url, "--webhook-secret", KEY]);
    farm.start_worker("w", 2);
    let scene = farm.demo_scene();
    let mut args = vec![scene.to_str().unwrap(), "--frames", "1"];
    args.extend(settings("1"));
    let job = farm.submit(&args);
    assert_eq!(
        farm.wait_for_job(job, Duration::from_secs(120)).state,
        JobState::Done
    );
    tests::wait_until(
        "the delivery and its retry",
        Duration::from_secs(30),
        || got.lock().unwrap().len() >= 2,
        || farm.logs(),
    );
    let got = got.lock().unwrap().clone();
    assert_eq!(
        got[0].body, got[1].body,
        "the retry repeats the notification"
    );
    let mut mac = Hmac::<sha2::Sha256>::new_from_slice(KEY.as_bytes()).unwrap();
    mac.update(&got[1].body);
    let hex: String = mac
        .finalize()
        .into_bytes()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    assert_eq!(
        got[1].header(Notification::SIGNATURE),
        format!("sha256={hex}")
    );
    let told: Notification = serde_json::from_slice(&got[1].body).unwrap();
    assert_eq!(got[1].header(Notification::DELIVERY), told.id.to_string());
    assert_eq!(told.event, NotificationKind::JobDone);
    assert_eq!(told.job.unwrap().id, job);

    // Without a key the server refuses to start rather than send unsigned notifications.
    let out = tests::tessera(&["server", "--webhook", &url], farm.path());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--webhook needs --webhook-secret"),
        "{err}"
    );
}
