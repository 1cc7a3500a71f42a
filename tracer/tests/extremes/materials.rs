//! Materials and path lengths at the extremes.
//!
//! - The white furnace (a unit sphere in a uniform environment of radiance 1) over the
//!   grid IOR {1, 1.0001, 1.33, 1.5, 2.4, 10} × roughness {0, 1e-4, 0.5, 1} × metallic
//!   {0, 0.5, 1}, and refractive transmission at roughness 0 and 1. With a white base the
//!   BSDF claims to conserve energy in every part (`tracer/src/bsdf.rs`, "Energy"): the
//!   metal and the specular layer are Turquin-compensated (exact for F0 = 1), the diffuse
//!   base gets what the specular layer leaves, and the rough refractive interface has a
//!   multiple-scattering lobe. So every white cell must measure 1 within 1%, and cells
//!   with a grey, black or coloured base (or a glass whose reflection tint is below 1,
//!   which absorbs what total internal reflection would return) lose energy and must stay
//!   at or below 1. Noise: perfectly smooth white cells must be noise-free (every path
//!   has weight 1); the others get three standard errors on top, and a standard error
//!   above 0.03 fails by itself. Rough refraction at IOR 10 has its own test, with more
//!   samples and a flat-shaded sphere: see `furnace_rough_glass_ior_10`.
//! - Path depth in closed boxes: depth 0 shows only emitters seen directly, depth 1 adds
//!   direct light, and no depth (up to 1000) returns more than was emitted.

use glam::{DMat4, DVec3, Vec3, Vec4};
use tracer::bsdf::{Bsdf, SurfaceParams};
use tracer::camera::Projection;
use tracer::film::{Layers, TileBuffer};
use tracer::light::Environment;
use tracer::material::Material;
use tracer::render::{PreparedFrame, RenderSettings};
use tracer::scene::{CameraDef, Scene, SceneBuilder};
use tracer::shapes::{cube, uv_sphere};

use crate::common::Rng;
use crate::support::{assert_finite, options, prepare, render_buffer};

/// Renders the whole frame and also returns the raw sums: the film silently drops NaN or
/// infinite samples, so a finite image alone does not prove that none occurred, and the
/// ray count is the integrator's path-length statistic.
fn render_counted(frame: &PreparedFrame, max_depth: u32, spp: u32) -> (Layers, TileBuffer) {
    let buf = render_buffer(
        frame,
        &RenderSettings {
            noise: None,
            max_depth,
            seed: 0,
            ..RenderSettings::DEFAULT
        },
        spp,
    );
    (buf.resolve(), buf)
}

/// A perspective camera with this vertical field of view, placed by `at`.
fn camera(b: &mut SceneBuilder, yfov: f32, at: DMat4) {
    let def = CameraDef {
        name: None,
        projection: Projection::Perspective {
            yfov,
            aspect_ratio: None,
            znear: 1e-3,
        },
    };
    b.camera(def, at);
}

// ---------------------------------------------------------------------------------------
// White furnace
// ---------------------------------------------------------------------------------------

/// Furnace image size: the sphere covers about 55% of it, silhouette included.
const FURNACE_SIZE: u32 = 24;
/// Deep enough that no path of the furnace is cut short (Russian roulette ends them).
const FURNACE_DEPTH: u32 = 1000;

/// A unit sphere of `material` in a uniform environment of radiance 1, seen from z = 4
/// (as in `white_furnace_conserves_energy` in tests/render.rs). With `flat`, the sphere
/// has no vertex normals: its facets shade with their own normals (see [`Cell::flat`]).
fn furnace(material: Material, flat: bool) -> Scene {
    let mut b = SceneBuilder::default();
    let m = b.material(material);
    let mut sphere = uv_sphere(m, 32, 64);
    if flat {
        sphere.normals.clear();
    }
    b.mesh("sphere", vec![sphere], DMat4::IDENTITY);
    camera(
        &mut b,
        0.6,
        DMat4::from_translation(DVec3::new(0.0, 0.0, 4.0)),
    );
    b.environment(Environment::Constant(Vec3::ONE));
    b.finish()
}

/// What the furnace measured: the sphere's mean radiance per channel and its standard
/// error (from the spread between fully covered pixels).
struct Furnace {
    rgb: Vec3,
    stderr: f32,
}

impl Furnace {
    fn mean(&self) -> f32 {
        (self.rgb.x + self.rgb.y + self.rgb.z) / 3.0
    }
}

/// Renders the furnace of `material` and measures the sphere alone: the background is
/// exactly 1 in every sample, so a pixel of coverage α holds `α · L_sphere + (1 − α)`,
/// and `(Σ L − Σ (1 − α)) / Σ α` is the sphere's mean radiance, silhouette included.
fn measure_furnace(case: &str, material: Material, spp: u32, flat: bool) -> Furnace {
    let frame = prepare(
        furnace(material, flat),
        &options(FURNACE_SIZE, FURNACE_SIZE),
    );
    let (layers, buf) = render_counted(&frame, FURNACE_DEPTH, spp);
    assert_finite(case, &layers);
    assert_eq!(buf.dropped, 0, "{case}: samples were NaN or infinite");
    let (mut sum, mut coverage) = (Vec3::ZERO, 0.0f32);
    let (mut n, mut s1, mut s2) = (0.0f64, 0.0f64, 0.0f64);
    for b in &layers.beauty {
        sum += b.truncate() - Vec3::splat(1.0 - b.w);
        coverage += b.w;
        if b.w == 1.0 {
            let l = f64::from(b.x + b.y + b.z) / 3.0;
            n += 1.0;
            s1 += l;
            s2 += l * l;
        }
    }
    assert!(n > 100.0, "{case}: the sphere covers too few pixels");
    let var = (s2 / n - (s1 / n).powi(2)).max(0.0);
    Furnace {
        rgb: sum / coverage,
        stderr: (var / n).sqrt() as f32,
    }
}

/// What a furnace cell must measure.
#[derive(Clone, Copy, PartialEq)]
enum Expect {
    /// 1 within 1% (plus three standard errors of noise).
    Conserves,
    /// At most 1 in every channel (plus three standard errors of noise).
    Loses,
}

struct Cell {
    name: String,
    material: Material,
    expect: Expect,
    spp: u32,
    /// Render the sphere's facets with their own normals. Interpolated normals disagree
    /// with a facet by up to a few degrees, and the integrator ends a path whose sampled
    /// direction lies between the two tangent planes (it would leak through the surface):
    /// a loss of order 1e-4 per bounce that only light trapped for hundreds of bounces
    /// shows.
    flat: bool,
}

fn white(metallic: f32, roughness: f32, ior: f32, transmission: f32) -> Material {
    Material {
        base_color: Vec4::ONE,
        metallic,
        roughness,
        ior,
        transmission,
        // Solid spheres (KHR_materials_volume), which refract and trap light.
        thickness: 1.0,
        double_sided: true,
        ..Default::default()
    }
}

/// Whether every lobe of `m` is perfectly smooth (mirror, clear interface or both).
fn is_delta(m: &Material) -> bool {
    Bsdf::new(m.factors()).is_delta()
}

/// Samples per pixel for a cell: perfectly smooth cells are deterministic (see
/// [`run_furnace`]), the rest need enough samples for a standard error near 0.1%. Rough
/// refraction needs far more: its paths are long and heavy-tailed, and at 64 or 256 spp
/// a cell's mean strayed up to 1.1% from 1 (within its noise), where at 1024 every cell
/// reads within 0.2%.
fn spp_for(m: &Material) -> u32 {
    if is_delta(m) {
        2
    } else if m.transmission > 0.0 {
        1024
    } else {
        32
    }
}

/// Largest standard error a furnace cell may show: a noisier cell cannot be judged at
/// its sample count (fireflies), and that is a failure too.
const MAX_STDERR: f32 = 0.03;

const IORS: [f32; 6] = [1.0, 1.0001, 1.33, 1.5, 2.4, 10.0];
const ROUGHNESSES: [f32; 4] = [0.0, 1e-4, 0.5, 1.0];

/// Runs the cells, prints one table row each, and panics listing every cell out of
/// bounds. A white, perfectly smooth material in a uniform environment gives every path
/// the weight 1 exactly (each lobe is chosen with the probability of the energy it
/// carries), so such a cell must be noise-free, not just close to 1 on average; the other
/// cells get three standard errors of noise on top of their bound.
fn run_furnace(cells: Vec<Cell>) {
    let mut failures = Vec::new();
    for cell in cells {
        let deterministic = cell.expect == Expect::Conserves && is_delta(&cell.material);
        let f = measure_furnace(&cell.name, cell.material, cell.spp, cell.flat);
        let (noise, noise_ok, noise_rule) = if deterministic {
            (0.0, f.stderr <= 1e-3, "noise-free: stderr <= 0.001")
        } else {
            (
                3.0 * f.stderr,
                f.stderr <= MAX_STDERR,
                "3 x stderr, stderr <= 0.03",
            )
        };
        let (in_bounds, expected, tolerance, measured) = match cell.expect {
            Expect::Conserves => {
                let tol = 0.01 + noise;
                ((f.mean() - 1.0).abs() <= tol, "1", tol, f.mean())
            }
            Expect::Loses => {
                let top = f.rgb.max_element();
                (top <= 1.0 + noise, "<= 1 (largest channel)", noise, top)
            }
        };
        let ok = in_bounds && noise_ok;
        println!(
            "furnace {}: measured {measured:.4} (expected {expected}, tolerance {tolerance:.4}; \
             stderr {:.4}, {noise_rule}; {} spp) {}",
            cell.name,
            f.stderr,
            cell.spp,
            if ok { "ok" } else { "OUT OF BOUNDS" }
        );
        if !ok {
            failures.push(format!(
                "{}: {measured:.4}, stderr {:.4}",
                cell.name, f.stderr
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "furnace cells out of bounds:\n{}",
        failures.join("\n")
    );
}

/// The cells a white base must conserve, except refraction at IOR 10 with roughness 1
/// (see `furnace_rough_glass_ior_10`).
fn white_cells() -> Vec<Cell> {
    let mut cells = Vec::new();
    let mut push = |name: String, material: Material| {
        let spp = spp_for(&material);
        cells.push(Cell {
            name,
            material,
            expect: Expect::Conserves,
            spp,
            flat: false,
        });
    };
    for &roughness in &ROUGHNESSES {
        for metallic in [0.0, 0.5] {
            for &ior in &IORS {
                push(
                    format!("white m={metallic} r={roughness} ior={ior}"),
                    white(metallic, roughness, ior, 0.0),
                );
            }
        }
        // The glTF metal ignores the IOR: one render stands for all six.
        push(
            format!("white m=1 r={roughness} ior=any"),
            white(1.0, roughness, 1.5, 0.0),
        );
    }
    for roughness in [0.0, 1.0] {
        for metallic in [0.0, 0.5] {
            for &ior in &IORS {
                if roughness == 1.0 && ior == 10.0 {
                    continue;
                }
                push(
                    format!("white glass t=1 m={metallic} r={roughness} ior={ior}"),
                    white(metallic, roughness, ior, 1.0),
                );
            }
        }
    }
    // A reflection tint below 1 on a smooth sphere: a chord meets both ends at the same
    // angle, so there is no total internal reflection to absorb and energy is conserved.
    push(
        "white glass specular=0.5 r=0 ior=1.5".into(),
        Material {
            specular: 0.5,
            ..white(0.0, 0.0, 1.5, 1.0)
        },
    );
    cells
}

/// Cells that lose energy: a grey, black or coloured base, and a rough glass whose
/// reflection tint is below 1.
fn lossy_cells() -> Vec<Cell> {
    let mut cells = Vec::new();
    let mut push = |name: String, material: Material| {
        // An upper bound needs fewer samples than a two-sided tolerance.
        let spp = (spp_for(&material) / 4).max(2);
        cells.push(Cell {
            name,
            material,
            expect: Expect::Loses,
            spp,
            flat: false,
        });
    };
    let with_base = |base: Vec3, m: Material| Material {
        base_color: base.extend(1.0),
        ..m
    };
    let grey = Vec3::splat(0.5);
    for metallic in [0.0, 0.5, 1.0] {
        for roughness in [0.0, 0.5, 1.0] {
            push(
                format!("grey m={metallic} r={roughness} ior=1.5"),
                with_base(grey, white(metallic, roughness, 1.5, 0.0)),
            );
        }
    }
    for roughness in [0.0, 1.0] {
        push(
            format!("grey glass t=1 r={roughness} ior=1.5"),
            with_base(grey, white(0.0, roughness, 1.5, 1.0)),
        );
    }
    push(
        "black m=0 r=0.5 ior=1.5 (specular layer alone)".into(),
        with_base(Vec3::ZERO, white(0.0, 0.5, 1.5, 0.0)),
    );
    push(
        "black m=1 r=0.5 (metal F0 = 0)".into(),
        with_base(Vec3::ZERO, white(1.0, 0.5, 1.5, 0.0)),
    );
    push(
        "black glass t=1 r=0 ior=1.5 (reflection alone)".into(),
        with_base(Vec3::ZERO, white(0.0, 0.0, 1.5, 1.0)),
    );
    let colour = Vec3::new(1.0, 0.5, 0.1);
    push(
        "coloured (1, 0.5, 0.1) m=1 r=0.5".into(),
        with_base(colour, white(1.0, 0.5, 1.5, 0.0)),
    );
    push(
        "coloured (1, 0.5, 0.1) m=0 r=0.5 ior=1.5".into(),
        with_base(colour, white(0.0, 0.5, 1.5, 0.0)),
    );
    push(
        "white glass specular=0.5 r=1 ior=1.5 (TIR remainder absorbed)".into(),
        Material {
            specular: 0.5,
            ..white(0.0, 1.0, 1.5, 1.0)
        },
    );
    cells
}

#[test]
fn furnace_material_grid() {
    let mut cells = white_cells();
    cells.extend(lossy_cells());
    run_furnace(cells);
}

/// Refraction at IOR 10 with roughness 1 (metallic 0 and 0.5): the white furnace must
/// still measure 1. Each interaction conserves energy (asserted here per side of the
/// interface, as `bsdf/tests.rs` does), but light that enters such a sphere is trapped by
/// total internal reflection for hundreds of bounces (only directions within 6° of the
/// normal can leave), and three things compound over them:
/// - the spread of the per-bounce weight f·cos/pdf around the albedo makes path weights
///   heavy-tailed: the typical path carries little, rare ones the rest. Splitting paths
///   whose weight grows (`integrator.rs`, `SPLIT_AT`) bounds the weights, but only while
///   a camera sample may still split: with at most 1024 copies, metallic 0.5 read
///   0.93; the 1.0 below needs up to 11,615 (now `MAX_BRANCHES` is 65,536).
/// - the shared albedo tables are right to about 1e-3 per bounce: metallic 0 read 0.958.
///   The material's own albedo curve (`bsdf/curve.rs`) is right to 5e-5.
/// - interpolated normals send light between the facet's and the shading normal's tangent
///   planes; ending those paths read 0.978 and 0.955 at 256 spp. The integrator folds
///   such directions through the facet's plane instead (`integrator.rs`, `fold`), and the
///   sphere is rendered both ways: with its facets' own normals (the BSDF alone) and
///   with interpolated ones.
#[test]
fn furnace_rough_glass_ior_10() {
    let mut rng = Rng(10);
    let bsdf = Bsdf::new(SurfaceParams {
        metallic: 0.0,
        roughness: 1.0,
        ior: 10.0,
        transmission: 1.0,
        ..Default::default()
    });
    for inside in [false, true] {
        for mu in [1.0f32, 0.7, 0.3, 0.05] {
            let wo = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, if inside { -mu } else { mu });
            let eta2 = if inside { 0.01 } else { 100.0 };
            let n = 50_000;
            let mut sum = 0.0f64;
            for _ in 0..n {
                let u = glam::Vec2::new(rng.f32(), rng.f32());
                if let Some(s) = bsdf.sample(wo, rng.f32(), u) {
                    let w = s.f.x * s.wi.z.abs() / s.pdf;
                    assert!(w.is_finite(), "interface ior=10 r=1: weight {w}");
                    // Refraction counted as energy: undo the 1/η² radiance factor.
                    sum += f64::from(if s.wi.z * wo.z < 0.0 { w * eta2 } else { w });
                }
            }
            let e = sum / f64::from(n);
            let side = if inside { "inside" } else { "outside" };
            println!(
                "interface ior=10 r=1 {side} mu={mu}: measured {e:.4} (expected 1, tolerance 0.01)"
            );
            assert!((e - 1.0).abs() <= 0.01, "interface {side} mu={mu}: {e}");
        }
    }
    let mut cells = Vec::new();
    for flat in [true, false] {
        for metallic in [0.0, 0.5] {
            let normals = if flat { "facet" } else { "interpolated" };
            cells.push(Cell {
                name: format!("white glass t=1 m={metallic} r=1 ior=10, {normals} normals"),
                material: white(metallic, 1.0, 10.0, 1.0),
                expect: Expect::Conserves,
                spp: 256,
                flat,
            });
        }
    }
    run_furnace(cells);
}

// ---------------------------------------------------------------------------------------
// Path depth in closed boxes
// ---------------------------------------------------------------------------------------

/// Emitted radiance of the box scenes.
const LE: f32 = 3.0;
/// The depths of the issue.
const DEPTHS: [u32; 4] = [0, 1, 2, 1000];

/// A perfect mirror: white metal with roughness 0 (Schlick with F0 = 1 reflects exactly
/// everything at every angle).
fn mirror() -> Material {
    Material {
        base_color: Vec4::ONE,
        metallic: 1.0,
        roughness: 0.0,
        double_sided: true,
        ..Default::default()
    }
}

/// The closed box [-1, 1]³ of `walls`, with the camera at `eye` looking down -Z.
fn closed_box(walls: Material, yfov: f32, eye: Vec3) -> SceneBuilder {
    let mut b = SceneBuilder::default();
    let w = b.material(walls);
    b.mesh("box", vec![cube(w)], DMat4::from_scale(DVec3::splat(2.0)));
    camera(&mut b, yfov, DMat4::from_translation(eye.as_dvec3()));
    b
}

/// Mean, standard error (from the spread between pixels) and largest value of the
/// beauty's RGB average.
fn pixel_stats(layers: &Layers) -> (f64, f64, f64) {
    let values: Vec<f64> = layers
        .beauty
        .iter()
        .map(|b| f64::from(b.x + b.y + b.z) / 3.0)
        .collect();
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let max = values.iter().cloned().fold(f64::MIN, f64::max);
    (mean, (var / n).sqrt(), max)
}

/// A closed box of perfect mirrors (reflectance 1) with a small black cube inside that
/// emits LE from its faces: known power Φ = π · A · LE with A = 1.5 (six faces of side
/// 0.5). The emitter is the only thing that absorbs, so the box fills up until the
/// emitter absorbs as much as it emits, which happens at radiance LE everywhere: every
/// path ends on the emitter and brings back exactly LE (a mirror of reflectance 1 keeps
/// the throughput at 1), or nothing if it has not found the emitter by the maximum depth.
/// So no pixel ever exceeds LE, deeper paths only add, and at depth 1000 the image is LE
/// (a path finds the emitter after about 16 bounces on average: the emitter's projected
/// area per unit of box volume against the wall-crossing rate, the same for every
/// direction).
///
/// The camera, 0.5 above the emitter's top face and looking down with a 90° field of
/// view, sees that face exactly on the central half of the image (pixels 6 to 17 of 24):
/// depth 0 is LE there and 0 elsewhere. No single mirror image of the emitter is in the
/// field of view (the nearest, through a side wall, is seen at more than 60° off the
/// axis), so depth 1 adds nothing.
#[test]
fn mirror_box_with_an_emitter_inside() {
    const SIZE: u32 = 24;
    const SPP: u32 = 4;
    let mut b = closed_box(
        mirror(),
        std::f32::consts::FRAC_PI_2,
        Vec3::new(0.0, 0.0, 0.75),
    );
    let emitter = b.material(Material {
        base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
        metallic: 0.0,
        specular: 0.0,
        emissive: Vec3::splat(LE),
        double_sided: true,
        ..Default::default()
    });
    b.mesh(
        "emitter",
        vec![cube(emitter)],
        DMat4::from_scale(DVec3::splat(0.5)),
    );
    let frame = prepare(b.finish(), &options(SIZE, SIZE));
    let mut previous: Option<Layers> = None;
    for depth in DEPTHS {
        let case = format!("mirror box with emitter, depth {depth}");
        let (layers, buf) = render_counted(&frame, depth, SPP);
        assert_finite(&case, &layers);
        assert_eq!(buf.dropped, 0, "{case}: samples were NaN or infinite");
        let rays = buf.rays as f64 / f64::from(SIZE * SIZE * SPP);
        let (mean, _, max) = pixel_stats(&layers);
        println!(
            "{case}: measured mean {mean:.4}, max {max:.4}, {rays:.1} rays per path \
             (bound LE = {LE}, tolerance 1e-4 relative)"
        );
        assert!(
            max <= f64::from(LE) * (1.0 + 1e-4),
            "{case}: a pixel holds {max}, more than the emitter's radiance {LE}"
        );
        // A path is at most depth + 1 rays (no shadow rays: everything is a mirror or
        // black), and Russian roulette cannot end it because nothing is lost.
        assert!(rays <= f64::from(depth + 1), "{case}: {rays} rays per path");
        if let Some(prev) = &previous {
            for (i, (now, before)) in layers.beauty.iter().zip(&prev.beauty).enumerate() {
                assert!(
                    now.x >= before.x - 1e-6,
                    "{case}: pixel {i} went down from {} to {} with more depth",
                    before.x,
                    now.x
                );
            }
        }
        // Depth 2 is only bounded: whatever two mirrors show of the emitter.
        let expected_mean = match depth {
            // The emitter's top face fills the central 12 x 12 pixels.
            0 | 1 => {
                for y in 0..SIZE {
                    for x in 0..SIZE {
                        let inside = |c: u32| (6..18).contains(&c);
                        let edge = |c: u32| c == 5 || c == 6 || c == 17 || c == 18;
                        if edge(x) || edge(y) {
                            continue;
                        }
                        let want = if inside(x) && inside(y) { LE } else { 0.0 };
                        let got = layers.beauty[(y * SIZE + x) as usize].x;
                        assert!(
                            (got - want).abs() <= 1e-4 * LE,
                            "{case}: pixel ({x}, {y}) is {got}, expected {want}"
                        );
                    }
                }
                Some(f64::from(LE) * 0.25)
            }
            2 => None,
            _ => Some(f64::from(LE)),
        };
        if let Some(expected) = expected_mean {
            // Depths 0 and 1 are exact up to the rare sample that falls on the emitter's
            // edge; depth 1000 misses the few paths that take that long to find it.
            let tolerance = if depth == 1000 { 0.01 } else { 1e-3 };
            println!(
                "{case}: measured mean {mean:.4} (expected {expected:.4}, tolerance \
                 {tolerance} relative)"
            );
            assert!(
                (mean - expected).abs() <= tolerance * expected,
                "{case}: mean {mean}, expected {expected}"
            );
        }
        previous = Some(layers);
    }
}

/// A closed box whose every wall emits LE and reflects a fraction ρ of what arrives. A
/// path collects LE at every surface it meets, weighted by ρ^k after k reflections, so
/// with maximum depth d every pixel is exactly `LE · (1 + ρ + … + ρ^d)`: depth 0 is LE
/// (emitters seen directly), depth 1 adds ρ · LE (direct light: the irradiance inside a
/// closed enclosure of uniform radiance LE is π · LE, whatever its shape), and the limit
/// is the bound `LE / (1 − ρ)`, never exceeded.
///
/// - ρ = 0.5, Lambertian walls: direct light goes through light sampling with MIS, and
///   Russian roulette (a survival chance of 0.5 per bounce from the third) bounds the
///   path length at depth 1000.
/// - ρ = 1, perfect mirrors: nothing is ever lost, so there is no steady state: the
///   radiance grows by LE with every bounce, `(d + 1) · LE`, without bound as the depth
///   grows. Russian roulette cannot end a path whose throughput stays 1, so the maximum
///   depth alone bounds the work, and the estimate must be exactly `(d + 1) · LE`, never
///   more.
#[test]
fn closed_emitting_boxes() {
    const SIZE: u32 = 16;
    let diffuse = |rho: f32| Material {
        base_color: Vec4::new(rho, rho, rho, 1.0),
        metallic: 0.0,
        specular: 0.0,
        emissive: Vec3::splat(LE),
        double_sided: true,
        ..Default::default()
    };
    let emitting_mirror = Material {
        emissive: Vec3::splat(LE),
        ..mirror()
    };
    for (name, walls, rho, spp) in [
        ("diffuse rho=0.5", diffuse(0.5), 0.5f64, 16),
        ("mirror rho=1", emitting_mirror, 1.0, 1),
    ] {
        let b = closed_box(walls, 1.2, Vec3::new(0.1, -0.2, 0.3));
        let frame = prepare(b.finish(), &options(SIZE, SIZE));
        for depth in DEPTHS {
            let case = format!("emitting box {name}, depth {depth}");
            let (layers, buf) = render_counted(&frame, depth, spp);
            assert_finite(&case, &layers);
            assert_eq!(buf.dropped, 0, "{case}: samples were NaN or infinite");
            let rays = buf.rays as f64 / f64::from(SIZE * SIZE * spp);
            let (mean, stderr, max) = pixel_stats(&layers);
            let expected = f64::from(LE) * (0..=depth).map(|k| rho.powi(k as i32)).sum::<f64>();
            let bound = if rho < 1.0 {
                f64::from(LE) / (1.0 - rho)
            } else {
                expected
            };
            // The mirror box is deterministic; the diffuse one has light-sampling noise.
            let tolerance = if rho < 1.0 {
                0.01 + 3.0 * stderr / expected
            } else {
                1e-4
            };
            println!(
                "{case}: measured {mean:.4} (expected {expected:.4}, tolerance {tolerance:.4} \
                 relative; bound {bound:.4}, largest pixel {max:.4}; {rays:.2} rays per path)"
            );
            assert!(
                (mean - expected).abs() <= tolerance * expected,
                "{case}: mean {mean}, expected {expected}"
            );
            assert!(
                mean <= bound * (1.0 + tolerance),
                "{case}: mean {mean} above the bound {bound}"
            );
            if rho == 1.0 {
                // Nothing is lost, so nothing is random: every pixel, every sample.
                assert!(
                    max <= expected * (1.0 + 1e-4),
                    "{case}: a pixel holds {max}"
                );
                assert_eq!(rays, f64::from(depth + 1), "{case}: rays per path");
            } else {
                // Camera ray, then a bounce ray and a shadow ray per bounce: Russian
                // roulette ends paths long before depth 1000 (about 5 bounces).
                assert!(rays < 16.0, "{case}: {rays} rays per path");
            }
        }
    }
}
