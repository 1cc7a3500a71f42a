//! Settings of the long-running commands (`tessera server`, `tessera worker`, `tessera
//! scale`) in layers:
//! a flag beats its `TESSERA_*` variable, which beats the `--config` file, which beats the
//! built-in default. This module is the one place that knows it.
//!
//! The layering is clap's own (flag > env > default) with the file slid in as the default:
//! each value read from the file becomes its flag's default before the command line is
//! parsed for good. So a value from the file goes through the flag's own parser and checks
//! (ranges, fractions), and nothing is repeated per flag.
//!
//! The file is TOML, one table per command, the keys the long flags with `_` for `-`:
//!
//! ```toml
//! [server]
//! listen = "0.0.0.0:8700"
//! lease_seconds = 120
//!
//! [worker]
//! server = "http://farm.example:8700"
//! threads = 8
//! ```
//!
//! A command is configurable when it has the [`Common`] flags; its settable keys are its
//! visible flags that take a value. An empty `TESSERA_*` variable counts as unset.

use std::collections::BTreeSet;
use std::ffi::OsString;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context};
use clap::parser::ValueSource;
use clap::{Arg, ArgMatches, Args, Command, Parser};
use serde::Serialize;

use crate::logs::LogFormat;

/// The id of the `--config` flag; a command that has it is configurable.
const CONFIG: &str = "config";

/// Flags every configurable command has.
#[derive(Args, Clone, Debug, Serialize)]
pub struct Common {
    /// A TOML file of settings: [server], [worker] and [scale] tables whose keys are the
    /// long flags with `_` for `-` (`lease_seconds = 120`). Flags and TESSERA_* variables
    /// override it. No file is read unless one is named (a system-wide install would keep
    /// it in /etc/tessera/tessera.toml).
    #[arg(long, env = "TESSERA_CONFIG", value_name = "FILE")]
    #[serde(skip)]
    pub config: Option<PathBuf>,
    /// Print the effective settings as TOML, each with where it came from (tokens as
    /// "***"), and exit.
    #[arg(long)]
    #[serde(skip)]
    pub print_config: bool,
    /// How log lines are written.
    #[arg(long, env = "TESSERA_LOG_FORMAT", value_enum, default_value_t = LogFormat::Human)]
    pub log_format: LogFormat,
}

/// Where a setting's value came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Source {
    /// `--flag` on the command line.
    Flag(String),
    /// A `TESSERA_*` environment variable.
    Env(String),
    /// The `--config` file.
    File(PathBuf),
    /// The built-in default (or one worked out at start, like the worker's threads).
    Default,
}

/// The chosen command's settings: how it was parsed, and which keys the file gave.
#[derive(Clone, Debug, Default)]
pub struct Layers {
    /// The subcommand and its matches (`None` for a command line without one).
    parsed: Option<(Command, ArgMatches)>,
    /// The `--config` file, when one was read.
    file: Option<PathBuf>,
    /// The keys whose value the file gave (flags and env overrode the others).
    from_file: BTreeSet<String>,
    /// The settable keys in `--help` order (giving an argument a default moves it last).
    keys: Vec<String>,
}

/// [`parse_from`] on this process's arguments; a command-line error (or `--help`) prints
/// and exits as clap does.
pub fn parse<C: Parser>() -> anyhow::Result<(C, Layers)> {
    parse_from(std::env::args_os()).map_err(|e| match e.downcast::<clap::Error>() {
        Ok(e) => e.exit(),
        Err(e) => e,
    })
}

/// Parses `argv` (program name first) into `C`, with the subcommand's `--config` file
/// layered under its flags and variables. Errors: clap's (as a `clap::Error` inside the
/// `anyhow::Error`), a file that cannot be read, an unknown table or key (named with the
/// file), a value the flag's parser refuses.
pub fn parse_from<C, I, T>(argv: I) -> anyhow::Result<(C, Layers)>
where
    C: Parser,
    I: IntoIterator<Item = T>,
    T: Into<OsString>,
{
    let argv: Vec<OsString> = argv.into_iter().map(Into::into).collect();
    let mut cmd = C::command().mut_subcommands(|sc| sc.mut_args(unset_if_empty));
    let first = cmd.clone().try_get_matches_from(&argv)?;
    let Some((name, sub)) = first.subcommand() else {
        return Ok((C::from_arg_matches(&first)?, Layers::default()));
    };
    let name = name.to_string();
    let keys = settable(cmd.find_subcommand(&name).expect("parsed subcommand"))
        .map(|a| a.get_id().to_string())
        .collect();
    let file = sub.try_get_one::<PathBuf>(CONFIG).ok().flatten().cloned();
    let mut from_file = BTreeSet::new();
    if let Some(path) = &file {
        let table = read_file(path, &cmd)?;
        let section = table.get(&name).and_then(|s| s.as_table());
        for (key, value) in section.into_iter().flatten() {
            let at = || format!("config file {}: [{name}] {key}", path.display());
            let text = arg_text(value).with_context(at)?;
            let arg = settable(cmd.find_subcommand(&name).expect("parsed subcommand"))
                .find(|a| a.get_id() == key)
                .expect("read_file checked the key");
            check(arg, &text).with_context(at)?;
            cmd = cmd.mut_subcommand(&name, |sc| sc.mut_arg(key, |a| a.default_value(text)));
            from_file.insert(key.clone());
        }
    }
    let matches = cmd.clone().try_get_matches_from(&argv)?;
    let cli = C::from_arg_matches(&matches)?;
    let sub_cmd = cmd
        .find_subcommand(&name)
        .expect("parsed subcommand")
        .clone();
    let sub_matches = matches
        .subcommand_matches(&name)
        .expect("parsed subcommand")
        .clone();
    Ok((
        cli,
        Layers {
            parsed: Some((sub_cmd, sub_matches)),
            file,
            from_file,
            keys,
        },
    ))
}

impl Layers {
    /// Where setting `id` (an argument id: the long flag with `_`) came from.
    pub fn source(&self, id: &str) -> Source {
        let Some((cmd, matches)) = &self.parsed else {
            return Source::Default;
        };
        let arg = cmd.get_arguments().find(|a| a.get_id() == id);
        match matches.value_source(id) {
            Some(ValueSource::CommandLine) => {
                Source::Flag(format!("--{}", arg.and_then(Arg::get_long).unwrap_or(id)))
            }
            Some(ValueSource::EnvVariable) => Source::Env(
                arg.and_then(Arg::get_env)
                    .map(|e| e.to_string_lossy().into_owned())
                    .unwrap_or_default(),
            ),
            Some(ValueSource::DefaultValue) if self.from_file.contains(id) => {
                Source::File(self.file.clone().unwrap_or_default())
            }
            _ => Source::Default,
        }
    }

    /// The effective settings `values` (serialized with the argument ids as keys) as a
    /// TOML document: one `[command]` table, a key per settable flag in `--help` order with
    /// its source as a comment, secrets (flags whose variable `--help` hides) as `"***"`,
    /// unset ones as comments.
    pub fn to_toml(&self, values: &impl Serialize) -> anyhow::Result<String> {
        let Some((cmd, _)) = &self.parsed else {
            bail!("no command to print the settings of");
        };
        let values = toml::Table::try_from(values).context("writing the settings as TOML")?;
        let mut out = format!(
            "# The settings of `tessera {0}`: a flag beats its TESSERA_* variable, which beats\n\
             # the --config file, which beats the default.\n[{0}]\n",
            cmd.get_name()
        );
        for id in &self.keys {
            let id = id.as_str();
            let arg = settable(cmd)
                .find(|a| a.get_id() == id)
                .expect("keys are settable");
            let source = match self.source(id) {
                Source::Flag(flag) => format!("from flag {flag}"),
                Source::Env(var) => format!("from env {var}"),
                Source::File(path) => format!("from file {}", path.display()),
                Source::Default => "default".into(),
            };
            let source = source.replace(['\n', '\r'], " ");
            match values.get(id) {
                Some(_) if arg.is_hide_env_values_set() => {
                    writeln!(out, "{id} = \"***\"  # {source}")?
                }
                Some(value) => writeln!(out, "{id} = {value}  # {source}")?,
                None => writeln!(out, "# {id}: not set")?,
            }
        }
        Ok(out)
    }
}

/// An argument whose variable is set but empty, as if the variable were unset.
fn unset_if_empty(arg: Arg) -> Arg {
    let empty = arg
        .get_env()
        .and_then(std::env::var_os)
        .is_some_and(|v| v.is_empty());
    if empty {
        arg.env(None::<&'static str>)
    } else {
        arg
    }
}

/// The flags of `cmd` the file may set: visible ones that take a value, but `--config` (and
/// not positional arguments: `scale`'s engine is named on the command line).
fn settable(cmd: &Command) -> impl Iterator<Item = &Arg> {
    cmd.get_arguments().filter(|a| {
        a.get_action().takes_values()
            && !a.is_hide_set()
            && !a.is_positional()
            && a.get_id() != CONFIG
    })
}

/// The configurable subcommands of `cmd`.
fn configurable(cmd: &Command) -> impl Iterator<Item = &Command> {
    cmd.get_subcommands()
        .filter(|sc| sc.get_arguments().any(|a| a.get_id() == CONFIG))
}

/// Reads the config file and checks every table and key in it (not only the chosen
/// command's: one file usually serves both, and a typo should not wait for the other).
fn read_file(path: &Path, cmd: &Command) -> anyhow::Result<toml::Table> {
    let shown = path.display();
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading the config file {shown}"))?;
    let table: toml::Table = text
        .parse()
        .with_context(|| format!("config file {shown} is not valid TOML"))?;
    let commands: Vec<&str> = configurable(cmd).map(Command::get_name).collect();
    for (section, value) in &table {
        let Some(sc) = configurable(cmd).find(|sc| sc.get_name() == section) else {
            bail!(
                "config file {shown}: unknown key `{section}` (expected the tables {})",
                commands
                    .iter()
                    .map(|c| format!("[{c}]"))
                    .collect::<Vec<_>>()
                    .join(" and ")
            );
        };
        let Some(keys) = value.as_table() else {
            bail!("config file {shown}: `{section}` must be a table ([{section}])");
        };
        for key in keys.keys() {
            if !settable(sc).any(|a| a.get_id() == key) {
                let known: Vec<&str> = settable(sc).map(|a| a.get_id().as_str()).collect();
                bail!(
                    "config file {shown}: unknown key `{key}` in [{section}] (known: {})",
                    known.join(", ")
                );
            }
        }
    }
    Ok(table)
}

/// A TOML value as the text its flag would be given.
fn arg_text(value: &toml::Value) -> anyhow::Result<String> {
    Ok(match value {
        toml::Value::String(s) => s.clone(),
        toml::Value::Integer(i) => i.to_string(),
        toml::Value::Float(f) => f.to_string(),
        toml::Value::Boolean(b) => b.to_string(),
        // A list flag (`tags = ["gpu", "fast"]`) takes its values comma-separated.
        toml::Value::Array(items) => items
            .iter()
            .map(arg_text)
            .collect::<anyhow::Result<Vec<_>>>()?
            .join(","),
        other => bail!("expected a string or a number, found {}", other.type_str()),
    })
}

/// Runs `text` through `arg`'s own parser, so a bad value in the file is refused with the
/// file named (as the default it would be refused only later, naming the flag alone).
fn check(arg: &Arg, text: &str) -> anyhow::Result<()> {
    let flag = format!(
        "--{}={text}",
        arg.get_long().unwrap_or(arg.get_id().as_str())
    );
    Command::new("config")
        .no_binary_name(true)
        .arg(arg.clone().env(None::<&'static str>))
        .try_get_matches_from([flag])
        .map(drop)
        .map_err(|e| {
            let e = e.to_string();
            let line = e.lines().next().unwrap_or_default();
            anyhow!("{}", line.trim_start_matches("error: "))
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;
    use std::sync::Mutex;

    /// Tests that set `TESSERA_*` variables take turns (the environment is per process).
    static ENV: Mutex<()> = Mutex::new(());

    #[derive(Parser, Debug)]
    struct Cli {
        #[command(subcommand)]
        command: Sub,
    }

    #[derive(clap::Subcommand, Debug)]
    enum Sub {
        Server(crate::server::ServerArgs),
        Worker(crate::worker::WorkerArgs),
    }

    fn server(argv: &[&str]) -> anyhow::Result<(crate::server::ServerArgs, Layers)> {
        let argv = ["tessera", "server"].iter().chain(argv);
        let (cli, layers) = parse_from::<Cli, _, _>(argv)?;
        match cli.command {
            Sub::Server(args) => Ok((args, layers)),
            Sub::Worker(_) => unreachable!(),
        }
    }

    fn worker(argv: &[&str]) -> anyhow::Result<crate::worker::WorkerArgs> {
        let argv = ["tessera", "worker"].iter().chain(argv);
        let (cli, _) = parse_from::<Cli, _, _>(argv)?;
        match cli.command {
            Sub::Worker(args) => Ok(args),
            Sub::Server(_) => unreachable!(),
        }
    }

    #[test]
    fn a_list_setting_comes_from_a_toml_array_a_variable_or_the_flag() {
        let dir = tempfile::tempdir().unwrap();
        let file = config_file(dir.path(), "[worker]\ntags = [\"gpu\", \"studio-a\"]\n");
        let args = worker(&["--config", &file]).unwrap();
        assert_eq!(args.tags, ["gpu", "studio-a"]);
        let args = with_env(&[("TESSERA_TAGS", "fast,big")], || worker(&[]).unwrap());
        assert_eq!(args.tags, ["fast", "big"]);
        assert_eq!(worker(&["--tags", "a,b"]).unwrap().tags, ["a", "b"]);
    }

    fn config_file(dir: &Path, text: &str) -> String {
        let path = dir.join("tessera.toml");
        std::fs::write(&path, text).unwrap();
        path.to_str().unwrap().to_string()
    }

    /// Sets `vars` for the duration of `f`, one test at a time.
    fn with_env<R>(vars: &[(&str, &str)], f: impl FnOnce() -> R) -> R {
        let _turn = ENV.lock().unwrap_or_else(|p| p.into_inner());
        for (k, v) in vars {
            std::env::set_var(k, v);
        }
        let r = f();
        for (k, _) in vars {
            std::env::remove_var(k);
        }
        r
    }

    const FILE: &str = r#"
        [server]
        listen = "127.0.0.1:9001"
        data = "/from/file"
        lease_seconds = 30
        verify_fraction = 0.25
        client_token = "file-secret"

        [worker]
        threads = 3
    "#;

    #[test]
    fn a_flag_beats_env_beats_the_file_beats_the_default() {
        let dir = tempfile::tempdir().unwrap();
        let file = config_file(dir.path(), FILE);
        let vars = [
            ("TESSERA_DATA", "/from/env"),
            ("TESSERA_LEASE_SECONDS", "40"),
            ("TESSERA_WORKER_TOKEN", "env-secret"),
        ];
        let (args, layers) = with_env(&vars, || {
            server(&["--config", &file, "--lease-seconds", "50"]).unwrap()
        });
        // Number: flag over env over file.
        assert_eq!(args.lease_seconds, 50);
        assert_eq!(
            layers.source("lease_seconds"),
            Source::Flag("--lease-seconds".into())
        );
        // Path: env over file.
        assert_eq!(args.data, PathBuf::from("/from/env"));
        assert_eq!(layers.source("data"), Source::Env("TESSERA_DATA".into()));
        // String (an address) and a fraction: the file over the default.
        assert_eq!(args.listen.to_string(), "127.0.0.1:9001");
        assert_eq!(args.verify_fraction, 0.25);
        assert_eq!(layers.source("listen"), Source::File(file.clone().into()));
        // Optional tokens: one from env, one from the file; the default stays.
        assert_eq!(args.worker_token.as_deref(), Some("env-secret"));
        assert_eq!(args.client_token.as_deref(), Some("file-secret"));
        assert_eq!(
            args.max_tasks_per_job,
            server::limits::DEFAULT_MAX_TASKS_PER_JOB
        );
        assert_eq!(layers.source("max_tasks_per_job"), Source::Default);

        // Without the file, the env and the defaults.
        let (args, _) = with_env(&vars, || server(&[]).unwrap());
        assert_eq!((args.lease_seconds, args.listen.port()), (40, 8700));
        assert_eq!(args.client_token, None);
    }

    #[test]
    fn an_empty_variable_counts_as_unset() {
        let (args, layers) = with_env(&[("TESSERA_WORKER_TOKEN", "")], || server(&[]).unwrap());
        assert_eq!(args.worker_token, None);
        assert_eq!(layers.source("worker_token"), Source::Default);
    }

    #[test]
    fn unknown_keys_and_bad_values_in_the_file_are_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let error = |text: &str| {
            let file = config_file(dir.path(), text);
            let e = server(&["--config", &file]).unwrap_err();
            let message = format!("{e:#}");
            assert!(message.contains(&file), "{message}");
            message
        };
        let m = error("[server]\nlease_second = 30\n");
        assert!(m.contains("unknown key `lease_second` in [server]"), "{m}");
        // The other command's table is checked too.
        let m = error("[worker]\nthread = 2\n");
        assert!(m.contains("unknown key `thread` in [worker]"), "{m}");
        let m = error("[client]\nserver = \"x\"\n");
        assert!(m.contains("unknown key `client`"), "{m}");
        // Hidden test-only flags and --config itself are not settings.
        let m = error("[worker]\ninject_fault = \"perturb\"\n");
        assert!(m.contains("unknown key `inject_fault`"), "{m}");
        let m = error("[server]\nlease_seconds = 3\n");
        assert!(
            m.contains("[server] lease_seconds") && m.contains("5..=86400"),
            "{m}"
        );
        let m = error("[server]\nlisten = { port = 1 }\n");
        assert!(m.contains("expected a string or a number"), "{m}");
        let m = error("[server\n");
        assert!(m.contains("not valid TOML"), "{m}");

        let missing = dir.path().join("missing.toml");
        let e = server(&["--config", missing.to_str().unwrap()]).unwrap_err();
        assert!(format!("{e:#}").contains("missing.toml"), "{e:#}");
    }

    #[test]
    fn print_config_is_toml_of_the_effective_values_with_tokens_masked() {
        let dir = tempfile::tempdir().unwrap();
        let file = config_file(dir.path(), FILE);
        let (args, layers) = with_env(&[("TESSERA_LOG_FORMAT", "json")], || {
            server(&["--config", &file, "--max-tile-bytes", "1000"]).unwrap()
        });
        let text = layers.to_toml(&args).unwrap();
        let doc: toml::Table = text.parse().unwrap_or_else(|e| panic!("{e}\n{text}"));
        let s = doc["server"].as_table().unwrap();
        assert_eq!(s["listen"].as_str(), Some("127.0.0.1:9001"));
        assert_eq!(s["data"].as_str(), Some("/from/file"));
        assert_eq!(s["lease_seconds"].as_integer(), Some(30));
        assert_eq!(s["verify_fraction"].as_float(), Some(0.25));
        assert_eq!(s["max_tile_bytes"].as_integer(), Some(1000));
        assert_eq!(s["log_format"].as_str(), Some("json"));
        assert_eq!(s["client_token"].as_str(), Some("***"));
        assert!(!text.contains("file-secret"), "{text}");
        assert!(!s.contains_key("worker_token"), "{text}");
        assert!(text.contains("# worker_token: not set"), "{text}");
        assert!(!s.contains_key("config") && !s.contains_key("print_config"));
        // In --help order, file or not.
        let at = |k: &str| text.find(&format!("\n{k} = ")).unwrap();
        assert!(
            at("listen") < at("data") && at("data") < at("lease_seconds"),
            "{text}"
        );
        // Each value says where it came from.
        for line in [
            format!("lease_seconds = 30  # from file {file}"),
            "max_tile_bytes = 1000  # from flag --max-tile-bytes".into(),
            "log_format = \"json\"  # from env TESSERA_LOG_FORMAT".into(),
        ] {
            assert!(text.contains(&line), "{line}\n{text}");
        }
    }

    #[test]
    fn every_setting_has_its_tessera_variable() {
        let cmd = Cli::command();
        let mut seen = 0;
        for sc in configurable(&cmd) {
            for arg in settable(sc) {
                let id = arg.get_id().as_str();
                // The worker's --token is the server's --worker-token.
                let expected = match (sc.get_name(), id) {
                    ("worker", "token") => "TESSERA_WORKER_TOKEN".to_string(),
                    _ => format!("TESSERA_{}", id.to_uppercase()),
                };
                let env = arg.get_env().map(|e| e.to_string_lossy().into_owned());
                assert_eq!(env.as_deref(), Some(expected.as_str()), "{id}");
                seen += 1;
            }
            let config = sc.get_arguments().find(|a| a.get_id() == CONFIG).unwrap();
            assert_eq!(config.get_env().unwrap(), "TESSERA_CONFIG");
        }
        assert_eq!(seen, 16 + 14);
    }
}
