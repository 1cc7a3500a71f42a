//! Plain HTTP/1.1 over a `TcpStream`, for requests no well-behaved client sends: a rogue
//! worker's uploads, a body cut short. One request per connection (`Connection: close`),
//! and the answer is read as the server wrote it.

use std::io::{Read, Write};
use std::net::{Shutdown, TcpStream};
use std::time::Duration;

use serde::de::DeserializeOwned;

/// How long a test waits for an answer before calling the server hung.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(60);

/// A request to `127.0.0.1:port`.
pub struct Request<'a> {
    /// `GET`, `POST`, ...
    pub method: &'a str,
    /// The path with its query, `/api/v1/...`.
    pub path: &'a str,
    /// Header lines besides `Host`, `Content-Length` and `Connection`.
    pub headers: Vec<(String, String)>,
    /// The body.
    pub body: &'a [u8],
}

/// What the server answered.
#[derive(Debug)]
pub struct Answer {
    /// The status code; 0 when the connection closed without an answer.
    pub status: u16,
    /// The body (de-chunked).
    pub body: Vec<u8>,
}

impl Answer {
    /// The body as text.
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }

    /// The body as JSON of type `T`; panics naming the body when it is not.
    pub fn json<T: DeserializeOwned>(&self) -> T {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|e| panic!("answer {}: {e}: {}", self.status, self.text()))
    }

    /// The body as the server's JSON error.
    pub fn error(&self) -> proto::ErrorBody {
        self.json()
    }
}

/// `GET path` without credentials, as a probe or a Prometheus scrape sends it.
pub fn get(port: u16, path: &str) -> Answer {
    Request {
        method: "GET",
        path,
        headers: vec![],
        body: b"",
    }
    .send(port)
}

impl Request<'_> {
    /// Sends the request and reads the answer.
    pub fn send(&self, port: u16) -> Answer {
        self.exchange(port, self.body.len())
    }

    /// Announces `Content-Length: claimed` but sends only the body, then closes the
    /// sending half of the connection, as a worker that dies mid-upload does; returns
    /// whatever the server answers.
    pub fn send_cut_short(&self, port: u16, claimed: usize) -> Answer {
        assert!(
            claimed > self.body.len(),
            "a cut-short body claims more than it has"
        );
        self.exchange(port, claimed)
    }

    /// Sends the request whole and returns the open connection without waiting for the
    /// answer: for a request whose handling the test interrupts (a server killed while it
    /// works on it).
    pub fn send_unanswered(&self, port: u16) -> TcpStream {
        let mut stream = self.send_head(port, self.body.len());
        stream.write_all(self.body).expect("sending the body");
        stream
    }

    /// Connects and sends the request line and headers.
    fn send_head(&self, port: u16, content_length: usize) -> TcpStream {
        let mut stream = TcpStream::connect(("127.0.0.1", port)).expect("connecting");
        stream.set_read_timeout(Some(ANSWER_TIMEOUT)).unwrap();
        let mut head = format!(
            "{} {} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\n\
             Content-Length: {content_length}\r\n",
            self.method, self.path
        );
        for (name, value) in &self.headers {
            head += &format!("{name}: {value}\r\n");
        }
        head += "\r\n";
        stream.write_all(head.as_bytes()).expect("sending the head");
        stream
    }

    fn exchange(&self, port: u16, content_length: usize) -> Answer {
        let mut stream = self.send_head(port, content_length);
        // The server may answer (413) and close before it has read everything: a failed
        // write is then not the test's failure; the answer says what happened.
        let _ = stream.write_all(self.body);
        if content_length > self.body.len() {
            let _ = stream.shutdown(Shutdown::Write);
        }
        let mut raw = Vec::new();
        // An error after some bytes (a reset once the answer is in) keeps what was read.
        if let Err(e) = stream.read_to_end(&mut raw) {
            assert!(
                !raw.is_empty() || e.kind() == std::io::ErrorKind::ConnectionReset,
                "reading the answer to {} {}: {e}",
                self.method,
                self.path
            );
        }
        parse(&raw)
    }
}

/// Splits a raw answer into status and body.
fn parse(raw: &[u8]) -> Answer {
    let Some(end) = raw.windows(4).position(|w| w == b"\r\n\r\n") else {
        return Answer {
            status: 0,
            body: raw.to_vec(),
        };
    };
    let head = String::from_utf8_lossy(&raw[..end]);
    let mut lines = head.split("\r\n");
    let status = lines
        .next()
        .and_then(|l| l.split(' ').nth(1))
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("not an HTTP answer: {head}"));
    let chunked = lines.any(|l| {
        let l = l.to_ascii_lowercase();
        l.starts_with("transfer-encoding:") && l.contains("chunked")
    });
    let rest = &raw[end + 4..];
    let body = if chunked {
        dechunk(rest)
    } else {
        rest.to_vec()
    };
    Answer { status, body }
}

/// The data of a chunked body.
fn dechunk(mut rest: &[u8]) -> Vec<u8> {
    let mut body = Vec::new();
    while let Some(eol) = rest.windows(2).position(|w| w == b"\r\n") {
        let size = String::from_utf8_lossy(&rest[..eol]);
        let size = size.split(';').next().unwrap_or("").trim();
        let size = usize::from_str_radix(size, 16).expect("a chunk size");
        rest = &rest[eol + 2..];
        if size == 0 || rest.len() < size {
            break;
        }
        body.extend_from_slice(&rest[..size]);
        rest = rest.get(size + 2..).unwrap_or_default();
    }
    body
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn answers_parse_plain_and_chunked() {
        let a = parse(b"HTTP/1.1 422 Unprocessable Entity\r\ncontent-length: 2\r\n\r\n{}");
        assert_eq!((a.status, a.text().as_str()), (422, "{}"));
        let a = parse(
            b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n3\r\nabc\r\n2\r\nde\r\n0\r\n\r\n",
        );
        assert_eq!((a.status, a.text().as_str()), (200, "abcde"));
        assert_eq!(parse(b"").status, 0);
    }
}
