use glam::Vec3;
use std::time::Instant;
use std::sync::atomic::Ordering::Relaxed;
use tracer::bvh::MeshBvh;
use tracer::bvh::node::{VISITS, LEAVES, TRIS};
use tracer::geometry::Ray;
struct Rng(u64);
impl Rng { fn f(&mut self)->f32{ self.0 ^= self.0<<13; self.0^=self.0>>7; self.0^=self.0<<17; (self.0>>40) as f32/(1u64<<24) as f32 }
 fn cube(&mut self)->Vec3{Vec3::new(self.f(),self.f(),self.f())*2.0-1.0}
 fn dir(&mut self)->Vec3{loop{let v=self.cube(); if v.length_squared()<=1.0 && v.length_squared()>1e-4 {return v.normalize()}}}}
fn sphere(n: u32) -> Vec<[Vec3;3]> {
  let p = |i:u32,j:u32| { let th = std::f32::consts::PI * i as f32 / n as f32; let ph = std::f32::consts::PI * j as f32 / n as f32; Vec3::new(th.sin()*ph.cos(), th.cos(), th.sin()*ph.sin()) };
  let mut t = Vec::new();
  for i in 0..n { for j in 0..2*n { let (a,b,c,d)=(p(i,j),p(i+1,j),p(i+1,j+1),p(i,j+1)); t.push([a,b,c]); t.push([a,c,d]); } }
  t }
fn run(name: &str, bvh: &MeshBvh, rays: &[Ray]) {
    let n = rays.len();
    VISITS.store(0, Relaxed); LEAVES.store(0, Relaxed); TRIS.store(0, Relaxed);
    let t0 = Instant::now(); let mut h = 0;
    for r in rays { if bvh.intersect(r, f32::INFINITY, |_,_,_| true).is_some() { h+=1; } }
    let dt = t0.elapsed().as_secs_f64();
    println!("  {name}: {:.2} Mrays/s ({} hits) visits {:.1} leaves {:.1} tris {:.1}", n as f64/dt/1e6, h, VISITS.load(Relaxed) as f64/n as f64, LEAVES.load(Relaxed) as f64/n as f64, TRIS.load(Relaxed) as f64/n as f64);
    let t0 = Instant::now(); let mut h = 0;
    for r in rays { if bvh.occluded(r, f32::INFINITY, |_,_,_| true) { h+=1; } }
    let dt = t0.elapsed().as_secs_f64();
    println!("  {name} occluded: {:.2} Mrays/s ({} hits)", n as f64/dt/1e6, h);
}
#[test]
fn perf() {
  let mut rng = Rng(88172645463325252);
  let soup: Vec<[Vec3;3]> = (0..1_000_000).map(|_| { let c = rng.cube()*100.0; [c+rng.cube(), c+rng.cube(), c+rng.cube()] }).collect();
  for (name, tris) in [("sphere 10k", sphere(50)), ("sphere 1M", sphere(500)), ("soup 1M", soup)] {
    let t0 = Instant::now();
    let mut bvh = MeshBvh::build(&tris);
    let mut best = t0.elapsed().as_secs_f64();
    for _ in 0..2 { let t0 = Instant::now(); bvh = MeshBvh::build(&tris); best = best.min(t0.elapsed().as_secs_f64()); }
    println!("{name}: {} tris, build {:.3}s, {} nodes", tris.len(), best, bvh.node_count());
    let ext = bvh.bounds().extent().length();
    let c = bvh.bounds().center();
    let rays: Vec<Ray> = (0..200_000).map(|_| { let o = c + rng.dir()*ext; let tgt = c + rng.cube()*ext*0.3; Ray::new(o, tgt-o) }).collect();
    run("random", &bvh, &rays);
    // coherent: a 448x448 camera looking at the centre
    let o = c + Vec3::new(0.3, 0.4, 1.0).normalize() * ext;
    let w = (c - o).normalize(); let u = w.cross(Vec3::Y).normalize(); let v = u.cross(w);
    let rays: Vec<Ray> = (0..448*448).map(|i| { let (x, y) = ((i % 448) as f32 / 448.0 - 0.5, (i / 448) as f32 / 448.0 - 0.5); Ray::new(o, w + u * x * 0.8 + v * y * 0.8) }).collect();
    run("camera", &bvh, &rays);
  }
}
