//! Whole renders against known answers: white furnace, closed-form irradiance, and the
//! determinism of tiles, sample ranges and regions.

// Test scenes and closed forms use the platform's maths; tracer::math is for the tracer.
#![allow(clippy::disallowed_methods)]

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use glam::{DMat4, DQuat, DVec3, Vec3, Vec4};

use tracer::camera::Projection;
use tracer::film::{Layers, SampleRange, TileBuffer, TileRect};
use tracer::light::{Environment, PunctualLight};
use tracer::material::Material;
use tracer::render::{
    prepare_frame, render_region, render_tile, render_tile_cancellable, FrameOptions,
    PreparedFrame, RenderSettings,
};
use tracer::scene::{CameraDef, Scene, SceneBuilder};
use tracer::shapes::{quad, uv_sphere};

mod common;
use common::{cornell_frame, demo_frame, frame, furnace, render};

/// Mean radiance over the pixels fully covered by geometry, and over the background.
fn furnace_means(layers: &Layers) -> (f64, f64) {
    let (mut hit, mut nh, mut miss, mut nm) = (0.0, 0, 0.0, 0);
    for b in &layers.beauty {
        let l = (b.x + b.y + b.z) as f64 / 3.0;
        if b.w == 1.0 {
            hit += l;
            nh += 1;
        } else if b.w == 0.0 {
            miss += l;
            nm += 1;
        }
    }
    assert!(nh > 100 && nm > 100, "sphere and background both visible");
    (hit / nh as f64, miss / nm as f64)
}

#[test]
fn white_furnace_conserves_energy() {
    let white = Material {
        base_color: Vec4::ONE,
        double_sided: true,
        ..Default::default()
    };
    let cases = [
        (
            "diffuse albedo 1",
            Material {
                metallic: 0.0,
                specular: 0.0,
                ..white.clone()
            },
        ),
        (
            "rough dielectric",
            Material {
                metallic: 0.0,
                roughness: 0.4,
                transmission: 1.0,
                thickness: 1.0,
                ..white.clone()
            },
        ),
        (
            "metal F0 = 1",
            Material {
                metallic: 1.0,
                roughness: 0.3,
                ..white.clone()
            },
        ),
    ];
    for (name, material) in cases {
        let f = frame(furnace(material), 40, 40);
        let settings = RenderSettings {
            noise: None,
            max_depth: 64,
            seed: 0,
            ..RenderSettings::DEFAULT
        };
        let layers = render(&f, &settings, 64).resolve();
        let (sphere, background) = furnace_means(&layers);
        println!("{name}: sphere {sphere:.4}, background {background:.4}");
        assert!(
            (background - 1.0).abs() < 1e-6,
            "{name}: background {background}"
        );
        assert!(
            (sphere - 1.0).abs() < 0.01,
            "{name}: sphere {sphere}, expected 1 ± 1%"
        );
    }
}

/// A white Lambertian floor (y = 0), seen from above by an orthographic camera so narrow
/// that each pixel sees practically one point.
/// `extra` adds more to the scene before it is finished.
fn lit_floor(
    light: PunctualLight,
    light_at: DMat4,
    extra: impl FnOnce(&mut SceneBuilder),
) -> Scene {
    let mut b = SceneBuilder::default();
    let white = b.material(Material {
        base_color: Vec4::ONE,
        metallic: 0.0,
        specular: 0.0,
        double_sided: true,
        ..Default::default()
    });
    let s = 100.0;
    let floor = quad(
        [
            Vec3::new(-s, 0.0, s),
            Vec3::new(s, 0.0, s),
            Vec3::new(s, 0.0, -s),
            Vec3::new(-s, 0.0, -s),
        ],
        white,
    );
    b.mesh("floor", vec![floor], DMat4::IDENTITY);
    let down = DMat4::from_rotation_translation(
        DQuat::from_rotation_x(-std::f64::consts::FRAC_PI_2),
        DVec3::new(0.0, 1.0, 0.0),
    );
    let camera = CameraDef {
        name: None,
        projection: Projection::Orthographic {
            xmag: 1e-3,
            ymag: 1e-3,
            znear: 0.0,
        },
    };
    b.camera(camera, down);
    b.light(light, light_at);
    extra(&mut b);
    b.finish()
}

fn mean_radiance(layers: &Layers) -> f64 {
    layers.beauty.iter().map(|b| b.x as f64).sum::<f64>() / layers.beauty.len() as f64
}

/// Mean radiance of a [`lit_floor`] scene under direct light only.
fn direct_floor_radiance(scene: Scene) -> f64 {
    let settings = RenderSettings {
        noise: None,
        max_depth: 1,
        seed: 0,
        ..RenderSettings::DEFAULT
    };
    mean_radiance(&render(&frame(scene, 8, 8), &settings, 4).resolve())
}

#[test]
fn point_light_on_a_plane_matches_closed_form_irradiance() {
    // E = I cosθ / d², and a white Lambertian surface reflects L = E / π.
    let (intensity, height) = (10.0f32, 2.0f64);
    let light = PunctualLight::Point {
        intensity: Vec3::splat(intensity),
        range: None,
    };
    let scene = lit_floor(
        light,
        DMat4::from_translation(DVec3::new(0.0, height, 0.0)),
        |_| {},
    );
    let expected = intensity as f64 / (std::f64::consts::PI * height * height);
    let got = direct_floor_radiance(scene);
    assert!(
        (got / expected - 1.0).abs() < 0.01,
        "got {got}, expected {expected}"
    );
}

#[test]
fn directional_light_on_a_plane_matches_closed_form_irradiance() {
    // 1 lux arriving 60° from the normal: E = cos 60° = 0.5, L = 0.5 / π.
    let light = PunctualLight::Directional {
        illuminance: Vec3::ONE,
    };
    let tilt = DMat4::from_rotation_x(-std::f64::consts::FRAC_PI_2 + std::f64::consts::FRAC_PI_3);
    let expected = (std::f64::consts::FRAC_PI_3).cos().abs() / std::f64::consts::PI;
    let got = direct_floor_radiance(lit_floor(light, tilt, |_| {}));
    assert!(
        (got / expected - 1.0).abs() < 0.01,
        "got {got}, expected {expected}"
    );
}

#[test]
fn any_tile_split_is_bit_identical_to_the_whole_frame() {
    let f = demo_frame();
    let settings = RenderSettings::default();
    let rect = TileRect::new(0, 0, 24, 24);
    let samples = SampleRange::new(0, 4);
    let whole = render_tile(&f, &settings, rect, samples);
    for tile_size in [1, 5, 7, 16] {
        let split = render_region(&f, &settings, rect, samples, tile_size, &|_| {});
        assert!(
            whole == split,
            "tiles of {tile_size} differ from the whole frame"
        );
    }
    // One-pixel-wide columns too.
    let mut columns = TileBuffer::new(rect);
    for x in 0..24 {
        columns.paste(&render_tile(
            &f,
            &settings,
            TileRect::new(x, 0, 1, 24),
            samples,
        ));
    }
    assert!(whole == columns, "one-pixel columns differ");
    assert_eq!(whole.dropped, 0);
}

/// `render_tile` traces each pixel's samples as one run (`trace_samples`): a run must be
/// its samples traced one by one, whatever came before in it (split paths among them),
/// and end where its callback says.
#[test]
fn a_pixels_run_of_samples_is_its_samples_traced_one_by_one() {
    use tracer::film::SampleValue;
    use tracer::integrator::{trace_sample, trace_samples};

    let f = demo_frame();
    for spectral in [false, true] {
        let settings = RenderSettings {
            spectral,
            ..RenderSettings::default()
        };
        for (x, y) in [(3, 4), (12, 12), (20, 7)] {
            let mut run: Vec<(u32, SampleValue)> = Vec::new();
            trace_samples(&f, &settings, x, y, 5..17, &mut |i, v| {
                run.push((i, *v));
                true
            });
            let one_by_one: Vec<(u32, SampleValue)> = (5..17)
                .map(|i| (i, trace_sample(&f, &settings, x, y, i)))
                .collect();
            assert!(run == one_by_one, "pixel {x},{y}, spectral {spectral}");
            let mut stopped = Vec::new();
            trace_samples(&f, &settings, x, y, 5..17, &mut |i, _| {
                stopped.push(i);
                i < 8
            });
            assert_eq!(stopped, [5, 6, 7, 8]);
        }
    }
}

/// The Cornell box (nothing moves) as frame `number`.
#[test]
fn a_fixed_pattern_gives_a_still_scene_the_same_noise_on_every_frame() {
    let own = RenderSettings::default();
    let fixed = RenderSettings {
        fixed_pattern: true,
        ..own
    };
    let frames: Vec<PreparedFrame> = [0, 1, 7].into_iter().map(cornell_frame).collect();
    let image = |f: &PreparedFrame, s: &RenderSettings| render(f, s, 2).resolve();
    // Each frame its own pattern: the same still scene, other noise.
    assert!(image(&frames[1], &own) != image(&frames[2], &own));
    // A fixed pattern: every frame is the noise of frame 0's.
    let zero = image(&frames[0], &own);
    assert!(image(&frames[1], &fixed) == zero);
    assert!(image(&frames[2], &fixed) == zero);
    // The seed still changes it.
    let reseeded = RenderSettings { seed: 3, ..fixed };
    assert!(image(&frames[1], &reseeded) != zero);
}

#[test]
fn a_cancellable_render_finishes_identically_or_stops_when_cancelled() {
    let f = demo_frame();
    let settings = RenderSettings::default();
    let rect = TileRect::new(2, 3, 10, 7);
    let samples = SampleRange::new(0, 3);
    let go = AtomicBool::new(false);
    let finished = render_tile_cancellable(&f, &settings, rect, samples, &go);
    assert!(finished == Some(render_tile(&f, &settings, rect, samples)));
    let stop = AtomicBool::new(true);
    assert!(render_tile_cancellable(&f, &settings, rect, samples, &stop).is_none());
}

#[test]
fn sample_ranges_merge_to_the_whole_range() {
    let f = demo_frame();
    let settings = RenderSettings::default();
    let rect = TileRect::new(3, 2, 12, 9);
    let whole = render_tile(&f, &settings, rect, SampleRange::new(0, 9)).resolve();
    let mut merged = render_tile(&f, &settings, rect, SampleRange::new(0, 4));
    merged.merge(&render_tile(&f, &settings, rect, SampleRange::new(4, 9)));
    let merged = merged.resolve();
    for (a, b) in whole.beauty.iter().zip(&merged.beauty) {
        assert!(
            (*a - *b).abs().max_element() <= 1e-5 * a.abs().max_element().max(1.0),
            "{a} vs {b}"
        );
    }
}

#[test]
fn a_region_equals_the_crop_of_the_full_render() {
    let f = demo_frame();
    let settings = RenderSettings::default();
    let full = render(&f, &settings, 3).resolve();
    let region = TileRect::new(5, 4, 11, 7);
    let part = render_region(&f, &settings, region, SampleRange::new(0, 3), 4, &|_| {}).resolve();
    assert!(part == full.crop(region));
}

#[test]
fn the_demo_scene_renders_finite_plausible_pixels() {
    let f = demo_frame();
    let tile = render(&f, &RenderSettings::default(), 16);
    assert_eq!(tile.dropped, 0, "no sample was NaN or infinite");
    let layers = tile.resolve();
    assert!(layers
        .beauty
        .iter()
        .all(|b| b.is_finite() && b.min_element() >= 0.0));
    // The square view sees only the inside of the closed box, so every camera ray hits.
    assert!(layers.beauty.iter().all(|b| b.w == 1.0));
    let mean = mean_radiance(&layers);
    assert!(mean > 0.05 && mean < 5.0, "mean red radiance {mean}");
    assert!(layers.depth.iter().all(|d| *d > 0.0 && *d < 10.0));
}

#[test]
fn an_importance_sampled_environment_map_lights_a_furnace_like_a_constant_one() {
    // A map that is 1 everywhere but for a bright patch: the importance sampler sends most
    // light samples to the patch, yet a white diffuse sphere must still see the map's mean
    // irradiance, i.e. the estimate stays unbiased. With uniform radiance 1 it is exactly
    // the furnace; here we compare against a constant environment of the same mean.
    let (w, h) = (64, 32);
    let mut pixels = vec![Vec3::ONE; w * h];
    for y in 8..12 {
        for x in 20..26 {
            pixels[y * w + x] = Vec3::splat(50.0);
        }
    }
    let map = tracer::light::EnvironmentMap::from_pixels(w, h, pixels).unwrap();
    let white = Material {
        base_color: Vec4::ONE,
        metallic: 0.0,
        specular: 0.0,
        double_sided: true,
        ..Default::default()
    };
    let uniform = tracer::light::EnvironmentMap::from_pixels(w, h, vec![Vec3::ONE; w * h]).unwrap();
    let render_with = |env: Environment, spp: u32, seed: u32| {
        let options = FrameOptions {
            width: 24,
            height: 24,
            environment: Some(env),
            ..Default::default()
        };
        let f = prepare_frame(Arc::new(furnace(white.clone())), &options).unwrap();
        render(
            &f,
            &RenderSettings {
                noise: None,
                max_depth: 8,
                seed,
                ..RenderSettings::DEFAULT
            },
            spp,
        )
        .resolve()
    };
    let (sphere, _) = furnace_means(&render_with(Environment::Map(uniform), 64, 0));
    assert!((sphere - 1.0).abs() < 0.01, "uniform map furnace {sphere}");

    // The patched map against a reference with many more samples and another seed.
    let mapped = render_with(Environment::Map(map.clone()), 64, 1);
    let reference = render_with(Environment::Map(map), 1024, 2);
    let (a, _) = furnace_means(&mapped);
    let (b, _) = furnace_means(&reference);
    assert!((a / b - 1.0).abs() < 0.02, "64 spp {a} vs 1024 spp {b}");
    assert!(b > 1.0, "the bright patch adds light: {b}");
}

#[test]
fn alpha_masked_cut_outs_let_light_through_for_shadow_rays_too() {
    // A masked sheet between the point light and the floor: below the cutoff it is cut
    // away (the floor gets the full closed-form irradiance), above it the floor is in shadow.
    let (intensity, height) = (10.0f32, 2.0f64);
    let floor_radiance = |alpha: f32| {
        let light = PunctualLight::Point {
            intensity: Vec3::splat(intensity),
            range: None,
        };
        let sheet = |b: &mut SceneBuilder| {
            let m = b.material(Material {
                base_color: Vec4::new(1.0, 1.0, 1.0, alpha),
                alpha_mode: tracer::material::AlphaMode::Mask { cutoff: 0.5 },
                double_sided: true,
                ..Default::default()
            });
            let s = 0.5;
            let corners = [
                Vec3::new(-s, 1.5, s),
                Vec3::new(s, 1.5, s),
                Vec3::new(s, 1.5, -s),
                Vec3::new(-s, 1.5, -s),
            ];
            b.mesh("sheet", vec![quad(corners, m)], DMat4::IDENTITY);
        };
        let at = DMat4::from_translation(DVec3::new(0.0, height, 0.0));
        direct_floor_radiance(lit_floor(light, at, sheet))
    };
    let lit = intensity as f64 / (std::f64::consts::PI * height * height);
    let cut_away = floor_radiance(0.2);
    assert!(
        (cut_away / lit - 1.0).abs() < 0.01,
        "cut-out sheet: {cut_away}, expected {lit}"
    );
    let solid = floor_radiance(0.8);
    assert_eq!(
        solid, 0.0,
        "an opaque part of the sheet casts a full shadow"
    );
}

/// Russian roulette is unbiased: the Cornell box with it from the first bounce and without
/// it has the same mean radiance (within noise), and the roulette traces fewer rays.
#[test]
fn russian_roulette_saves_rays_without_changing_the_mean() {
    let frame = frame(tracer::demo::cornell_box(), 16, 16);
    let at = |russian_roulette| {
        let settings = RenderSettings {
            russian_roulette,
            ..RenderSettings::DEFAULT
        };
        let tile = render(&frame, &settings, 256);
        (mean_radiance(&tile.resolve()), tile.rays)
    };
    let (never, never_rays) = at(None);
    let (first, first_rays) = at(Some(1));
    assert!(
        (first - never).abs() < 0.02 * never,
        "mean {first} with roulette from bounce 1, {never} without"
    );
    assert!(
        (first_rays as f64) < 0.8 * never_rays as f64,
        "{first_rays} rays with roulette, {never_rays} without"
    );
}

/// The Cornell box's lamp lights the room below it and nothing above, as the measured
/// box's does: seen from the 2 mm gap between lamp and ceiling, the ceiling there gets
/// only what leaks in from the sides. (With the lamp lit from both faces this read 19.5:
/// the ceiling and the lamp's back reflect each other there, and the camera saw it through
/// a sliver at the lamp's near edge.)
#[test]
fn the_cornell_lamp_lights_only_the_room_below() {
    let mut scene = tracer::demo::cornell_box();
    let camera = scene
        .nodes
        .iter_mut()
        .find(|n| n.camera.is_some())
        .expect("the box has a camera");
    // In the gap (the lamp at y = 1.998, the ceiling at 2), looking up.
    camera.local = DMat4::from_rotation_translation(
        DQuat::from_rotation_x(std::f64::consts::FRAC_PI_2),
        DVec3::new(0.0, 1.999, 0.0),
    );
    let settings = RenderSettings {
        max_depth: 4,
        seed: 0,
        ..RenderSettings::DEFAULT
    };
    let lit = render(&frame(scene, 8, 8), &settings, 64).resolve();
    assert!(
        lit.beauty.iter().all(|b| b.w == 1.0),
        "the camera sees the ceiling"
    );
    let mean = mean_radiance(&lit);
    assert!(mean < 0.5, "the ceiling above the lamp reads {mean}");
}

/// A hash of every bit of every layer.
fn layers_hash(layers: &Layers) -> u64 {
    let words = layers
        .beauty
        .iter()
        .flat_map(|p| p.to_array())
        .chain(layers.albedo.iter().flat_map(|p| p.to_array()))
        .chain(layers.normal.iter().flat_map(|p| p.to_array()))
        .chain(layers.depth.iter().copied());
    words.fold(0xcbf29ce484222325u64, |h, w| {
        (h ^ u64::from(w.to_bits())).wrapping_mul(0x100000001b3)
    })
}

/// The farm compares tiles from different workers bit for bit, so a pixel must not
/// depend on the CPU that traced it. These renders touch every transcendental function
/// of the tracer (GGX and light sampling, slerped motion blur, the environment map's
/// angles, a spot cone) and must give the bits this machine's class gave when the
/// constants were written; CI runs them on whatever CPU it gets.
#[test]
fn every_machine_renders_the_same_bits() {
    // Both compiled copies of the path loop and the BVH node test: AVX's, where this CPU
    // has it, and SSE2's, which a CPU without AVX runs (the switch is process-wide; other
    // tests running meanwhile get the same bits either way, which is what this checks).
    if !tracer::simd::avx() {
        // Straight to stderr, past the test harness's capture: a skip must be seen.
        use std::io::Write;
        let _ = writeln!(
            std::io::stderr(),
            "WARNING: this CPU has no AVX: only the SSE2 copy is checked"
        );
    }
    for avx in [true, false] {
        tracer::simd::allow_avx(avx);
        let copy = if tracer::simd::avx() { "AVX" } else { "SSE2" };
        assert_eq!(
            renders_that_touch_every_function(),
            [4850733489281474494, 2190308934475342347],
            "this machine renders other bits ({copy} copy) than the machine that wrote the \
             constants: CPU-dependent maths reached the tracer (a platform sin, exp \
             or pow, or a SIMD path whose lanes round differently). If the image changed on \
             purpose, these are the new constants."
        );
    }
    tracer::simd::allow_avx(true);
}

/// The hashes of two small renders that touch every transcendental function of the tracer.
fn renders_that_touch_every_function() -> [u64; 2] {
    // The animated demo at frame 12 with a 180° shutter: metal, glass, a moving box.
    let options = FrameOptions {
        frame: 12,
        width: 24,
        height: 24,
        shutter: tracer::motion::Shutter {
            open: -0.25,
            close: 0.25,
        },
        ..Default::default()
    };
    let demo = prepare_frame(Arc::new(tracer::demo::animated_demo_scene()), &options).unwrap();
    let demo = render(&demo, &RenderSettings::default(), 4).resolve();

    // A glossy sphere in an environment map with a bright patch, under a spot light.
    let (w, h) = (32, 16);
    let mut pixels = vec![Vec3::new(0.2, 0.3, 0.5); w * h];
    pixels[5 * w + 9] = Vec3::splat(40.0);
    let map = tracer::light::EnvironmentMap::from_pixels(w, h, pixels).unwrap();
    let mut b = SceneBuilder::default();
    let m = b.material(Material {
        base_color: Vec4::new(0.8, 0.5, 0.3, 1.0),
        roughness: 0.3,
        ..Default::default()
    });
    b.mesh("sphere", vec![uv_sphere(m, 16, 32)], DMat4::IDENTITY);
    let spot = PunctualLight::Spot {
        intensity: Vec3::splat(30.0),
        range: None,
        inner_cone: 0.2,
        outer_cone: 0.5,
    };
    b.light(spot, DMat4::from_translation(DVec3::new(0.0, 0.0, 3.0)));
    let camera = CameraDef {
        name: None,
        projection: Projection::Perspective {
            yfov: 0.7,
            aspect_ratio: None,
            znear: 0.01,
        },
    };
    b.camera(camera, DMat4::from_translation(DVec3::new(0.0, 0.5, 4.0)));
    b.environment(Environment::Map(map));
    let lit = render(&frame(b.finish(), 24, 24), &RenderSettings::default(), 4).resolve();

    [layers_hash(&demo), layers_hash(&lit)]
}
