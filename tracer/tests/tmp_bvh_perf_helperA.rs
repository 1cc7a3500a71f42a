use glam::Vec3;
struct Instant(u64);
impl Instant { fn now() -> Self { Instant(cpu_ns()) } fn elapsed(&self) -> std::time::Duration { std::time::Duration::from_nanos(cpu_ns() - self.0) } }
fn proc_cpu() -> f64 { let s = std::fs::read_to_string("/proc/self/stat").unwrap(); let f: Vec<&str> = s.rsplit(')').next().unwrap().split_whitespace().collect(); (f[11].parse::<u64>().unwrap() + f[12].parse::<u64>().unwrap()) as f64 / 100.0 }
fn cpu_ns() -> u64 { std::fs::read_to_string("/proc/thread-self/schedstat").unwrap().split_whitespace().next().unwrap().parse().unwrap() }
use tracer::bvh::MeshBvh;
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
    let t0 = Instant::now(); let mut h = 0;
    for r in rays { if bvh.intersect(r, f32::INFINITY, |_,_,_| true).is_some() { h+=1; } }
    let dt = t0.elapsed().as_secs_f64();
    println!("  {name}: {:.2} Mrays/s ({} hits)", n as f64/dt/1e6, h);
    let t0 = Instant::now(); let mut h = 0;
    for r in rays { if bvh.occluded(r, f32::INFINITY, |_,_,_| true) { h+=1; } }
    let dt = t0.elapsed().as_secs_f64();
    println!("  {name} occluded: {:.2} Mrays/s ({} hits)", n as f64/dt/1e6, h);
}
#[test]
fn perf() {
  let mut rng = Rng(88172645463325252);
  let soup: Vec<[Vec3;3]> = (0..1_000_000).map(|_| { let c = rng.cube()*100.0; [c+rng.cube(), c+rng.cube(), c+rng.cube()] }).collect();
  let only = std::env::var("ONLY").unwrap_or_default();
  for (name, tris) in [("sphere 10k", sphere(50)), ("sphere 1M", sphere(500)), ("soup 1M", soup)] {
    if !only.is_empty() && !name.contains(&only) { continue; }
    let t0 = Instant::now();
    let mut bvh = MeshBvh::build(&tris);
    let mut best = t0.elapsed().as_secs_f64();
    for _ in 0..2 { let t0 = Instant::now(); bvh = MeshBvh::build(&tris); best = best.min(t0.elapsed().as_secs_f64()); }
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let w0 = std::time::Instant::now(); let c0 = proc_cpu();
    pool.install(|| MeshBvh::build(&tris));
    let (w1, c1) = (w0.elapsed().as_secs_f64(), proc_cpu() - c0);
    let w0 = std::time::Instant::now(); let c0 = proc_cpu();
    MeshBvh::build(&tris);
    let w2 = w0.elapsed().as_secs_f64(); let c2 = proc_cpu() - c0;
    println!("{name}: {} tris, build {:.3}s (cpu, main thread), 1 thread: wall {w1:.3}s cpu {c1:.3}s; default pool wall {w2:.3}s cpu {c2:.2}s; {} nodes, {:.1} B/tri", tris.len(), best, bvh.node_count(), bvh.memory_bytes() as f64 / tris.len() as f64);
    let ext = bvh.bounds().extent().length();
    let c = bvh.bounds().center();
    let rays: Vec<Ray> = (0..1_000_000).map(|_| { let o = c + rng.dir()*ext; let tgt = c + rng.cube()*ext*0.3; Ray::new(o, tgt-o) }).collect();
    run("random", &bvh, &rays);
    // coherent: a 448x448 camera looking at the centre
    let o = c + Vec3::new(0.3, 0.4, 1.0).normalize() * ext;
    let w = (c - o).normalize(); let u = w.cross(Vec3::Y).normalize(); let v = u.cross(w);
    let rays: Vec<Ray> = (0..448*448).map(|i| { let (x, y) = ((i % 448) as f32 / 448.0 - 0.5, (i / 448) as f32 / 448.0 - 0.5); Ray::new(o, w + u * x * 0.8 + v * y * 0.8) }).collect();
    run("camera", &bvh, &rays);
  }
}
