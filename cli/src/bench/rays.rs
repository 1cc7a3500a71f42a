//! Ray throughput for `tessera bench`, one thread and all threads: closest-hit camera
//! rays, any-hit shadow rays between surface points and incoherent bounce rays on a
//! scene; and a generated mesh of over a million triangles: its BVH's build time and bytes
//! per triangle, and the same ray kinds through it.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use serde::Serialize;

use tracer::bvh::MeshBvh;
use tracer::geometry::{Aabb, Ray};
use tracer::render::PreparedFrame;
use tracer::scene::Scene;
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
fn rates<Q>(kind: &str, rays: &[(Ray, f32)], query: Q) -> RayRate
where
    Q: Fn(&Ray, f32) -> bool + Sync,
{
    let passes = 4;
    let start = Instant::now();
    let hits: usize = (0..passes)
        .map(|_| rays.par_iter().filter(|(r, t)| query(r, *t)).count())
        .sum();
    std::hint::black_box(hits);
    RayRate {
        kind: kind.into(),
        one_thread: one_thread_rate(rays, &query),
        all_threads: (rays.len() * passes) as f64 / start.elapsed().as_secs_f64(),
    }
}

/// Camera rays through every pixel centre, then from their hits: shadow rays to another
/// pixel's hit (any hit, stopping short of it) and bounce rays in random directions on the
/// side the camera ray came from.
pub fn scene_rates(frame: &PreparedFrame) -> Vec<RayRate> {
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
    vec![
        rates("camera (closest hit)", &camera, |r, t| {
            frame.intersect(r, t).is_some()
        }),
        rates("shadow (any hit)", &shadow, |r, t| frame.occluded(r, t)),
        rates("bounce (closest hit, incoherent)", &bounce, |r, t| {
            frame.intersect(r, t).is_some()
        }),
    ]
}

/// The three ray sets traced through a mesh, made from its bounding box `b`: coherent
/// closest-hit rays from a point above it (a 256x256 grid of directions towards its middle
/// plane), incoherent ones between random points of the box, and any-hit rays between
/// those points (stopping at the second).
pub struct RaySets {
    /// The three sets.
    pub sets: Vec<RaySet>,
}

/// Rays of one kind.
pub struct RaySet {
    /// What they are.
    pub kind: &'static str,
    /// The rays, each with its `t_max`.
    pub rays: Vec<(Ray, f32)>,
    /// Whether they are coherent (Embree is told so).
    #[cfg_attr(not(feature = "embree"), allow(dead_code))]
    pub coherent: bool,
    /// Whether the query is any-hit (else closest-hit).
    pub any_hit: bool,
}

impl RaySet {
    fn new(kind: &'static str, rays: Vec<(Ray, f32)>, coherent: bool, any_hit: bool) -> Self {
        Self {
            kind,
            rays,
            coherent,
            any_hit,
        }
    }
}

impl RaySets {
    pub fn new(b: Aabb) -> Self {
        let count = 1 << 16;
        let (c, e) = (b.center(), b.extent());
        let mut rng = Rng(11);
        let mut point = || b.min + e * Vec3::new(rng.next(), rng.next(), rng.next());
        let origin = Vec3::new(c.x, b.max.y + e.max_element(), c.z);
        let coherent: Vec<(Ray, f32)> = (0..count)
            .map(|i| {
                let (u, v) = ((i % 256) as f32 / 256.0, (i / 256) as f32 / 256.0);
                let target = Vec3::new(b.min.x + u * e.x, c.y, b.min.z + v * e.z);
                (Ray::new(origin, target - origin), f32::INFINITY)
            })
            .collect();
        let pairs: Vec<(Vec3, Vec3)> = (0..count).map(|_| (point(), point())).collect();
        let incoherent = pairs
            .iter()
            .map(|&(a, b)| (Ray::new(a, b - a), f32::INFINITY))
            .collect();
        let segments = pairs
            .iter()
            .map(|&(a, b)| (Ray::new(a, b - a), 1.0))
            .collect();
        Self {
            sets: vec![
                RaySet::new("coherent (closest hit, from above)", coherent, true, false),
                RaySet::new("incoherent (closest hit, random)", incoherent, false, false),
                RaySet::new("any hit (random segments)", segments, false, true),
            ],
        }
    }
}

/// A generated mesh of `2 n²` triangles (n = 708: just over a million): build time, bytes
/// per triangle, and the [`RaySets`] through it.
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
    let rays = RaySets::new(bvh.bounds())
        .sets
        .iter()
        .map(|set| {
            let (kind, rays) = (set.kind, &set.rays);
            if set.any_hit {
                rates(kind, rays, |r, t| bvh.occluded(r, t, |_, _, _| true))
            } else {
                rates(kind, rays, |r, t| {
                    bvh.intersect(r, t, |_, _, _| true).is_some()
                })
            }
        })
        .collect();
    Ok(BigMesh {
        triangles: tris.len(),
        build_seconds_one_thread,
        build_seconds_all_threads,
        bytes_per_triangle: bvh.memory_bytes() as f64 / tris.len() as f64,
        rays,
    })
}

/// `tessera bench rays`.
#[derive(Args)]
pub struct RaysArgs {
    /// Trace the same rays through native Embree 3 as well, and compare. Needs a build with
    /// the `embree` feature (`cargo build --release -p cli --features embree`) after
    /// `scripts/install-embree.sh`.
    #[arg(long)]
    pub embree: bool,
    /// A .gltf or .glb whose triangles (every mesh, placed as its nodes are) replace the
    /// generated mesh.
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Quads a side of the generated mesh (708: 1,002,528 triangles).
    #[arg(long, default_value_t = 708, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub side: u32,
    /// Rounds: each ray set is traced this many times by each BVH, taking turns; the
    /// fastest round counts.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=20))]
    pub rounds: u32,
    /// Test Tessera's nodes in SSE2's halves of four lanes even where the CPU has AVX: the
    /// same hits, so one binary measures what AVX buys.
    #[arg(long)]
    pub sse2: bool,
}

/// Every triangle of `scene` in world space, each mesh placed by every node that holds it
/// (the scene as it stands, no animation).
pub fn world_triangles(scene: &Scene) -> Vec<[Vec3; 3]> {
    let mut out = Vec::new();
    scene.for_each_node_instance(|node, world| {
        let Some(mesh) = scene.nodes[node as usize].mesh else {
            return;
        };
        for prim in &scene.meshes[mesh as usize].primitives {
            let place = |i: u32| world.transform_point3(prim.positions[i as usize].as_dvec3());
            out.extend(prim.indices.iter().map(|t| t.map(|i| place(i).as_vec3())));
        }
    });
    out
}

/// Rays per second of `query` over `rays` on the calling thread alone: the set traced
/// twice, so that a run takes long enough to time.
///
/// Never inlined, so that a profiler can cut a run at each call: `valgrind --tool=callgrind
/// --dump-before='*one_thread_rate*' tessera bench rays --embree --rounds 1` dumps before each
/// call, so that every file but the first (the set-up) holds one timed call, the last call
/// in the file without a suffix; their totals divided by twice the set's rays are the
/// per-ray counts in BENCHMARKS.md.
#[inline(never)]
fn one_thread_rate(rays: &[(Ray, f32)], query: impl Fn(&Ray, f32) -> bool) -> f64 {
    let start = Instant::now();
    let mut hits = 0usize;
    for _ in 0..2 {
        hits += rays.iter().filter(|(r, t)| query(r, *t)).count();
    }
    std::hint::black_box(hits);
    (2 * rays.len()) as f64 / start.elapsed().as_secs_f64()
}

/// Runs `tessera bench rays`.
pub fn run(args: RaysArgs) -> anyhow::Result<()> {
    if args.embree && !cfg!(feature = "embree") {
        anyhow::bail!(
            "this tessera was built without Embree: run scripts/install-embree.sh, then \
             cargo build --release -p cli --features embree (and run that binary)"
        );
    }
    let (name, triangles) = match &args.mesh {
        Some(path) => (
            path.display().to_string(),
            world_triangles(&crate::render::load_scene(
                Some(path),
                tracer::demo::demo_scene,
            )?),
        ),
        None => (
            format!("generated bumpy grid, {0}x{0} quads", args.side),
            bumpy_grid(args.side as usize),
        ),
    };
    anyhow::ensure!(!triangles.is_empty(), "{name} has no triangles");
    eprintln!("{name}: {} triangles; building ...", triangles.len());
    let bvh = MeshBvh::build(&triangles);
    let sets = RaySets::new(bvh.bounds());
    let tessera_rate = |rays: &[(Ray, f32)], any_hit: bool| {
        if any_hit {
            one_thread_rate(rays, |r, t| bvh.occluded(r, t, |_, _, _| true))
        } else {
            one_thread_rate(rays, |r, t| bvh.intersect(r, t, |_, _, _| true).is_some())
        }
    };
    if args.sse2 {
        tracer::simd::allow_avx(false);
    }
    let node_test = if tracer::simd::avx() { "AVX" } else { "SSE2" };
    println!(
        "\n{name}, {} triangles, one thread, {} rays per set, the fastest of {} rounds, \
         Tessera's node test in {node_test} lanes:\n",
        triangles.len(),
        sets.sets[0].rays.len(),
        args.rounds
    );
    if !args.embree {
        println!("| rays | Tessera (M rays/s) |\n|---|---:|");
        for RaySet {
            kind,
            rays,
            any_hit,
            ..
        } in &sets.sets
        {
            let best = (0..args.rounds)
                .map(|_| tessera_rate(rays, *any_hit))
                .fold(0.0, f64::max);
            println!("| {kind} | {:.2} |", best / 1e6);
        }
        return Ok(());
    }
    #[cfg(feature = "embree")]
    super::embree::with_scene(&triangles, |embree| -> anyhow::Result<()> {
        let mut disagreements = Vec::new();
        println!(
            "| rays | Tessera (M rays/s) | Embree (M rays/s) | Tessera / Embree | agree |\n\
             |---|---:|---:|---:|---:|"
        );
        // Every set compared before any is timed, so that the timed calls follow one another
        // (see `one_thread_rate`).
        let agreements: Vec<Agreement> = sets
            .sets
            .iter()
            .map(|set| compare(&bvh, embree, set))
            .collect();
        for (set, agreement) in sets.sets.iter().zip(agreements) {
            let RaySet {
                kind,
                rays,
                coherent,
                any_hit,
            } = set;
            let embree_rate = |rays: &[(Ray, f32)]| {
                if *any_hit {
                    one_thread_rate(rays, |r, t| embree.occluded(r, t))
                } else {
                    one_thread_rate(rays, |r, t| embree.intersect(r, t, *coherent).is_some())
                }
            };
            let (mut ours, mut theirs) = (0.0f64, 0.0f64);
            for _ in 0..args.rounds {
                ours = ours.max(tessera_rate(rays, *any_hit));
                theirs = theirs.max(embree_rate(rays));
            }
            let cracks = match agreement.embree_cracks {
                0 => String::new(),
                n => format!(" (+{n} through an edge, Embree missed)"),
            };
            println!(
                "| {kind} | {:.2} | {:.2} | {:.2} | {}/{}{cracks} |",
                ours / 1e6,
                theirs / 1e6,
                ours / theirs,
                agreement.agree,
                rays.len()
            );
            if let Some(first) = agreement.other.first() {
                disagreements.push(format!(
                    "{kind}: {} rays, the first {first}",
                    agreement.other.len()
                ));
            }
        }
        anyhow::ensure!(
            disagreements.is_empty(),
            "Tessera's BVH and Embree disagree on some rays ({})",
            disagreements.join("; ")
        );
        Ok(())
    })?;
    Ok(())
}

/// How the two BVHs' answers over a ray set compare.
#[cfg(feature = "embree")]
#[derive(Debug, Default, PartialEq)]
pub struct Agreement {
    /// Rays on which both agree: both miss, both are occluded or not, or both hit at
    /// distances within float tolerance of each other.
    pub agree: usize,
    /// Rays that only Tessera hits, each through an edge or a vertex of the mesh (its
    /// barycentrics within 1e-5 of one): Embree's triangle test is not watertight by
    /// default, and a ray through a shared edge can slip between the two triangles.
    pub embree_cracks: usize,
    /// Every other disagreement: rays only Embree hits or sees occluded, rays both hit at
    /// different distances, and rays only Tessera hits away from any edge.
    pub other: Vec<String>,
}

/// Compares both BVHs' answers on `rays`.
#[cfg(feature = "embree")]
pub fn compare(bvh: &MeshBvh, embree: &super::embree::EmbreeQueries, set: &RaySet) -> Agreement {
    let (coherent, any_hit) = (set.coherent, set.any_hit);
    let mut out = Agreement::default();
    for (r, t) in &set.rays {
        let ours = bvh.intersect(r, *t, |_, _, _| true);
        let on_edge = ours.is_some_and(|(_, _, b1, b2)| b1.min(b2).min(1.0 - b1 - b2) < 1e-5);
        let (agree, only_ours) = if any_hit {
            let (a, b) = (bvh.occluded(r, *t, |_, _, _| true), embree.occluded(r, *t));
            (a == b, a && !b)
        } else {
            match (ours.map(|h| h.0), embree.intersect(r, *t, coherent)) {
                (None, None) => (true, false),
                (Some(a), Some(b)) => ((a - b).abs() <= 1e-4 * a.abs().max(b.abs()), false),
                (Some(_), None) => (false, true),
                (None, Some(_)) => (false, false),
            }
        };
        if agree {
            out.agree += 1;
        } else if only_ours && on_edge {
            out.embree_cracks += 1;
        } else {
            out.other.push(format!(
                "ray {:?} -> {:?} (t_max {t}): Tessera {:?}, Embree {:?}",
                r.origin,
                r.dir,
                ours,
                embree.intersect(r, *t, coherent)
            ));
        }
    }
    out
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

    #[test]
    fn world_triangles_place_every_instance_of_a_mesh() {
        let scene = tracer::demo::cornell_box();
        let tris = world_triangles(&scene);
        // Each of the box's meshes is placed once.
        let placed: usize = scene.meshes.iter().map(|m| m.triangle_count()).sum();
        assert_eq!(tris.len(), placed);
        // Camera rays meet them where they meet the prepared frame (which renders
        // camera-relative, so the triangles move by the camera's position).
        let options = tracer::render::FrameOptions {
            width: 32,
            height: 32,
            ..Default::default()
        };
        let frame = tracer::render::prepare_frame(std::sync::Arc::new(scene), &options).unwrap();
        let shift = frame.camera_origin.as_vec3();
        let moved: Vec<[Vec3; 3]> = tris.iter().map(|t| t.map(|p| p - shift)).collect();
        let bvh = MeshBvh::build(&moved);
        for i in 0..32 * 32 {
            let film = Vec2::new((i % 32) as f32 + 0.5, (i / 32) as f32 + 0.5) / 32.0;
            let ray = frame.camera.generate_ray(film, 0.0);
            let want = frame.intersect(&ray, f32::INFINITY).map(|h| h.t);
            let got = bvh
                .intersect(&ray, f32::INFINITY, |_, _, _| true)
                .map(|h| h.0);
            match (want, got) {
                (Some(a), Some(b)) => assert!((a - b).abs() <= 1e-4 * a, "{i}: {a} {b}"),
                _ => panic!("pixel {i}: frame {want:?}, world triangles {got:?}"),
            }
        }
    }

    #[test]
    fn coherent_rays_hit_the_mesh_they_were_aimed_at() {
        let tris = bumpy_grid(32);
        let bvh = MeshBvh::build(&tris);
        let sets = RaySets::new(bvh.bounds());
        let coherent = &sets.sets[0].rays;
        let hits = coherent
            .iter()
            .filter(|(r, t)| bvh.intersect(r, *t, |_, _, _| true).is_some())
            .count();
        // Aimed at the box's middle plane: near its far edges a ray can pass over a dip.
        assert!(hits > coherent.len() * 95 / 100, "{hits}");
    }

    #[cfg(feature = "embree")]
    #[test]
    fn embree_and_the_tracer_find_the_same_hits() {
        let tris = bumpy_grid(40);
        let bvh = MeshBvh::build(&tris);
        let sets = RaySets::new(bvh.bounds());
        super::super::embree::with_scene(&tris, |embree| {
            for set in &sets.sets {
                let agreement = compare(&bvh, embree, set);
                assert!(
                    agreement.other.is_empty(),
                    "{}: {:?}",
                    set.kind,
                    agreement.other
                );
                assert!(
                    agreement.embree_cracks <= set.rays.len() / 1000,
                    "{}",
                    set.kind
                );
            }
            // Not vacuous: most closest-hit rays hit something, and Embree says where.
            let incoherent = &sets.sets[1].rays;
            let hits = incoherent
                .iter()
                .filter(|(r, t)| embree.intersect(r, *t, false).is_some())
                .count();
            assert!(hits > incoherent.len() / 4, "{hits}");
        });
    }

    #[cfg(not(feature = "embree"))]
    #[test]
    fn embree_comparison_needs_the_feature_and_says_so() {
        // Straight to stderr, past the test harness's capture: a skip must be seen.
        use std::io::Write;
        let _ = writeln!(
            std::io::stderr(),
            "\n=== SKIPPED: the Embree comparison's own test (built without the `embree` \
             feature). scripts/test.sh installs Embree and runs it; CI does. ===\n"
        );
        let args = RaysArgs {
            embree: true,
            mesh: None,
            side: 4,
            rounds: 1,
            sse2: false,
        };
        let err = run(args).unwrap_err().to_string();
        assert!(err.contains("scripts/install-embree.sh"), "{err}");
    }
}
