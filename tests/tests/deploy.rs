//! deploy/ against the binary: the compose file and Kubernetes manifests parse; every
//! subcommand, flag and `TESSERA_*` variable that the Dockerfile, compose file, manifests
//! and systemd units use exists in `tessera <role> --help`, and `--print-config` shows
//! their values taken; every port is 8700; and the paths that probes and Prometheus hit,
//! and the queue-depth series the autoscaler reads, answer on a running server; and the
//! manifests match the Kubernetes and KEDA schemas (deploy/schemas.rs).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

use tests::http;
use tests::{tessera_bin, Farm};

#[path = "deploy/files.rs"]
mod files;
use files::*;

#[path = "deploy/schemas.rs"]
mod schemas;

/// The one port the farm uses, in and out of containers.
const PORT: i64 = 8700;

/// How long a worker's goodbye may take after SIGTERM (`LEAVE_TIMEOUT` in
/// worker/src/daemon.rs); every stop timeout must leave room beyond it.
const LEAVE_SECONDS: u64 = 10;

#[test]
fn compose_file_and_manifests_parse_and_name_what_they_make() {
    let compose = compose();
    for service in ["server", "worker"] {
        assert!(
            compose["services"][service].as_hash().is_some(),
            "compose.yaml has a `{service}` service"
        );
    }

    let docs = manifests();
    let mut listed = BTreeSet::new();
    for (file, doc) in &docs {
        let kind = doc["kind"]
            .as_str()
            .unwrap_or_else(|| panic!("{file}: no kind"));
        assert!(
            doc["apiVersion"].as_str().is_some(),
            "{file}: no apiVersion"
        );
        if kind == "Kustomization" {
            // Resources are files or folders with a kustomization of their own, relative to
            // the kustomization's folder.
            let folder = Path::new(file).parent().unwrap();
            for r in doc["resources"].as_vec().expect("resources") {
                let r = normalize(&folder.join(r.as_str().unwrap()));
                let path = deploy_dir().join("kubernetes").join(&r);
                assert!(
                    path.is_file() || path.join("kustomization.yaml").is_file(),
                    "{file} lists {}",
                    r.display()
                );
                listed.insert(r.to_string_lossy().into_owned());
            }
        } else {
            assert!(
                !name_of(doc).is_empty(),
                "{file}: a {kind} without metadata.name"
            );
        }
    }
    // Every manifest but the example Secret (placeholder tokens must not reach a cluster
    // by accident) is part of a kustomization, and both ways to run workers name the same
    // image.
    for (file, doc) in &docs {
        if !matches!(doc["kind"].as_str(), Some("Kustomization" | "Secret")) {
            assert!(listed.contains(file), "no kustomization lists {file}");
        }
    }
    let images: Vec<&yaml_rust2::Yaml> = docs
        .iter()
        .filter(|(_, d)| d["kind"].as_str() == Some("Kustomization"))
        .map(|(_, d)| &d["images"])
        .filter(|i| !i.is_badvalue())
        .collect();
    assert_eq!(
        images.len(),
        2,
        "kustomization.yaml and jobs/ set the image"
    );
    assert_eq!(
        images[0], images[1],
        "both kustomizations name the same image"
    );

    // The pieces fit together: the Service selects the server's pods, the StatefulSet is
    // governed by it, KEDA scales the workers' Deployment, secrets come from the Secret.
    let service = manifest(&docs, "Service");
    let server = manifest(&docs, "StatefulSet");
    let workers = manifest(&docs, "Deployment");
    let secret = manifest(&docs, "Secret");
    let scaler = manifest(&docs, "ScaledObject");
    assert_eq!(
        server["spec"]["replicas"].as_i64(),
        Some(1),
        "one server, one database"
    );
    assert_eq!(
        server["spec"]["serviceName"].as_str(),
        Some(name_of(service))
    );
    assert!(!server["spec"]["volumeClaimTemplates"][0].is_badvalue());
    let labels = server["spec"]["template"]["metadata"]["labels"]
        .as_hash()
        .unwrap();
    for (k, v) in service["spec"]["selector"].as_hash().unwrap() {
        assert_eq!(
            labels.get(k),
            Some(v),
            "the Service selects the server's pods"
        );
    }
    assert_eq!(
        scaler["spec"]["scaleTargetRef"]["name"].as_str(),
        Some(name_of(workers))
    );
    // The pilot-job variant: KEDA starts Jobs on the same demand query; each worker
    // leaves when idle and its pod is not restarted.
    let jobs = manifest(&docs, "ScaledJob");
    assert_eq!(jobs["spec"]["triggers"], scaler["spec"]["triggers"]);
    let pod = &jobs["spec"]["jobTargetRef"]["template"]["spec"];
    assert_eq!(pod["restartPolicy"].as_str(), Some("Never"));
    let launch = kubernetes_launches(&[("jobs".into(), jobs.clone())]).remove(0);
    assert!(launch.env("TESSERA_EXIT_WHEN_IDLE").is_some());
    for (file, c) in containers(&docs) {
        for e in c["env"].as_vec().into_iter().flatten() {
            let secret_ref = &e["valueFrom"]["secretKeyRef"];
            if let Some(key) = secret_ref["key"].as_str() {
                assert_eq!(secret_ref["name"].as_str(), Some(name_of(secret)), "{file}");
                assert!(
                    !secret["stringData"][key].is_badvalue(),
                    "{file}: secret key {key}"
                );
            }
        }
    }
}

/// `a/b/../c` as `a/c`.
fn normalize(path: &Path) -> std::path::PathBuf {
    let mut out = std::path::PathBuf::new();
    for part in path.components() {
        match part {
            std::path::Component::ParentDir => {
                assert!(out.pop(), "{} leaves deploy/kubernetes", path.display())
            }
            std::path::Component::CurDir => {}
            other => out.push(other),
        }
    }
    out
}

#[test]
fn every_subcommand_flag_and_variable_they_use_exists() {
    let commands = subcommands();
    let roles = [Role::of("server"), Role::of("worker")];
    assert!(
        roles.iter().all(|r| r.env_names().len() >= 5),
        "`tessera server|worker --help` name their TESSERA_* variables: {:?}",
        roles.iter().map(|r| r.env_names()).collect::<Vec<_>>()
    );
    let role = |name: &str| roles.iter().find(|r| r.name == name);

    for launch in all_launches() {
        let place = &launch.place;
        let r = role(launch.role()).unwrap_or_else(|| {
            panic!(
                "{place}: runs `tessera {}`, not server or worker",
                launch.role()
            )
        });
        assert!(
            commands.contains(&r.name),
            "{place}: no subcommand {}",
            r.name
        );
        for arg in launch.args.iter().filter(|a| a.starts_with("--")) {
            let flag = arg.split('=').next().unwrap();
            assert!(
                r.flags.contains_key(flag),
                "{place}: `tessera {} {flag}` does not exist",
                r.name
            );
        }
        for (var, _) in launch.env.iter().filter(|(k, _)| k.starts_with("TESSERA_")) {
            assert!(
                r.env_names().contains(var),
                "{place}: `tessera {}` reads no {var}",
                r.name
            );
        }
    }

    // The image serves both roles: its defaults must each mean something to one of them.
    let image = dockerfile();
    let entrypoint = image
        .iter()
        .find(|(op, _)| op == "ENTRYPOINT")
        .expect("ENTRYPOINT");
    assert_eq!(entrypoint.1, r#"["tessera"]"#);
    for (var, _) in dockerfile_env() {
        assert!(
            roles.iter().any(|r| r.env_names().contains(&var)),
            "Dockerfile: ENV {var} is read by neither server nor worker"
        );
    }

    // Any TESSERA_* name anywhere under deploy/ (comments, README, examples) exists: in a
    // role, or in the client commands (`tessera submit`).
    let mut known: BTreeSet<String> = roles.iter().flat_map(|r| r.env_names()).collect();
    for command in [&["submit"][..], &["scale", "slurm"]] {
        known.extend(parse_options(&help(command)).into_values().flatten());
    }
    let mut stack = vec![deploy_dir()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
                continue;
            }
            let text = std::fs::read_to_string(&path).unwrap();
            for (at, _) in text.match_indices("TESSERA_") {
                let name: String = text[at..]
                    .chars()
                    .take_while(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || *c == '_')
                    .collect();
                if name != "TESSERA_" {
                    assert!(known.contains(&name), "{}: unknown {name}", path.display());
                }
            }
        }
    }
}

#[test]
fn print_config_shows_every_value_they_set_taken() {
    let roles = [Role::of("server"), Role::of("worker")];
    for launch in all_launches() {
        let place = &launch.place;
        let role = roles.iter().find(|r| r.name == launch.role()).unwrap();
        let out = tessera_command()
            .env_clear()
            .envs(launch.env.iter().map(|(k, v)| (k, v)))
            .args(&launch.args)
            .arg("--print-config")
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{place}: tessera {} --print-config failed:\n{}",
            launch.args.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
        let config: toml::Table = stdout
            .parse()
            .unwrap_or_else(|e| panic!("{place}: --print-config is not TOML: {e}\n{stdout}"));
        let table = config
            .get(&role.name)
            .and_then(toml::Value::as_table)
            .unwrap_or_else(|| panic!("{place}: no [{}] table in\n{stdout}", role.name));

        // What each setting should read: the variables, overridden by the flags.
        let mut expected: BTreeMap<String, String> = BTreeMap::new();
        for (var, value) in &launch.env {
            if let Some(flag) = role.flag_of(var) {
                expected.insert(flag.to_string(), value.clone());
            }
        }
        let mut args = launch.args[1..].iter();
        while let Some(arg) = args.next() {
            let value = args
                .next()
                .unwrap_or_else(|| panic!("{place}: {arg} without a value"));
            expected.insert(arg.clone(), value.clone());
        }
        for (flag, value) in expected {
            // Tokens may be left out or masked: only their presence in --help counts.
            if flag.contains("token") || flag == "--config" {
                continue;
            }
            let key = flag.trim_start_matches("--").replace('-', "_");
            let shown = table
                .get(&key)
                .unwrap_or_else(|| panic!("{place}: no `{key}` in\n{stdout}"));
            assert!(
                same_value(shown, &value),
                "{place}: {key} = {shown}, wanted {value}"
            );
        }
    }
}

#[test]
fn every_port_is_8700() {
    for launch in all_launches() {
        for var in ["TESSERA_LISTEN", "TESSERA_SERVER"] {
            if let Some(address) = launch.env(var) {
                assert_eq!(
                    port_in(address),
                    Some(PORT),
                    "{}: {var}={address}",
                    launch.place
                );
            }
        }
    }
    for (file, doc) in manifests() {
        let mut ports = vec![];
        ports_in(&doc, &mut ports);
        for (key, value) in ports {
            assert_eq!(value, PORT.to_string(), "kubernetes/{file}: {key}: {value}");
        }
    }
    let compose = compose();
    for (name, service) in compose["services"].as_hash().unwrap() {
        for mapping in service["ports"].as_vec().into_iter().flatten() {
            let mapping = text(mapping).unwrap();
            let mut parts = mapping.rsplit(':');
            let (inside, outside) = (parts.next().unwrap(), parts.next().unwrap());
            assert_eq!(
                (inside, outside),
                ("8700", "8700"),
                "compose {name:?} ports"
            );
        }
        for word in service["healthcheck"]["test"]
            .as_vec()
            .into_iter()
            .flatten()
        {
            let word = text(word).unwrap();
            if word.contains("://") {
                assert_eq!(port_in(&word), Some(PORT), "compose {name:?} healthcheck");
            }
        }
    }
    for (var, value) in dockerfile_env() {
        if var == "TESSERA_LISTEN" {
            assert_eq!(port_in(&value), Some(PORT), "Dockerfile ENV {var}");
        }
    }
    let exposed: Vec<String> = dockerfile()
        .into_iter()
        .filter(|(op, _)| op == "EXPOSE")
        .map(|(_, rest)| rest)
        .collect();
    assert_eq!(exposed, ["8700"]);
    for (_, env) in UNITS {
        for (var, value) in env_file(env, true) {
            if var == "TESSERA_LISTEN" || var == "TESSERA_SERVER" {
                assert_eq!(port_in(&value), Some(PORT), "{env}: {var}");
            }
        }
    }
}

#[test]
fn workers_get_the_cores_they_use_and_time_to_give_their_lease_back() {
    let docs = manifests();
    for kind in ["Deployment", "ScaledJob"] {
        let workers = manifest(&docs, kind);
        let pod = &pod_template(workers).unwrap()["spec"];
        let grace = pod["terminationGracePeriodSeconds"]
            .as_i64()
            .expect("a grace period");
        assert!(grace as u64 >= 2 * LEAVE_SECONDS, "{kind}: grace {grace} s");
        let launch = kubernetes_launches(&[(kind.into(), workers.clone())]).remove(0);
        assert_eq!(launch.role(), "worker");
        let threads = launch
            .env("TESSERA_THREADS")
            .expect("TESSERA_THREADS is set");
        let container = &pod["containers"][0];
        for bound in ["requests", "limits"] {
            let cpu = text(&container["resources"][bound]["cpu"]);
            assert_eq!(
                cpu.as_deref(),
                Some(threads),
                "{kind}: cpu {bound} = threads"
            );
        }
    }

    let compose = compose();
    for service in ["server", "worker"] {
        let grace = text(&compose["services"][service]["stop_grace_period"]).unwrap();
        assert!(
            seconds(&grace) >= 2 * LEAVE_SECONDS,
            "compose {service}: {grace}"
        );
    }

    for (service, _) in UNITS {
        let unit = unit(service);
        assert_eq!(
            unit_value(&unit, "KillSignal"),
            Some("SIGTERM"),
            "{service}"
        );
        let stop = unit_value(&unit, "TimeoutStopSec").expect("TimeoutStopSec");
        assert!(
            seconds(stop) >= 2 * LEAVE_SECONDS,
            "{service}: TimeoutStopSec={stop}"
        );
    }
    // Docker stops a container with SIGTERM unless told otherwise.
    assert!(dockerfile()
        .iter()
        .all(|(op, rest)| op != "STOPSIGNAL" || rest == "SIGTERM"));
}

#[test]
fn systemd_units_restart_sandbox_and_write_only_their_own_folder() {
    for ((service, _), launch) in UNITS.iter().zip(systemd_launches()) {
        let unit = unit(service);
        assert!(
            unit.contains_key("Unit") && unit.contains_key("Install"),
            "{service}"
        );
        for (key, want) in [
            ("Restart", "on-failure"),
            ("ProtectSystem", "strict"),
            ("ProtectHome", "yes"),
            ("PrivateTmp", "yes"),
            ("NoNewPrivileges", "yes"),
            ("DynamicUser", "yes"),
        ] {
            assert_eq!(unit_value(&unit, key), Some(want), "{service}: {key}");
        }
        // With ProtectSystem=strict only the State/CacheDirectory is writable: the data
        // folder or scene cache must be that one.
        let (flag, dir_key, base) = match launch.role() {
            "server" => ("--data", "StateDirectory", "/var/lib/"),
            _ => ("--cache", "CacheDirectory", "/var/cache/"),
        };
        let dir = unit_value(&unit, dir_key).unwrap_or_else(|| panic!("{service}: {dir_key}"));
        let at = launch.args.iter().position(|a| a == flag).expect(flag);
        assert_eq!(launch.args[at + 1], format!("{base}{dir}"), "{service}");
    }

    // systemd's own check, where systemd-analyze is installed, on copies that run this
    // build's binary (it refuses a unit whose ExecStart program is missing).
    let Ok(out) = Command::new("systemd-analyze").arg("--version").output() else {
        eprintln!("systemd-analyze is not installed: skipping `systemd-analyze verify`");
        return;
    };
    assert!(out.status.success());
    let dir = tempfile::tempdir().unwrap();
    let mut paths = vec![];
    for (service, _) in UNITS {
        let text = read(service).replace("/usr/local/bin/tessera", tessera_bin().to_str().unwrap());
        let path = dir.path().join(Path::new(service).file_name().unwrap());
        std::fs::write(&path, text).unwrap();
        paths.push(path);
    }
    let out = Command::new("systemd-analyze")
        .args(["verify", "--man=no"])
        .args(&paths)
        .output()
        .unwrap();
    assert!(
        out.status.success() && out.stderr.is_empty(),
        "systemd-analyze verify:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn probes_scrapes_and_the_autoscaler_query_answer_on_a_running_server() {
    let docs = manifests();
    let server = manifest(&docs, "StatefulSet");
    let pod = &server["spec"]["template"];
    let container = &pod["spec"]["containers"][0];
    let mut paths = BTreeSet::new();
    for probe in ["startupProbe", "readinessProbe", "livenessProbe"] {
        let path = container[probe]["httpGet"]["path"].as_str();
        paths.insert(path.unwrap_or_else(|| panic!("the server has an HTTP {probe}")));
    }
    let scrape = pod["metadata"]["annotations"]["prometheus.io/path"].as_str();
    paths.insert(scrape.expect("a prometheus.io/path annotation"));
    let query = manifest(&docs, "ScaledObject")["spec"]["triggers"][0]["metadata"]["query"]
        .as_str()
        .expect("a Prometheus query");
    let wanted = selectors(query);
    assert!(
        !wanted.is_empty(),
        "the query reads a tessera_ metric: {query}"
    );

    // A server with tokens, as deployed: probes and scrapes go without one.
    const CLIENT_TOKEN: &str = "deploy-client-token";
    let mut farm = Farm::new();
    farm.client_token = Some(CLIENT_TOKEN.into());
    farm.start_server_with(60, &["--worker-token", "w", "--client-token", CLIENT_TOKEN]);
    for &path in &paths {
        let answer = http::get(farm.port, path);
        assert_eq!(answer.status, 200, "GET {path}: {}", answer.text());
    }
    let metrics = http::get(farm.port, "/metrics").text();
    for (name, label, values) in wanted {
        for value in &values {
            let series = format!("{name}{{{label}=\"{value}\"}}");
            assert!(
                metrics.lines().any(|l| l.starts_with(&series)),
                "/metrics has no {series} (the autoscaler's query {query}):\n{metrics}"
            );
        }
        if values.is_empty() {
            assert!(metrics.lines().any(|l| l.starts_with(&name)), "no {name}");
        }
    }

    // compose's healthcheck runs in the server's container, whose TESSERA_CLIENT_TOKEN is
    // the server's: here against this server's address instead of 127.0.0.1:8700.
    let compose = compose();
    let test = compose["services"]["server"]["healthcheck"]["test"]
        .as_vec()
        .unwrap();
    let words: Vec<String> = test.iter().map(|w| text(w).unwrap()).collect();
    assert_eq!(
        &words[..2],
        ["CMD", "tessera"],
        "the healthcheck needs no shell or curl"
    );
    let args: Vec<String> = words[2..]
        .iter()
        .map(|w| {
            w.replace(
                &format!("127.0.0.1:{PORT}"),
                &format!("127.0.0.1:{}", farm.port),
            )
        })
        .collect();
    let out = tessera_command()
        .env("TESSERA_CLIENT_TOKEN", CLIENT_TOKEN)
        .args(&args)
        .current_dir(farm.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "compose's healthcheck `tessera {}` failed:\n{}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn the_image_builds_the_binary_locked_and_runs_it_unprivileged() {
    let image = dockerfile();
    let froms: Vec<&String> = image
        .iter()
        .filter(|(op, _)| op == "FROM")
        .map(|(_, r)| r)
        .collect();
    assert!(froms.len() >= 2, "a multi-stage build: {froms:?}");
    assert!(
        image.iter().any(|(op, rest)| op == "RUN" && rest.contains("cargo build --release -p cli --locked")),
        "the builder runs `cargo build --release -p cli --locked`"
    );
    let user = image
        .iter()
        .rev()
        .find(|(op, _)| op == "USER")
        .expect("a USER");
    let uid = user.1.split(':').next().unwrap();
    assert!(uid != "root" && uid != "0", "runs as {uid}");
    let data = dockerfile_env()
        .into_iter()
        .find(|(k, _)| k == "TESSERA_DATA")
        .expect("ENV TESSERA_DATA")
        .1;
    let volume = image
        .iter()
        .find(|(op, _)| op == "VOLUME")
        .expect("a VOLUME");
    assert!(
        volume.1.contains(&format!("\"{data}\"")),
        "VOLUME {} holds {data}",
        volume.1
    );
    // The build context leaves out the build outputs.
    let ignore = std::fs::read_to_string(deploy_dir().parent().unwrap().join(".dockerignore"))
        .expect("a .dockerignore at the repository root");
    assert!(ignore
        .lines()
        .any(|l| l.trim().trim_end_matches('/') == "target"));
}
