//! KHR_materials_dispersion: a prism bends each wavelength by its own IOR, which the
//! spectral path follows; the image of a thin slit of white light seen through it matches
//! the one that Snell's and Fresnel's laws give per wavelength.

use std::sync::Arc;

use glam::{DMat4, DVec3, DVec4, Vec2, Vec3};

use tracer::camera::Projection;
use tracer::film::{Layers, TileRect};
use tracer::light::Environment;
use tracer::material::{dispersive_ior, Material};
use tracer::math;
use tracer::render::{prepare_frame, FrameOptions, PreparedFrame, RenderSettings};
use tracer::scene::{CameraDef, SceneBuilder};
use tracer::shapes::{prism, quad};
use tracer::spectrum::{self, DenseSpectrum, SpectrumShape, LAMBDA_MAX, LAMBDA_MIN, XYZ_TO_REC709};

mod common;

/// The spec's formula at the Fraunhofer lines it is built from: n_d at the d line and
/// n_F − n_C = (n_d − 1) / V, V = 20 / dispersion; no dispersion leaves the IOR alone,
/// and no IOR falls below 1.
#[test]
fn the_ior_follows_the_abbe_number() {
    for (ior, dispersion) in [(1.5, 0.33), (2.42, 0.36), (1.33, 1.0), (1.5, 2.0)] {
        let abbe = 20.0 / dispersion;
        let n = |nm| dispersive_ior(ior, dispersion, nm);
        assert!((n(587.56) - ior).abs() < 1e-4, "n_d {}", n(587.56));
        let spread = n(486.13) - n(656.27);
        let want = (ior - 1.0) / abbe;
        assert!((spread - want).abs() < 1e-3 * want, "{spread} vs {want}");
        assert!(n(400.0) > n(500.0) && n(500.0) > n(700.0));
        assert_eq!(dispersive_ior(ior, 0.0, 450.0), ior);
    }
    assert_eq!(dispersive_ior(1.01, 50.0, 830.0), 1.0);
}

/// The image: 256 columns (14° across) by 4 rows, so each row is a ray fan in one plane.
const WIDTH: u32 = 256;
const HEIGHT: u32 = 4;
/// The prism's apex angle and its IOR at the d line.
const APEX: f64 = std::f64::consts::FRAC_PI_3;
const IOR: f32 = 1.5;
/// The slit: this far from the prism, this many radians wide.
const SLIT_DISTANCE: f64 = 1000.0;
const SLIT_WIDTH: f64 = 0.008;

/// A plane: a point on it and its unit normal.
#[derive(Clone, Copy)]
struct Plane {
    point: DVec3,
    normal: DVec3,
}

impl Plane {
    /// Where a ray from `o` along `d` meets it.
    fn hit(&self, o: DVec3, d: DVec3) -> DVec3 {
        o + d * ((self.point - o).dot(self.normal) / d.dot(self.normal))
    }
}

/// The prism's local frame in the world: light along local +x travels along world −z,
/// local +y (towards the apex) is world +x, and the camera at the origin looks at the
/// left face from 6 units away, 3 below the apex.
fn prism_to_world() -> DMat4 {
    DMat4::from_cols(
        DVec4::new(0.0, 0.0, -1.0, 0.0),
        DVec4::new(1.0, 0.0, 0.0, 0.0),
        DVec4::new(0.0, -1.0, 0.0, 0.0),
        DVec4::new(-3.0, 0.0, -6.0, 1.0),
    )
}

const PRISM_HEIGHT: f64 = 4.0;

/// The prism's entry and exit faces in the world, normals outwards.
fn faces() -> [Plane; 2] {
    let m = prism_to_world();
    let half = APEX / 2.0;
    let apex = m.transform_point3(DVec3::new(0.0, PRISM_HEIGHT, 0.0));
    let (sin, cos) = math::sin_cos_f64(half);
    [-1.0, 1.0].map(|side| Plane {
        point: apex,
        normal: m.transform_vector3(DVec3::new(side * cos, sin, 0.0)),
    })
}

/// `d` refracted through a surface of normal `n` (facing `d`'s side) from index `from`
/// into index `to`, with the share of the energy that passes (Fresnel, unpolarised);
/// `None` on total internal reflection.
fn refract(d: DVec3, n: DVec3, from: f64, to: f64) -> Option<(DVec3, f64)> {
    let eta = from / to;
    let cos_i = -d.dot(n);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let t = eta * d + (eta * cos_i - cos_t) * n;
    let rs = (from * cos_i - to * cos_t) / (from * cos_i + to * cos_t);
    let rp = (to * cos_i - from * cos_t) / (to * cos_i + from * cos_t);
    Some((t, 1.0 - 0.5 * (rs * rs + rp * rp)))
}

/// A camera ray through the prism at IOR `n`: where it leaves, its direction, the share
/// of its energy that passes both faces, and the distance it travels inside.
fn through_prism(o: DVec3, d: DVec3, n: f64) -> Option<(DVec3, DVec3, f64, f64)> {
    let [entry, exit] = faces();
    let p1 = entry.hit(o, d);
    let (d1, t1) = refract(d, entry.normal, 1.0, n)?;
    let p2 = exit.hit(p1, d1);
    let (d2, t2) = refract(d1, -exit.normal, n, 1.0)?;
    Some((p2, d2.normalize(), t1 * t2, (p2 - p1).length()))
}

/// The slit: a plane far behind the prism facing the light that the image's middle ray
/// brings at the d line, and the axis across it.
struct Slit {
    plane: Plane,
    across: DVec3,
}

fn slit() -> Slit {
    // The camera sits at the origin looking down −z.
    let (p, d, _, _) = through_prism(DVec3::ZERO, DVec3::NEG_Z, f64::from(IOR))
        .expect("the middle ray passes the prism");
    Slit {
        plane: Plane {
            point: p + d * SLIT_DISTANCE,
            normal: -d,
        },
        across: d.cross(DVec3::Y).normalize(),
    }
}

/// The slit's half width and half height.
const SLIT_HALF: (f64, f64) = (SLIT_DISTANCE * SLIT_WIDTH / 2.0, 50.0);

/// The prism's glass and the slit's light.
#[derive(Clone, Default)]
struct Setup {
    /// KHR_materials_dispersion of the glass.
    dispersion: f32,
    /// The slit's spectrum; white where `None`.
    slit_light: Option<SpectrumShape>,
    /// KHR_materials_volume's `attenuationDistance`, over which the glass turns white
    /// light the grey [`ATTENUATION_COLOUR`]; clear glass where `None`.
    attenuation_distance: Option<f32>,
}

/// The glass's `attenuationColor`, grey: its spectrum is flat, so the closed form's
/// `exp(−σ L)` holds at every wavelength.
const ATTENUATION_COLOUR: f32 = 0.5;

impl Setup {
    /// The absorption coefficient per unit length (Beer–Lambert).
    fn sigma(&self) -> f64 {
        self.attenuation_distance.map_or(0.0, |d| {
            -f64::from(math::ln(ATTENUATION_COLOUR)) / f64::from(d)
        })
    }
}

/// The prism and the slit of `setup`, seen by a camera at the origin.
fn scene_and_frame(setup: &Setup) -> PreparedFrame {
    let mut b = SceneBuilder::default();
    let glass = b.material(Material {
        base_color: glam::Vec4::ONE,
        metallic: 0.0,
        roughness: 0.0,
        transmission: 1.0,
        thickness: 1.0,
        ior: IOR,
        dispersion: setup.dispersion,
        attenuation_color: Vec3::splat(ATTENUATION_COLOUR),
        attenuation_distance: setup.attenuation_distance.unwrap_or(f32::INFINITY),
        ..Material::default()
    });
    let light = b.material(Material {
        base_color: glam::Vec4::new(0.0, 0.0, 0.0, 1.0),
        emissive: Vec3::ONE,
        emission_spectrum: setup.slit_light.clone(),
        double_sided: true,
        ..Material::default()
    });
    b.mesh(
        "prism",
        vec![prism(glass, APEX as f32, PRISM_HEIGHT as f32, 40.0)],
        prism_to_world(),
    );
    let xfov = 14f64.to_radians();
    let aspect = f64::from(WIDTH) / f64::from(HEIGHT);
    let camera = CameraDef {
        name: None,
        projection: Projection::Perspective {
            yfov: (2.0 * math::atan_f64(math::tan_f64(xfov / 2.0) / aspect)) as f32,
            aspect_ratio: None,
            znear: 0.01,
        },
    };
    b.camera(camera, DMat4::IDENTITY);
    b.environment(Environment::Black);
    let s = slit();
    let corner = |a: f64, v: f64| (s.plane.point + s.across * a + DVec3::Y * v).as_vec3();
    let (w, h) = SLIT_HALF;
    let corners = [corner(-w, -h), corner(w, -h), corner(w, h), corner(-w, h)];
    b.mesh("slit", vec![quad(corners, light)], DMat4::IDENTITY);
    let options = FrameOptions {
        width: WIDTH,
        height: HEIGHT,
        ..Default::default()
    };
    prepare_frame(Arc::new(b.finish()), &options).expect("prepares")
}

/// Per column (rows summed), CIE XYZ of the image that Snell's and Fresnel's laws give:
/// each pixel averaged over 64 × 2 positions and over 360–830 nm in 1 nm steps, of the
/// slit's light (white, which is D65 on the spectral path, or of the setup's spectrum)
/// that passes both faces of the prism at that wavelength's IOR, less what the glass
/// absorbs on the way, and lands on the slit.
fn predicted(frame: &PreparedFrame, setup: &Setup) -> Vec<DVec3> {
    let light = setup
        .slit_light
        .as_ref()
        .map(|s| DenseSpectrum::light(s).expect("visible power"));
    let sigma = setup.sigma();
    let emitted = |nm| light.as_ref().map_or(spectrum::d65(nm), |l| l.eval(nm));
    const SUB: (u32, u32) = (64, 2);
    let s = slit();
    let lambdas: Vec<f32> = (0..(LAMBDA_MAX - LAMBDA_MIN) as u32)
        .map(|i| LAMBDA_MIN + i as f32 + 0.5)
        .collect();
    let y_integral: f64 = lambdas
        .iter()
        .map(|&nm| f64::from(spectrum::cmf(nm).y))
        .sum();
    let mut columns = vec![DVec3::ZERO; WIDTH as usize];
    for (x, column) in columns.iter_mut().enumerate() {
        for y in 0..HEIGHT {
            for (i, j) in (0..SUB.0).flat_map(|i| (0..SUB.1).map(move |j| (i, j))) {
                let film = Vec2::new(
                    (x as f32 + (i as f32 + 0.5) / SUB.0 as f32) / WIDTH as f32,
                    (y as f32 + (j as f32 + 0.5) / SUB.1 as f32) / HEIGHT as f32,
                );
                let ray = frame.camera.generate_ray(film, 0.0);
                for &nm in &lambdas {
                    let n = f64::from(dispersive_ior(IOR, setup.dispersion, nm));
                    let Some((p, d, passed, inside)) =
                        through_prism(ray.origin.as_dvec3(), ray.dir.as_dvec3(), n)
                    else {
                        continue;
                    };
                    let at = s.plane.hit(p, d) - s.plane.point;
                    if at.dot(s.across).abs() < SLIT_HALF.0 && at.y.abs() < SLIT_HALF.1 {
                        *column += spectrum::cmf(nm).as_dvec3()
                            * (passed
                                * (1.0 + math::exp_m1_f64(-sigma * inside))
                                * f64::from(emitted(nm)));
                    }
                }
            }
        }
        *column /= f64::from(SUB.0 * SUB.1) * y_integral;
    }
    columns
}

/// Per column (rows summed), CIE XYZ of the rendered image.
fn rendered(frame: &PreparedFrame, spp: u32) -> Vec<DVec3> {
    let settings = RenderSettings {
        max_depth: 2,
        ..RenderSettings::DEFAULT
    };
    let layers: Layers =
        common::render_rect(frame, &settings, TileRect::new(0, 0, WIDTH, HEIGHT), spp);
    let to_xyz = XYZ_TO_REC709.inverse().as_dmat3();
    let mut columns = vec![DVec3::ZERO; WIDTH as usize];
    for (i, p) in layers.beauty.iter().enumerate() {
        columns[i % WIDTH as usize] += to_xyz * p.truncate().as_dvec3();
    }
    columns
}

/// Each of X, Y and Z: the column its light is centred on, and its sum.
fn centroids(columns: &[DVec3]) -> [(f64, f64); 3] {
    std::array::from_fn(|k| {
        let sum: f64 = columns.iter().map(|c| c[k]).sum();
        let moment: f64 = columns
            .iter()
            .enumerate()
            .map(|(x, c)| (x as f64 + 0.5) * c[k])
            .sum();
        (moment / sum, sum)
    })
}

/// How closely a render at some samples per pixel must match the prediction.
struct Match {
    spp: u32,
    /// Pixels between the centroids.
    centroid: f64,
    /// Relative difference of the sums.
    sum: f64,
}

/// White light at 4096 samples per pixel: a quarter of a pixel and 2%. (At 16384 the
/// dispersive prism's agree within 0.02 pixels and 0.2%.)
const WHITE: Match = Match {
    spp: 4096,
    centroid: 0.25,
    sum: 0.02,
};

/// The rendered image against the prediction: each of X, Y and Z (those with at least a
/// hundredth of the brightest one's light) centred on the same column and as bright, as
/// closely as `m` says. Gives the centroids.
fn assert_matches(frame: &PreparedFrame, setup: &Setup, m: Match) -> [f64; 3] {
    let want = centroids(&predicted(frame, setup));
    let got = centroids(&rendered(frame, m.spp));
    let brightest = want.iter().map(|w| w.1).fold(0.0, f64::max);
    for (k, (w, g)) in want.iter().zip(&got).enumerate() {
        eprintln!(
            "channel {k}: centroid {:.2} vs {:.2}, sum {:.4} vs {:.4}",
            g.0, w.0, g.1, w.1
        );
        if w.1 < 0.01 * brightest {
            continue;
        }
        let (centroid, sum) = ((g.0 - w.0).abs(), (g.1 / w.1 - 1.0).abs());
        assert!(
            centroid < m.centroid,
            "channel {k}: centroid {} vs {}",
            g.0,
            w.0
        );
        assert!(sum < m.sum, "channel {k}: sum {} vs {}", g.1, w.1);
    }
    got.map(|c| c.0)
}

/// A prism of a flint glass (Abbe number 20) fans a slit of white light into a spectrum:
/// blue (Z) bent further than green (Y), as the closed form says per wavelength. The
/// scene takes the spectral path itself: the settings do not ask for it.
#[test]
fn a_dispersive_prism_fans_white_light_as_snells_law_says() {
    let flint = Setup {
        dispersion: 1.0,
        ..Setup::default()
    };
    let frame = scene_and_frame(&flint);
    assert!(frame.features.dispersion && frame.features.needs_spectral());
    assert!(frame.features.names().contains(&"dispersion"));
    let [_, y, z] = assert_matches(&frame, &flint, WHITE);
    // Bent further means seen towards the prism's base: +x in the image.
    assert!(z - y > 20.0, "blue at {z}, green at {y}: no spectrum");
}

/// Dispersive glass that absorbs (KHR_materials_volume's attenuation) takes from each
/// wavelength what Beer–Lambert says over the length that wavelength travels inside: the
/// slit's spectrum through the flint prism, half as bright for each 0.8 units of glass,
/// matches the closed form with `exp(−σ L(λ))`, and is darker than through clear glass.
#[test]
fn dispersive_glass_absorbs_along_each_wavelengths_path() {
    let tinted = Setup {
        dispersion: 1.0,
        attenuation_distance: Some(0.8),
        ..Setup::default()
    };
    let frame = scene_and_frame(&tinted);
    assert!(frame.features.volume && frame.features.dispersion);
    assert_matches(&frame, &tinted, WHITE);
    let clear = predicted(
        &frame,
        &Setup {
            attenuation_distance: None,
            ..tinted.clone()
        },
    );
    let tinted_sum: f64 = predicted(&frame, &tinted).iter().map(|c| c.y).sum();
    let clear_sum: f64 = clear.iter().map(|c| c.y).sum();
    assert!(tinted_sum < 0.8 * clear_sum, "{tinted_sum} vs {clear_sum}");
}

/// Light of one colour (a 10 nm band from a slit of that spectrum) through the flint
/// prism lands where Snell's law at its wavelength's IOR sends it: the image matches the
/// closed form over the band, its centre is within half a pixel of the column whose ray
/// at the band's peak reaches the slit's middle (the band's width and the deviation's
/// curvature account for 0.3 pixels at 450 nm), and shorter waves bend further.
#[test]
fn each_wavelength_bends_by_its_own_ior() {
    let mut seen = Vec::new();
    for peak in [450.0, 550.0, 650.0] {
        let slit = SpectrumShape::Gaussian { peak, width: 10.0 };
        let setup = Setup {
            dispersion: 1.0,
            slit_light: Some(slit),
            ..Setup::default()
        };
        let frame = scene_and_frame(&setup);
        // One band's light is a few percent of the samples' wavelengths: noisier.
        let band = Match {
            spp: 2048,
            centroid: 0.3,
            sum: 0.1,
        };
        let [_, y, _] = assert_matches(&frame, &setup, band);
        let n = f64::from(dispersive_ior(IOR, 1.0, peak));
        let column = column_reaching_the_slit(&frame, n);
        eprintln!("{peak} nm, n {n:.4}: seen at {y:.2}, Snell's law says {column:.2}");
        assert!((y - column).abs() < 0.5, "{peak} nm: at {y}, not {column}");
        seen.push(y);
    }
    assert!(
        seen[0] > seen[1] + 5.0 && seen[1] > seen[2] + 5.0,
        "{seen:?}"
    );
}

/// The image column (continuous, in pixels) whose middle-row ray at IOR `n` reaches the
/// middle of the slit: by bisection, from the first column whose ray leaves the prism
/// (towards the image's left edge the rays meet the exit face past the critical angle).
fn column_reaching_the_slit(frame: &PreparedFrame, n: f64) -> f64 {
    let s = slit();
    let offset = |x: f64| {
        let film = Vec2::new((x / f64::from(WIDTH)) as f32, 0.5);
        let ray = frame.camera.generate_ray(film, 0.0);
        let (p, d, _, _) = through_prism(ray.origin.as_dvec3(), ray.dir.as_dvec3(), n)?;
        Some((s.plane.hit(p, d) - s.plane.point).dot(s.across))
    };
    let mut lo = (0..WIDTH)
        .map(f64::from)
        .find(|&x| offset(x).is_some())
        .expect("some rays leave the prism");
    let mut hi = f64::from(WIDTH);
    let side = |x| offset(x).expect("leaves the prism").signum();
    assert!(side(lo) != side(hi), "the slit is in view");
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if side(mid) == side(lo) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// Without dispersion the same prism bends every wavelength alike: the slit's image is
/// white (X, Y and Z on one column), on the RGB path.
#[test]
fn a_prism_without_dispersion_splits_nothing() {
    let crown = Setup::default();
    let frame = scene_and_frame(&crown);
    assert!(!frame.features.dispersion && !frame.features.needs_spectral());
    let [x, y, z] = assert_matches(&frame, &crown, WHITE);
    assert!((x - y).abs() < 0.1 && (z - y).abs() < 0.1, "{x} {y} {z}");
}

/// Dispersive glass, smooth or rough, loses no light: in a white furnace each wavelength
/// keeps its energy whatever its IOR, so the sphere is as white as the sky behind it:
/// within 1% (rough glass at a wavelength's IOR is compensated by the shared albedo
/// tables, not its material's own curve, which reads +0.5% at 2048 samples per pixel;
/// smooth glass is exact).
#[test]
fn dispersive_glass_in_a_white_furnace_loses_nothing() {
    for roughness in [0.0, 0.4] {
        let material = Material {
            base_color: glam::Vec4::ONE,
            metallic: 0.0,
            roughness,
            transmission: 1.0,
            thickness: 1.0,
            dispersion: 2.0,
            double_sided: true,
            ..Material::default()
        };
        let options = FrameOptions {
            width: 40,
            height: 40,
            ..Default::default()
        };
        let frame = prepare_frame(Arc::new(common::furnace(material)), &options).expect("prepares");
        assert!(frame.features.dispersion);
        let settings = RenderSettings {
            max_depth: 64,
            ..RenderSettings::DEFAULT
        };
        let layers = common::render_rect(&frame, &settings, TileRect::new(0, 0, 40, 40), 1024);
        let sphere: Vec<_> = layers.beauty.iter().filter(|p| p.w == 1.0).collect();
        assert!(sphere.len() > 100);
        let mean = sphere
            .iter()
            .map(|p| p.truncate().as_dvec3())
            .sum::<DVec3>()
            / sphere.len() as f64;
        eprintln!("roughness {roughness}: {mean}");
        assert!(
            (mean - DVec3::ONE).abs().max_element() < 0.01,
            "roughness {roughness}: {mean}"
        );
    }
}

/// KHR_materials_dispersion is read as the spec says (default 0), counts only on a
/// refracting volume, and a value that is no dispersion is refused.
#[test]
fn dispersion_is_read_and_refused_as_the_spec_says() {
    let doc = |volume: &str, dispersion: &str| {
        format!(
            r#"{{"asset":{{"version":"2.0"}},
            "extensionsUsed":["KHR_materials_transmission","KHR_materials_volume","KHR_materials_dispersion"],
            "materials":[{{"extensions":{{"KHR_materials_transmission":{{"transmissionFactor":1}},
            "KHR_materials_volume":{volume},"KHR_materials_dispersion":{dispersion}}}}}]}}"#
        )
    };
    let load =
        |volume, dispersion| tracer::loader::load_slice(doc(volume, dispersion).as_bytes(), None);
    let scene = load(r#"{"thicknessFactor":1}"#, r#"{"dispersion":0.36}"#).expect("loads");
    assert_eq!(scene.materials[0].dispersion, 0.36);
    assert!(scene.materials[0].is_dispersive());

    // The default, and a thin wall (which bends no light), are not dispersive.
    let scene = load(r#"{"thicknessFactor":1}"#, "{}").expect("loads");
    assert_eq!(scene.materials[0].dispersion, 0.0);
    assert!(!scene.materials[0].is_dispersive());
    let scene = load("{}", r#"{"dispersion":1}"#).expect("loads");
    assert!(!scene.materials[0].is_dispersive());

    for bad in [
        r#"{"dispersion":-0.5}"#,
        r#"{"dispersion":"high"}"#,
        r#"{"dispersion":1e300}"#,
    ] {
        let err = load(r#"{"thicknessFactor":1}"#, bad)
            .expect_err("refused")
            .to_string();
        assert!(err.contains("dispersion"), "{bad}: {err}");
    }
}
