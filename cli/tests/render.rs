//! The real `tessera render` binary, as a user runs it.

use std::path::Path;
use std::process::{Command, Output};

use tracer::film::TileRect;
use tracer::output::read_exr;

fn tessera(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tessera"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("tessera runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn renders_the_demo_to_a_multilayer_exr_and_a_preview() {
    let dir = tempfile::tempdir().unwrap();
    let o = tessera(
        &[
            "render", "--size", "24x24", "--spp", "4", "--out", "demo.exr",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let summary = String::from_utf8_lossy(&o.stdout);
    assert!(
        summary.contains("M rays/s") && summary.contains("dropped"),
        "{summary}"
    );

    let img = read_exr(&dir.path().join("demo.exr")).unwrap();
    assert_eq!(img.frame_size, (24, 24));
    assert_eq!(img.layers.rect, TileRect::new(0, 0, 24, 24));
    // A square view of the demo sees only the inside of the closed box.
    assert!(img
        .layers
        .beauty
        .iter()
        .all(|b| b.is_finite() && b.w == 1.0));
    assert!(img
        .layers
        .normal
        .iter()
        .all(|n| (n.length() - 1.0).abs() < 1e-3));
    assert_eq!(img.attribute("tessera/spp"), Some("4"));
    let png = image::open(dir.path().join("demo.png")).unwrap();
    assert_eq!((png.width(), png.height()), (24, 24));
}

#[test]
fn a_region_keeps_the_full_frame_as_display_window_and_matches_the_full_render() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["render", "--size", "32x24", "--spp", "2", "--seed", "7"];
    let full = tessera(&[&args[..], &["--out", "full.exr"]].concat(), dir.path());
    assert!(full.status.success(), "{}", stderr(&full));
    let part = tessera(
        &[&args[..], &["--region", "5,6,10,8", "--out", "part.exr"]].concat(),
        dir.path(),
    );
    assert!(part.status.success(), "{}", stderr(&part));

    let full = read_exr(&dir.path().join("full.exr")).unwrap();
    let part = read_exr(&dir.path().join("part.exr")).unwrap();
    assert_eq!(part.frame_size, (32, 24));
    let region = TileRect::new(5, 6, 10, 8);
    assert_eq!(part.layers.rect, region);
    assert!(
        part.layers == full.layers.crop(region),
        "region pixels differ from the full render"
    );
}

#[test]
fn bad_arguments_are_refused_with_a_clear_message() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&[&str], &str); 9] = [
        (&["render", "--size", "0x10"], "each side must be"),
        (&["render", "--frames", "5-1"], "ends before it starts"),
        (&["render", "--shutter", "0.5,0"], "after it closes"),
        (&["render", "--motion-steps", "0"], "--motion-steps 0"),
        (&["render", "--animation", "walk"], "animation"),
        (&["render", "--spp", "0"], "--spp 0"),
        (
            &["render", "--region", "30,0,10,10", "--size", "32x24"],
            "does not fit",
        ),
        (&["render", "missing.gltf"], "missing.gltf"),
        (&["render", "--camera", "7"], "camera 7"),
    ];
    for (args, message) in cases {
        let o = tessera(args, dir.path());
        assert!(!o.status.success(), "{args:?} should fail");
        assert!(stderr(&o).contains(message), "{args:?}: {}", stderr(&o));
    }
}

#[test]
fn a_sequence_of_the_animated_demo_moves_and_blurs() {
    let dir = tempfile::tempdir().unwrap();
    let o = tessera(
        &[
            "render",
            "--frames",
            "1-3",
            "--fps",
            "24",
            "--shutter",
            "-0.25,0.25",
            "--size",
            "24x24",
            "--spp",
            "2",
            "--out",
            "seq",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("wrote 3 frame(s)"), "{stdout}");
    let frames: Vec<_> = (1..=3)
        .map(|f| {
            let exr = dir.path().join(format!("seq/frame_{f:04}.exr"));
            assert!(
                exr.with_extension("png").is_file(),
                "no preview for frame {f}"
            );
            read_exr(&exr).unwrap()
        })
        .collect();
    for (f, img) in (1..=3).zip(&frames) {
        assert_eq!(img.attribute("tessera/frame"), Some(f.to_string().as_str()));
        assert_eq!(img.attribute("tessera/shutter"), Some("-0.25,0.25"));
        let steps: u32 = img
            .attribute("tessera/motion-steps")
            .unwrap()
            .parse()
            .unwrap();
        assert!(steps >= 2, "frame {f}: {steps} motion steps");
        assert!(img
            .attribute("tessera/features")
            .unwrap()
            .contains("animation"));
        assert!(img.layers.beauty.iter().all(|b| b.is_finite()));
    }
    assert!(frames[0].layers.beauty != frames[2].layers.beauty);
}
