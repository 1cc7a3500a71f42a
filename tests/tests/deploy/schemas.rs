//! deploy/kubernetes against the schemas of the APIs it targets.

use std::path::Path;
use std::process::Command;

use super::files::*;

/// The manifests, and what kustomize makes of both kustomizations, against the schemas of
/// the Kubernetes API and KEDA's CRDs (tests/kubernetes/check.mjs: the validators and the
/// strict types `kubernetes-models` generates from them; unknown fields are errors). A
/// broken copy must fail, so the check is known to bite.
#[test]
fn manifests_match_the_kubernetes_and_keda_schemas() {
    let checker = Path::new(env!("CARGO_MANIFEST_DIR")).join("kubernetes");
    let node = Command::new("node").arg("--version").output();
    if node.is_err() || !checker.join("node_modules").is_dir() {
        eprintln!(
            "\n=== SKIPPED: the Kubernetes schema check needs Node.js and its packages \
             (scripts/install-kubernetes-check.sh installs them) ===\n"
        );
        return;
    }
    let check = |files: &[std::path::PathBuf]| {
        let out = Command::new("node")
            .arg(checker.join("check.mjs"))
            .args(files)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout).into_owned()
            + &String::from_utf8_lossy(&out.stderr);
        (out.status.success(), text)
    };
    let mut files: Vec<std::path::PathBuf> = manifests()
        .into_iter()
        .filter(|(_, doc)| doc["kind"].as_str() != Some("Kustomization"))
        .map(|(file, _)| deploy_dir().join("kubernetes").join(file))
        .collect();
    files.dedup();
    let (ok, text) = check(&files);
    assert!(ok, "deploy/kubernetes against the schemas:\n{text}");
    eprintln!("{text}");

    let dir = tempfile::tempdir().unwrap();
    let broken = dir.path().join("broken.yaml");
    let scaler = read("kubernetes/worker-scaledobject.yaml");
    let statefulset = read("kubernetes/server/server-statefulset.yaml");
    std::fs::write(
        &broken,
        scaler.replace("pollingInterval:", "pollingIntervall:")
            + "---\n"
            + &statefulset.replace("containerPort: 8700", "containerPort: \"8700\""),
    )
    .unwrap();
    let (ok, text) = check(&[broken]);
    assert!(
        !ok,
        "a misspelt KEDA field and a port as text pass:\n{text}"
    );
    assert!(
        text.contains("pollingIntervall") && text.contains("containerPort"),
        "{text}"
    );

    // What `kubectl apply -k` would send, where kubectl is installed (its dry run needs an
    // API server; rendering does not).
    if Command::new("kubectl")
        .arg("version")
        .arg("--client")
        .output()
        .is_err()
    {
        eprintln!("\n=== NOTE: no kubectl here: the kustomizations were not rendered ===\n");
        return;
    }
    for (folder, kinds) in [
        (
            "",
            &["Deployment", "ScaledObject", "Service", "StatefulSet"][..],
        ),
        ("jobs", &["ScaledJob", "Service", "StatefulSet"]),
    ] {
        let out = Command::new("kubectl")
            .arg("kustomize")
            .arg(deploy_dir().join("kubernetes").join(folder))
            .output()
            .unwrap();
        let yaml = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "kubectl kustomize {folder}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let mut made: Vec<String> = yaml_rust2::YamlLoader::load_from_str(&yaml)
            .unwrap()
            .iter()
            .map(|d| d["kind"].as_str().unwrap().to_string())
            .collect();
        made.sort();
        assert_eq!(made, kinds, "kubectl kustomize deploy/kubernetes/{folder}");
        let rendered = dir
            .path()
            .join(format!("kustomized-{}.yaml", folder.replace('/', "-")));
        std::fs::write(&rendered, yaml).unwrap();
        let (ok, text) = check(&[rendered]);
        assert!(ok, "kubectl kustomize deploy/kubernetes/{folder}:\n{text}");
    }
}
