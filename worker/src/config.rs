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
    /// A name for people: shown in `GET /workers` and the dashboard.
    pub name: String,
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
            name: "w".into(),
        }
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
