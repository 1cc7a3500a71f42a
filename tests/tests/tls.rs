//! HTTPS without a proxy, as a user sets it up: `tessera server --tls-cert --tls-key` with
//! a certificate a private CA signed, and a worker and the client commands that trust
//! that CA (`--ca`). A client that does not trust it, or speaks plain HTTP to the port,
//! gets nothing.

use proto::JobState;
use tests::{render_directly, settings, tessera, Farm};
use tracer::output::read_exr;

#[test]
fn a_farm_over_tls_renders_and_untrusting_clients_are_refused() {
    let mut farm = Farm::new();
    farm.client_token = Some("client-secret".into());
    farm.start_tls_server(
        60,
        &[
            "--worker-token",
            "worker-secret",
            "--client-token",
            "client-secret",
        ],
    );
    farm.start_worker_with("w1", 2, &["--token", "worker-secret"]);
    let scene = farm.demo_scene();
    let scene = scene.to_str().unwrap();
    let mut args = vec![scene, "--frames", "2-2"];
    args.extend(settings("2"));
    args.extend(["--wait", "--out", "frames"]);
    let job = farm.submit(&args);
    assert_eq!(farm.job(job).state, JobState::Done);
    // What came over TLS is the frame a direct render makes.
    let frame = read_exr(&farm.path().join("frames/frame_0002.exr")).unwrap();
    assert!(frame.layers == render_directly(std::path::Path::new(scene), 2, "2", farm.path()));

    let https = farm.url();
    assert!(https.starts_with("https://"), "{https}");
    let refused = |url: &str| {
        let o = tessera(
            &["status", "--server", url, "--token", "client-secret"],
            farm.path(),
        );
        assert!(!o.status.success(), "status {url} succeeded");
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    // Without --ca the private CA is not trusted.
    let untrusted = refused(&https);
    assert!(
        untrusted.contains("certificate") && untrusted.contains("--ca"),
        "{untrusted}"
    );
    // Plain HTTP to the TLS port: the handshake fails, nothing is served.
    let plain = refused(&https.replacen("https", "http", 1));
    assert!(plain.contains("use an https:// URL"), "{plain}");
}
