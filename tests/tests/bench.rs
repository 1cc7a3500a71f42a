//! The benchmarks' own checks: `tessera bench farm` and `tessera bench --quick` run as a
//! user runs them and report every figure. A binary of its own, so that their load does not
//! share the machine with the farm tests' timed jobs (the time budget's).

use tests::tessera_ok;

#[test]
fn bench_farm_loses_nothing_and_does_nothing_twice() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("bench.json");
    let out = tessera_ok(
        &[
            "bench",
            "farm",
            "--workers",
            "20",
            "--tasks",
            "400",
            "--timeout-seconds",
            "120",
            "--json",
            json.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert!(out.contains("tasks per second"), "the summary table: {out}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let n = |key: &str| {
        report[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key}: {report}"))
    };
    assert_eq!((n("tasks"), n("workers")), (400.0, 20.0), "{report}");
    assert_eq!(n("accepted"), n("tasks"), "{report}");
    assert_eq!((n("duplicates"), n("lost")), (0.0, 0.0), "{report}");
    assert_eq!(n("frames_done"), n("frames"), "{report}");
    assert!(n("tasks_per_second") > 0.0, "{report}");
    let lease = &report["lease_latency_ms"];
    let (p50, p99) = (
        lease["p50"].as_f64().unwrap(),
        lease["p99"].as_f64().unwrap(),
    );
    assert!(p99 >= p50 && p50 > 0.0, "{report}");
    assert_eq!(lease["count"].as_u64(), Some(400), "{report}");
    let peak = report["server_memory"]["peak_rss_mib"].as_f64().unwrap();
    assert!(peak > 0.0, "{report}");
    assert_eq!(report["passed"].as_bool(), Some(true), "{report}");
    // The server's own assembly times, one per frame.
    let assembly = &report["assembly"];
    assert_eq!(assembly["frames"], report["frames_done"], "{report}");
    assert!(assembly["seconds"].as_f64().unwrap() > 0.0, "{report}");
    assert!(out.contains("| frame assembly |"), "{out}");
}

/// With tiles the size and noise of rendered ones, the uploads and the assembly carry
/// megabytes: random radiance does not compress away.
#[test]
fn bench_farm_measures_upload_and_assembly_with_noisy_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("bench.json");
    let args = [
        "bench",
        "farm",
        "--workers",
        "2",
        "--tasks",
        "40",
        "--tile-size",
        "32",
        "--noise",
        "--json",
        json.to_str().unwrap(),
    ];
    tessera_ok(&args, dir.path());
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(report["passed"].as_bool(), Some(true), "{report}");
    // 40 tiles of 32x32 pixels: at least the beauty's four f32 channels survive
    // compression, about 16 KiB a tile.
    let uploaded = report["upload_bytes"].as_u64().unwrap();
    assert!(uploaded > 40 * 32 * 32 * 4 * 4, "{report}");
    let assembly = &report["assembly"];
    assert_eq!(assembly["tile_bytes"].as_u64(), Some(uploaded), "{report}");
    assert!(
        assembly["mb_per_second"].as_f64().unwrap() > 0.0,
        "{report}"
    );
}

/// `tessera bench --quick` writes a report with every section: the reference scenes'
/// sweeps and presets, the Cornell box's efficiency, the million-triangle mesh, what each
/// feature costs and the farm against a direct render (real worker processes), and a
/// figure of error against time per scene.
#[test]
fn bench_features_prints_the_feature_table_alone() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "bench", "features", "--size", "8x8", "--spp", "1", "--runs", "1",
    ];
    let table = tessera_ok(&args, dir.path());
    let rows: Vec<&str> = table.lines().filter(|l| l.starts_with("| ")).collect();
    // The header and one row per feature, each with its two speeds.
    assert_eq!(rows.len(), 1 + 13, "{table}");
    for name in [
        "| anisotropy",
        "| iridescence",
        "| volume",
        "| metamaterial",
    ] {
        assert!(table.contains(name), "{name}:\n{table}");
    }
    assert!(
        !dir.path().join("bench-report").exists(),
        "no report is written"
    );
}

#[test]
fn bench_quick_writes_a_report_with_every_section() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "bench",
        "--quick",
        "--size",
        "16x16",
        "--reference-spp",
        "32",
        "--out",
        "report",
    ];
    let markdown = tessera_ok(&args, dir.path());
    let written = std::fs::read_to_string(dir.path().join("report/report.md")).unwrap();
    assert_eq!(markdown, written);
    for heading in [
        "### Cornell box, 256x256",
        "### A generated mesh of 1002528 triangles",
        "### The farm against a direct render",
        "### What each feature costs",
        "### cornell (16x16)",
        "### glossy-glass (16x16)",
        "### motion-blur (16x16)",
    ] {
        assert!(markdown.contains(heading), "{heading}:\n{markdown}");
    }
    let json = std::fs::read_to_string(dir.path().join("report/report.json")).unwrap();
    let report: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(report["scenes"].as_array().unwrap().len(), 3);
    assert_eq!(report["features"].as_array().unwrap().len(), 13);
    assert_eq!(
        report["farm"]["repeats"].as_u64(),
        Some(1),
        "quick: one run"
    );
    let runs = report["farm"]["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 4);
    for run in runs {
        let farm = run["farm_seconds"].as_f64().unwrap();
        let direct = run["direct_seconds"].as_f64().unwrap();
        assert!(farm > 0.0 && direct > 0.0, "{run}");
        // Both ways burn CPU rendering the same frames (this test runs on Linux, where
        // /proc tells).
        let cpu = |key: &str| run[key].as_f64().unwrap_or_else(|| panic!("{key}: {run}"));
        assert!(
            cpu("worker_cpu_seconds") > 0.0 && cpu("direct_cpu_seconds") > 0.0,
            "{run}"
        );
    }
    assert!(report["cornell"]["mse_times_seconds"].as_f64().unwrap() > 0.0);
    let motion = &report["scenes"][2]["motion_sweep"];
    assert_eq!(motion.as_array().unwrap().len(), 6, "{motion}");
    let roulette = &report["scenes"][0]["rr_sweep"];
    assert_eq!(roulette.as_array().unwrap().len(), 5, "{roulette}");
    // A figure per scene, linked from the report.
    for scene in ["cornell", "glossy-glass", "motion-blur"] {
        let plot = format!("plots/{scene}.png");
        assert!(
            markdown.contains(&format!("]({plot})")),
            "{plot}:\n{markdown}"
        );
        let (width, height) = image::image_dimensions(dir.path().join("report").join(&plot))
            .unwrap_or_else(|e| panic!("{plot}: {e}"));
        assert!(width >= 800 && height >= 600, "{plot}: {width}x{height}");
    }
}
