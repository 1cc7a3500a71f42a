//! Ray throughput for `tessera bench`, one thread and all threads: closest-hit camera
//! rays, any-hit shadow rays between surface points and incoherent bounce rays on a
//! scene; and a generated mesh of over a million triangles: its BVH's build time and bytes
//! per triangle, and the same ray kinds through it.

use std::time::Instant;

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use serde::Serialize;

use tracer::bvh::MeshBvh;
use tracer::geometry::Ray;
use tracer::render::PreparedFrame;
use tracer::shapes::bumpy_grid;

/// Rays per second of one kind.
#[derive(Clone, Serialize)]
pub struct RayRate {
    /// What the rays are.
    pub kind: String,
    /// Rays per second on one thread.
    pub one_thread: f64,
    /// Rays per second on every thread.
    pub all_threads: f64,
}

/// The generated mesh's figures.
#[derive(Serialize)]
pub struct BigMesh {
    /// Triangles.
    pub triangles: usize,
    /// Seconds to build its BVH, one thread and all threads.
    pub build_seconds_one_thread: f64,
    /// Seconds on every thread.
    pub build_seconds_all_threads: f64,
    /// The BVH's bytes per triangle (nodes and triangle data).
    pub bytes_per_triangle: f64,
    /// Ray rates through it.
    pub rays: Vec<RayRate>,
}

/// A fixed pseudo-random sequence (SplitMix64), so every run shoots the same rays.
pub(crate) struct Rng(pub u64);

impl Rng {
    /// The next number, uniform in [0, 1).
    pub fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }

    /// A direction uniform on the sphere.
    fn direction(&mut self) -> Vec3 {
        let z = 1.0 - 2.0 * self.next();
        let phi = std::f32::consts::TAU * self.next();
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

/// Rays per second of `query` over `rays`, on one thread and on every thread; each ray
/// set is traced several times so that a run takes long enough to time.
fn rates<Q>(kind: &str, rays: &[(Ray, f32)], query: Q) -> anyhow::Result<RayRate>
where
    Q: Fn(&Ray, f32) -> bool + Sync,
{
    let time = |passes: usize| {
        let start = Instant::now();
        let hits: usize = (0..passes)
            .map(|_| rays.par_iter().filter(|(r, t)| query(r, *t)).count())
            .sum();
        std::hint::black_box(hits);
        (rays.len() * passes) as f64 / start.elapsed().as_secs_f64()
    };
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    Ok(RayRate {
        kind: kind.into(),
        one_thread: one.install(|| time(2)),
        all_threads: time(4),
    })
}

/// Camera rays through every pixel centre, then from their hits: shadow rays to another
/// pixel's hit (any hit, stopping short of it) and bounce rays in random directions on the
/// side the camera ray came from.
pub fn scene_rates(frame: &PreparedFrame) -> anyhow::Result<Vec<RayRate>> {
    let (w, h) = (frame.width, frame.height);
    let camera: Vec<(Ray, f32)> = (0..w * h)
        .map(|i| {
            let film = Vec2::new(
                ((i % w) as f32 + 0.5) / w as f32,
                ((i / w) as f32 + 0.5) / h as f32,
            );
            (frame.camera.generate_ray(film, 0.0), f32::INFINITY)
        })
        .collect();
    // Points just in front of each surface hit, on the camera's side.
    let points: Vec<(Vec3, Vec3)> = camera
        .iter()
        .filter_map(|(r, _)| {
            let hit = frame.intersect(r, f32::INFINITY)?;
            let dir = r.dir.normalize();
            Some((r.origin + r.dir * hit.t - dir * 1e-3, -dir))
        })
        .collect();
    let mut rng = Rng(7);
    let n = points.len().max(1);
    let shadow: Vec<(Ray, f32)> = (0..points.len())
        .map(|i| {
            let (from, _) = points[i];
            let (to, _) = points[(i * 7919 + 13) % n];
            (Ray::new(from, to - from), 0.999)
        })
        .collect();
    let bounce: Vec<(Ray, f32)> = points
        .iter()
        .map(|&(from, towards_camera)| {
            let d = rng.direction();
            let d = if d.dot(towards_camera) < 0.0 { -d } else { d };
            (Ray::new(from, d), f32::INFINITY)
        })
        .collect();
    Ok(vec![
        rates("camera (closest hit)", &camera, |r, t| {
            frame.intersect(r, t).is_some()
        })?,
        rates("shadow (any hit)", &shadow, |r, t| frame.occluded(r, t))?,
        rates("bounce (closest hit, incoherent)", &bounce, |r, t| {
            frame.intersect(r, t).is_some()
        })?,
    ])
}

/// A generated mesh of `2 n²` triangles (n = 708: just over a million): build time, bytes
/// per triangle, and rays through it: coherent ones from a point above, incoherent ones
/// between random points of its bounding box, and any-hit rays between those.
pub fn big_mesh(n: usize) -> anyhow::Result<BigMesh> {
    let tris = bumpy_grid(n);
    let build = || {
        let start = Instant::now();
        let bvh = MeshBvh::build(&tris);
        (bvh, start.elapsed().as_secs_f64())
    };
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let (_, build_seconds_one_thread) = one.install(build);
    let (bvh, build_seconds_all_threads) = build();
    let count = 1 << 16;
    let mut rng = Rng(11);
    let mut point = || Vec3::new(rng.next(), rng.next() * 0.2 - 0.1, rng.next());
    let coherent: Vec<(Ray, f32)> = (0..count)
        .map(|i| {
            let (u, v) = ((i % 256) as f32 / 256.0, (i / 256) as f32 / 256.0);
            let origin = Vec3::new(0.5, 2.0, 0.5);
            (
                Ray::new(origin, Vec3::new(u, 0.0, v) - origin),
                f32::INFINITY,
            )
        })
        .collect();
    let pairs: Vec<(Vec3, Vec3)> = (0..count).map(|_| (point(), point())).collect();
    let incoherent: Vec<(Ray, f32)> = pairs
        .iter()
        .map(|&(a, b)| (Ray::new(a, b - a), f32::INFINITY))
        .collect();
    let segments: Vec<(Ray, f32)> = pairs
        .iter()
        .map(|&(a, b)| (Ray::new(a, b - a), 1.0))
        .collect();
    let closest = |r: &Ray, t: f32| bvh.intersect(r, t, |_, _, _| true).is_some();
    Ok(BigMesh {
        triangles: tris.len(),
        build_seconds_one_thread,
        build_seconds_all_threads,
        bytes_per_triangle: bvh.memory_bytes() as f64 / tris.len() as f64,
        rays: vec![
            rates("coherent (closest hit, from above)", &coherent, closest)?,
            rates("incoherent (closest hit, random)", &incoherent, closest)?,
            rates("any hit (random segments)", &segments, |r, t| {
                bvh.occluded(r, t, |_, _, _| true)
            })?,
        ],
    })
}

/// The markdown of a set of rates.
pub fn table(rates: &[RayRate]) -> String {
    let mut out = "| rays | 1 thread (M/s) | all threads (M/s) |\n|---|---:|---:|\n".to_string();
    for r in rates {
        out += &format!(
            "| {} | {:.2} | {:.2} |\n",
            r.kind,
            r.one_thread / 1e6,
            r.all_threads / 1e6
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rng_is_uniform_enough_and_directions_are_unit() {
        let mut rng = Rng(1);
        let n = 100_000;
        let mean = (0..n).map(|_| f64::from(rng.next())).sum::<f64>() / f64::from(n);
        // The mean of n uniform numbers has a standard deviation of 0.29 / sqrt(n).
        assert!((mean - 0.5).abs() < 0.005, "{mean}");
        assert!((0..100).all(|_| (rng.direction().length() - 1.0).abs() < 1e-5));
    }

    #[test]
    fn a_small_mesh_reports_every_figure() {
        let m = big_mesh(16).unwrap();
        assert_eq!(m.triangles, 512);
        assert!(m.bytes_per_triangle > 0.0);
        assert_eq!(m.rays.len(), 3);
        assert!(m
            .rays
            .iter()
            .all(|r| r.one_thread > 0.0 && r.all_threads > 0.0));
        assert!(table(&m.rays).contains("| any hit (random segments) |"));
    }
}
