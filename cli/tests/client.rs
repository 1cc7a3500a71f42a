//! The real `tessera` client commands, as a user runs them, where no farm is needed to
//! check what they say.

use std::path::Path;
use std::process::{Command, Output};

fn tessera(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tessera"))
        .args(args)
        .current_dir(dir)
        .env_remove("TESSERA_SERVER")
        .env_remove("TESSERA_CLIENT_TOKEN")
        .output()
        .expect("tessera runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn status_without_a_server_says_it_cannot_reach_it() {
    let dir = tempfile::tempdir().unwrap();
    // Port 1 on loopback: nothing listens there.
    for args in [
        &["status", "--server", "http://127.0.0.1:1"][..],
        &["workers", "--server", "http://127.0.0.1:1"][..],
        &["cancel", "3", "--server", "http://127.0.0.1:1"][..],
    ] {
        let o = tessera(args, dir.path());
        assert!(!o.status.success(), "{args:?} succeeded");
        let err = stderr(&o);
        assert!(
            err.contains("cannot reach the Tessera server at http://127.0.0.1:1")
                && err.contains("is `tessera server` running?"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn the_server_address_also_comes_from_the_environment() {
    let dir = tempfile::tempdir().unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_tessera"))
        .args(["status", "--json"])
        .env("TESSERA_SERVER", "http://127.0.0.1:1")
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(stderr(&o).contains("http://127.0.0.1:1"), "{}", stderr(&o));
}

#[test]
fn submitting_a_missing_scene_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    // The scene is checked before any server is asked: no server is needed for this.
    let o = tessera(
        &["submit", "missing.gltf", "--server", "http://127.0.0.1:1"],
        dir.path(),
    );
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("missing.gltf: no such file") && !err.contains("cannot reach"),
        "{err}"
    );
}

#[test]
fn bad_flags_are_refused_before_anything_runs() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("scene.glb"), b"not read").unwrap();
    for (args, expect) in [
        (&["submit", "scene.glb", "--size", "0x10"][..], "--size"),
        (&["submit", "scene.glb", "--frames", "9-1"][..], "--frames"),
        (&["submit", "scene.glb", "--out", "x"][..], "--wait"),
        (&["demo", "--workers", "0"][..], "--workers"),
    ] {
        let o = tessera(args, dir.path());
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(stderr(&o).contains(expect), "{args:?}: {}", stderr(&o));
    }
}
