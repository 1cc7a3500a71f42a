//! What a worker needs to know: where the server is, how to prove who it is, how many
//! threads to render with, where to cache scenes, and what to be called.

use std::path::PathBuf;

/// Settings of one worker daemon.
#[derive(Clone, Debug)]
pub struct WorkerConfig {
    /// The server's base URL, like `http://127.0.0.1:8700` (the `/api/v1` prefix is
    /// added; a URL that already ends in it is used as it is).
    pub server: String,
    /// Bearer token for the worker routes, when the server requires one.
    pub token: Option<String>,
    /// Render threads (the rayon pool's size); at least 1.
    pub threads: usize,
    /// Folder for downloaded scenes (`<digest>.glb`), created when missing.
    pub cache_dir: PathBuf,
    /// Most bytes of scenes the folder keeps: the least recently used go first.
    pub cache_limit_bytes: u64,
    /// A name for people: shown in `GET /workers` and the dashboard.
    pub name: String,
    /// A fault to inject, for testing how the farm copes with a bad worker; `None` for
    /// every real worker.
    pub fault: Option<Fault>,
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

#[cfg(test)]
mod tests {
    use super::*;

    fn config(server: &str) -> WorkerConfig {
        WorkerConfig {
            server: server.into(),
            token: None,
            threads: 1,
            cache_dir: PathBuf::from("cache"),
            cache_limit_bytes: u64::MAX,
            name: "w".into(),
            fault: None,
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
    fn api_base_adds_the_prefix_once() {
        assert_eq!(config("http://h:8700").api_base(), "http://h:8700/api/v1");
        assert_eq!(config("http://h:8700/").api_base(), "http://h:8700/api/v1");
        assert_eq!(
            config("http://h:8700/api/v1/").api_base(),
            "http://h:8700/api/v1"
        );
    }
}
