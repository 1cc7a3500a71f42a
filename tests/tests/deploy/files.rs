//! Readers for deploy/'s files (compose and Kubernetes YAML, systemd units and
//! environment files, the Dockerfile) and for what the binary says of itself (`--help`,
//! `--print-config`), so that deploy.rs can hold the checks alone.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use tests::tessera_bin;
use yaml_rust2::{Yaml, YamlLoader};

/// The repository's deploy/ folder.
pub fn deploy_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ lies in the workspace")
        .join("deploy")
}

/// A file under deploy/.
pub fn read(rel: &str) -> String {
    let path = deploy_dir().join(rel);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The YAML documents of a file under deploy/.
pub fn yaml(rel: &str) -> Vec<Yaml> {
    YamlLoader::load_from_str(&read(rel)).unwrap_or_else(|e| panic!("deploy/{rel}: {e}"))
}

/// A scalar as text (YAML reads `8700` as a number and `"8700"` as a string).
pub fn text(y: &Yaml) -> Option<String> {
    match y {
        Yaml::String(s) | Yaml::Real(s) => Some(s.clone()),
        Yaml::Integer(i) => Some(i.to_string()),
        Yaml::Boolean(b) => Some(b.to_string()),
        _ => None,
    }
}

/// A manifest's `metadata.name` (empty when missing).
pub fn name_of(doc: &Yaml) -> &str {
    doc["metadata"]["name"].as_str().unwrap_or("")
}

/// `tessera` without the `TESSERA_*` variables of the test's own environment.
pub fn tessera_command() -> Command {
    let mut command = Command::new(tessera_bin());
    for (key, _) in std::env::vars_os() {
        if key.to_string_lossy().starts_with("TESSERA_") {
            command.env_remove(key);
        }
    }
    command
}

/// `tessera ARGS --help`.
pub fn help(args: &[&str]) -> String {
    let out = tessera_command().args(args).arg("--help").output().unwrap();
    assert!(out.status.success(), "tessera {args:?} --help failed");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// What `tessera <role> --help` lists: each long flag with the variable clap also reads
/// it from (`[env: TESSERA_X=...]`), if any.
pub struct Role {
    pub name: String,
    pub flags: BTreeMap<String, Option<String>>,
}

impl Role {
    pub fn of(name: &str) -> Role {
        Role {
            name: name.into(),
            flags: parse_options(&help(&[name])),
        }
    }

    pub fn env_names(&self) -> BTreeSet<String> {
        self.flags.values().flatten().cloned().collect()
    }

    /// The flag that `var` stands for.
    pub fn flag_of(&self, var: &str) -> Option<&str> {
        self.flags
            .iter()
            .find(|(_, env)| env.as_deref() == Some(var))
            .map(|(flag, _)| flag.as_str())
    }
}

/// The options section of clap's help: an option starts on a line indented by at most six
/// spaces with a `-`; its description (maybe wrapped) follows until the next one.
pub fn parse_options(help: &str) -> BTreeMap<String, Option<String>> {
    let mut options: Vec<String> = vec![];
    let mut in_options = false;
    for line in help.lines() {
        if line.trim_end() == "Options:" {
            in_options = true;
            continue;
        }
        let indent = line.len() - line.trim_start().len();
        if !in_options || line.trim().is_empty() {
            continue;
        }
        match options.last_mut() {
            Some(last) if !(indent <= 6 && line.trim_start().starts_with('-')) => {
                last.push(' ');
                last.push_str(line.trim());
            }
            _ => options.push(line.trim().to_string()),
        }
    }
    options
        .iter()
        .filter_map(|option| {
            let flag = option
                .split_whitespace()
                .find(|w| w.starts_with("--"))?
                .trim_end_matches(',')
                .to_string();
            let env = option.split("[env: ").nth(1).map(|rest| {
                rest.chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect()
            });
            Some((flag, env))
        })
        .collect()
}

/// `tessera --help`'s subcommands.
pub fn subcommands() -> BTreeSet<String> {
    help(&[])
        .lines()
        .skip_while(|l| l.trim_end() != "Commands:")
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect()
}

/// One way the deploy files start a role: its arguments after `tessera` and its
/// environment (a secret or a field reference stands in as a placeholder value).
#[derive(Debug)]
pub struct Launch {
    pub place: String,
    pub args: Vec<String>,
    pub env: Vec<(String, String)>,
}

impl Launch {
    pub fn role(&self) -> &str {
        self.args.first().map_or("", String::as_str)
    }

    pub fn env(&self, var: &str) -> Option<&str> {
        self.env
            .iter()
            .find(|(k, _)| k == var)
            .map(|(_, v)| v.as_str())
    }
}

/// `${NAME:-default}` as compose reads it with NAME unset.
pub fn compose_default(value: &str) -> String {
    let mut out = String::new();
    let mut rest = value;
    while let Some(start) = rest.find("${") {
        out += &rest[..start];
        let end = rest[start..].find('}').expect("a closed ${...}") + start;
        let inner = &rest[start + 2..end];
        out += inner.split_once(":-").map_or("", |(_, default)| default);
        rest = &rest[end + 1..];
    }
    out + rest
}

/// deploy/compose.yaml.
pub fn compose() -> Yaml {
    yaml("compose.yaml").remove(0)
}

/// The compose services, each as a [`Launch`].
pub fn compose_launches() -> Vec<Launch> {
    let compose = compose();
    let services = compose["services"].as_hash().expect("compose has services");
    services
        .iter()
        .map(|(name, service)| {
            let name = name.as_str().unwrap();
            let env = service["environment"].as_hash().map_or(vec![], |env| {
                env.iter()
                    .map(|(k, v)| {
                        let v = text(v).unwrap_or_default();
                        (k.as_str().unwrap().to_string(), compose_default(&v))
                    })
                    .collect()
            });
            Launch {
                place: format!("compose.yaml service {name}"),
                args: service["command"]
                    .as_vec()
                    .unwrap_or_else(|| panic!("compose service {name} names its role"))
                    .iter()
                    .map(|a| text(a).unwrap())
                    .collect(),
                env,
            }
        })
        .collect()
}

/// Every document of every manifest under deploy/kubernetes/ (subfolders too), with its
/// path there (`server/server-service.yaml`).
pub fn manifests() -> Vec<(String, Yaml)> {
    let root = deploy_dir().join("kubernetes");
    let mut files = vec![];
    let mut stack = vec![root.clone()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "yaml" || e == "yml") {
                let rel = path.strip_prefix(&root).unwrap();
                files.push(rel.to_string_lossy().into_owned());
            }
        }
    }
    files.sort();
    let mut docs = vec![];
    for file in files {
        for doc in yaml(&format!("kubernetes/{file}")) {
            if !doc.is_null() {
                docs.push((file.clone(), doc));
            }
        }
    }
    docs
}

/// The one manifest of `kind`.
pub fn manifest<'a>(docs: &'a [(String, Yaml)], kind: &str) -> &'a Yaml {
    let found: Vec<_> = docs
        .iter()
        .filter(|(_, d)| d["kind"].as_str() == Some(kind))
        .collect();
    assert_eq!(found.len(), 1, "one {kind} in deploy/kubernetes");
    &found[0].1
}

/// A manifest's pod template: a Deployment's or StatefulSet's, or the Job's of a KEDA
/// ScaledJob.
pub fn pod_template(doc: &Yaml) -> Option<&Yaml> {
    [
        &doc["spec"]["template"],
        &doc["spec"]["jobTargetRef"]["template"],
    ]
    .into_iter()
    .find(|t| !t.is_badvalue())
}

/// The containers of the pod templates.
pub fn containers(docs: &[(String, Yaml)]) -> Vec<(String, &Yaml)> {
    docs.iter()
        .filter_map(|(file, doc)| {
            let list = pod_template(doc)?["spec"]["containers"].as_vec()?;
            Some(list.iter().map(move |c| (file.clone(), c)))
        })
        .flatten()
        .collect()
}

/// The pod templates' containers, each as a [`Launch`].
pub fn kubernetes_launches(docs: &[(String, Yaml)]) -> Vec<Launch> {
    containers(docs)
        .into_iter()
        .map(|(file, c)| {
            let env = c["env"].as_vec().map_or(vec![], |env| {
                env.iter()
                    .map(|e| {
                        let key = e["name"].as_str().unwrap().to_string();
                        let value = text(&e["value"]).unwrap_or_else(|| {
                            let from = &e["valueFrom"];
                            match from["secretKeyRef"]["key"].as_str() {
                                Some(key) => format!("secret-{key}"),
                                None => {
                                    assert!(!from["fieldRef"].is_badvalue(), "{key}: no value");
                                    "pod-name".into()
                                }
                            }
                        });
                        (key, value)
                    })
                    .collect()
            });
            Launch {
                place: format!(
                    "kubernetes/{file} container {}",
                    c["name"].as_str().unwrap()
                ),
                args: c["args"]
                    .as_vec()
                    .expect("a container names its role in args")
                    .iter()
                    .map(|a| text(a).unwrap())
                    .collect(),
                env,
            }
        })
        .collect()
}

/// A unit file's `[Section]` -> `Key=Value` lines (a key may repeat).
pub type Unit = BTreeMap<String, Vec<(String, String)>>;

pub fn unit(rel: &str) -> Unit {
    let mut unit = Unit::new();
    let mut section = None;
    for (n, line) in read(rel).lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') || line.starts_with(';') {
            continue;
        }
        if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            section = Some(name.to_string());
            unit.entry(name.to_string()).or_default();
            continue;
        }
        let (key, value) = line
            .split_once('=')
            .unwrap_or_else(|| panic!("deploy/{rel}:{}: not Key=Value: {line}", n + 1));
        let section = section
            .as_ref()
            .unwrap_or_else(|| panic!("deploy/{rel}:{}: outside a section", n + 1));
        unit.get_mut(section)
            .unwrap()
            .push((key.trim().to_string(), value.trim().to_string()));
    }
    unit
}

/// The last value of `key` in `[Service]`.
pub fn unit_value<'a>(unit: &'a Unit, key: &str) -> Option<&'a str> {
    unit.get("Service")?
        .iter()
        .rev()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.as_str())
}

/// `KEY=VALUE` lines of an environment file; with `commented`, also `#KEY=VALUE` ones.
pub fn env_file(rel: &str, commented: bool) -> Vec<(String, String)> {
    read(rel)
        .lines()
        .filter_map(|line| {
            let line = line.trim();
            let line = match line.strip_prefix('#') {
                Some(rest) if commented && rest.starts_with("TESSERA_") => rest,
                Some(_) => return None,
                None => line,
            };
            let (k, v) = line.split_once('=')?;
            Some((k.trim().to_string(), v.trim().to_string()))
        })
        .collect()
}

/// The systemd units, each with its example environment file.
pub const UNITS: [(&str, &str); 2] = [
    (
        "systemd/tessera-server.service",
        "systemd/server.env.example",
    ),
    (
        "systemd/tessera-worker.service",
        "systemd/worker.env.example",
    ),
];

/// The units' `ExecStart` with their example environment files, as [`Launch`]es.
pub fn systemd_launches() -> Vec<Launch> {
    UNITS
        .iter()
        .map(|(service, env)| {
            let unit = unit(service);
            let exec = unit_value(&unit, "ExecStart").expect("ExecStart");
            let mut words = exec.split_whitespace().map(str::to_string);
            let program = words.next().unwrap();
            assert!(program.ends_with("/tessera"), "{service} runs {program}");
            let mut vars = env_file(env, false);
            for (k, v) in unit.get("Service").unwrap() {
                if k == "Environment" {
                    let (k, v) = v.trim_matches('"').split_once('=').unwrap();
                    vars.push((k.into(), v.into()));
                }
            }
            Launch {
                place: format!("{service} with {env}"),
                args: words.collect(),
                env: vars,
            }
        })
        .collect()
}

/// The Dockerfile's instructions, continuation lines joined.
pub fn dockerfile() -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = vec![];
    let mut pending = String::new();
    for line in read("docker/Dockerfile").lines() {
        let line = line.trim();
        if line.starts_with('#') || (line.is_empty() && pending.is_empty()) {
            continue;
        }
        match line.strip_suffix('\\') {
            Some(part) => pending += &format!("{} ", part.trim()),
            None => {
                pending += line;
                let (op, rest) = pending.split_once(' ').unwrap_or((&pending, ""));
                out.push((op.to_uppercase(), rest.trim().to_string()));
                pending.clear();
            }
        }
    }
    out
}

/// `NAME=value NAME2=value2` of an ENV instruction.
pub fn dockerfile_env() -> Vec<(String, String)> {
    dockerfile()
        .iter()
        .filter(|(op, _)| op == "ENV")
        .flat_map(|(_, rest)| {
            rest.split_whitespace()
                .map(|pair| {
                    let (k, v) = pair.split_once('=').expect("ENV NAME=value");
                    (k.to_string(), v.to_string())
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Every role started by compose, Kubernetes and systemd.
pub fn all_launches() -> Vec<Launch> {
    let mut all = compose_launches();
    all.extend(kubernetes_launches(&manifests()));
    all.extend(systemd_launches());
    all
}

/// A value of `--print-config`'s TOML equals `expected`, as the flag would parse it.
pub fn same_value(value: &toml::Value, expected: &str) -> bool {
    match value {
        toml::Value::String(s) => s == expected,
        toml::Value::Integer(i) => expected.parse::<i64>() == Ok(*i),
        toml::Value::Float(f) => expected.parse::<f64>() == Ok(*f),
        toml::Value::Boolean(b) => expected.parse::<bool>() == Ok(*b),
        _ => false,
    }
}

/// The port in `host:port` or `scheme://host:port/...`.
pub fn port_in(address: &str) -> Option<i64> {
    let rest = address.split_once("://").map_or(address, |(_, r)| r);
    let host_port = rest.split('/').next()?;
    host_port.rsplit_once(':')?.1.parse().ok()
}

/// Every value under a key named like a port, anywhere in `y`.
pub fn ports_in(y: &Yaml, out: &mut Vec<(String, String)>) {
    match y {
        Yaml::Hash(h) => {
            for (k, v) in h {
                let key = k.as_str().unwrap_or("");
                if matches!(
                    key,
                    "port" | "containerPort" | "targetPort" | "prometheus.io/port"
                ) {
                    out.push((key.to_string(), text(v).unwrap_or_default()));
                }
                ports_in(v, out);
            }
        }
        Yaml::Array(a) => a.iter().for_each(|v| ports_in(v, out)),
        _ => {}
    }
}

/// `"30s"`, `"1m30s"` or `30` as seconds.
pub fn seconds(duration: &str) -> u64 {
    let (mut total, mut number) = (0, String::new());
    for c in duration.chars() {
        match c {
            '0'..='9' => number.push(c),
            's' | 'm' | 'h' => {
                let n: u64 = number.parse().unwrap();
                total += n * [1, 60, 3600]["smh".find(c).unwrap()];
                number.clear();
            }
            _ => panic!("not a duration: {duration}"),
        }
    }
    total + number.parse::<u64>().unwrap_or(0)
}

/// Metric selectors in a PromQL query: `name{label=~"a|b"}` -> (name, label, [a, b]).
pub fn selectors(query: &str) -> Vec<(String, String, Vec<String>)> {
    let mut out = vec![];
    for (at, _) in query.match_indices("tessera_") {
        let name: String = query[at..]
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        let rest = &query[at + name.len()..];
        let Some(matcher) = rest.strip_prefix('{').and_then(|r| r.split('}').next()) else {
            out.push((name, String::new(), vec![]));
            continue;
        };
        let (label, values) = matcher.split_once('=').expect("label=value");
        let values = values.trim_start_matches('~').trim_matches('"');
        out.push((
            name,
            label.trim().to_string(),
            values.split('|').map(str::to_string).collect(),
        ));
    }
    out
}
