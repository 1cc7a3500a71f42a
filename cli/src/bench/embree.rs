//! Native Embree 3 (through the `embree` crate, which links Debian's `libembree3`) over the
//! same triangles as the tracer's BVH, for `tessera bench rays --embree` only. Built with
//! the `cli` crate's `embree` feature; `scripts/install-embree.sh` installs the library.

use cgmath::{Vector3, Vector4};
use embree::{Device, Geometry, IntersectContext, RayHit, Scene, TriangleMesh};
use glam::Vec3;

use tracer::geometry::Ray;

/// Embree's closest-hit and any-hit queries over `triangles` (one geometry, Embree's
/// default build: medium quality, as an application that does not tune it gets), handed
/// to `run` while the scene lives.
pub fn with_scene<R>(triangles: &[[Vec3; 3]], run: impl FnOnce(&EmbreeQueries) -> R) -> R {
    let device = Device::new();
    let mut mesh = TriangleMesh::unanimated(&device, triangles.len(), 3 * triangles.len());
    {
        let mut vertices = mesh.vertex_buffer.map();
        for (i, tri) in triangles.iter().enumerate() {
            for (j, v) in tri.iter().enumerate() {
                vertices[3 * i + j] = Vector4::new(v.x, v.y, v.z, 0.0);
            }
        }
    }
    {
        let mut indices = mesh.index_buffer.map();
        for i in 0..triangles.len() {
            let k = 3 * i as u32;
            indices[i] = Vector3::new(k, k + 1, k + 2);
        }
    }
    let mut geometry = Geometry::Triangle(mesh);
    geometry.commit();
    let mut scene = Scene::new(&device);
    scene.attach_geometry(geometry);
    let committed = scene.commit();
    run(&EmbreeQueries { scene: &committed })
}

/// Ray queries on a committed Embree scene.
pub struct EmbreeQueries<'a> {
    scene: &'a embree::CommittedScene<'a>,
}

// Embree's rtcIntersect1 and rtcOccluded1 may be called from any thread on a committed
// scene (Embree's API documentation); the crate only lacks the marker.
unsafe impl Sync for EmbreeQueries<'_> {}

fn embree_ray(ray: &Ray, t_max: f32) -> embree::Ray {
    let (o, d) = (ray.origin, ray.dir);
    embree::Ray::segment(
        Vector3::new(o.x, o.y, o.z),
        Vector3::new(d.x, d.y, d.z),
        0.0,
        t_max,
    )
}

impl EmbreeQueries<'_> {
    /// The distance to the closest hit before `t_max`, in units of `ray.dir`.
    pub fn intersect(&self, ray: &Ray, t_max: f32, coherent: bool) -> Option<f32> {
        let mut context = if coherent {
            IntersectContext::coherent()
        } else {
            IntersectContext::incoherent()
        };
        let mut hit = RayHit::new(embree_ray(ray, t_max));
        self.scene.intersect(&mut context, &mut hit);
        hit.hit.hit().then_some(hit.ray.tfar)
    }

    /// Whether anything lies on the ray before `t_max`.
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        let mut context = IntersectContext::incoherent();
        let mut ray = embree_ray(ray, t_max);
        self.scene.occluded(&mut context, &mut ray);
        // Embree marks an occluded ray by setting its tfar to -inf.
        ray.tfar < 0.0
    }
}
