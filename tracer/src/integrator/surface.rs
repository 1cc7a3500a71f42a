//! The surface point a ray hits: position with its error bound, geometric and shading
//! frames (normal maps, anisotropy directions, clear-coat normals), and the material's
//! values there.

use glam::Vec3;

use crate::bsdf::SurfaceParams;
use crate::frame::PreparedFrame;
use crate::geometry::{barycentric, plane_hit_point, Frame, Hit, Ray};
use crate::math;

/// Shading and geometric normals closer than this (in cosine: 0.08°) count as one: the
/// wedge between their tangent planes holds a fraction of order 1e-6 of any lobe, where
/// folding (see [`fold`](super::folding::fold)) would cost every bounce on a transformed
/// flat mesh, whose normals differ from its facets' by rounding alone.
const FLAT_COS: f32 = 1.0 - 1e-6;

/// Everything the integrator needs at a surface point.
pub(crate) struct SurfacePoint {
    /// Position (camera-relative world space).
    pub p: Vec3,
    /// Bound on the error of `p`, per coordinate (see
    /// [`hit_point_error`](crate::geometry::hit_point_error)).
    pub p_error: Vec3,
    /// Geometric normal, unit, on the side of the surface's front face.
    pub ng: Vec3,
    /// Shading frame (normal map and interpolated normal applied).
    pub frame: Frame,
    /// The clear coat's normal where it differs from the shading normal (the coat has
    /// its own normal map, or the base's is not the coat's).
    pub coat_normal: Option<Vec3>,
    /// Whether the shading normal differs from the geometric one, so that some directions
    /// lie between the two tangent planes (see [`fold`](super::folding::fold)).
    pub curved: bool,
    /// Whether the ray arrived on the front face.
    pub front: bool,
    /// Emitted radiance at the point.
    pub emission: Vec3,
    /// The BSDF's parameters at the point where textures or vertex colours may change
    /// them; `None` where they are the material's factors (its prepared BSDF applies).
    pub varying: Option<SurfaceParams>,
    /// Whether the material emits only from its front face.
    pub single_sided: bool,
    /// The material's index in the scene.
    pub material_index: u32,
}

/// Builds the surface point of `hit` on `ray`, with the hit instance where it is at the
/// ray's time.
// Inlined into each path loop (RGB and spectral): called out of line, as two callers made
// the compiler choose, the Cornell box counted 2.5% more instructions.
#[inline(always)]
pub(crate) fn surface_point(frame: &PreparedFrame, ray: &Ray, hit: &Hit) -> SurfacePoint {
    let scene = &*frame.scene;
    let mut moved = None;
    let tri = frame.triangle_at(hit.instance, hit.triangle, ray.time, &mut moved);
    let (prim, t) = (tri.prim, tri.t);
    let (b1, b2) = (hit.b1, hit.b2);

    // Position where the object-space ray meets the triangle's plane, in double precision:
    // exactly on the plane, and not off along it by the rounding of barycentrics times
    // vertices, which on a triangle 1e5 across is centimetres. Then to world.
    let object_ray = tri.object_ray(ray);
    // Read once: a deformed mesh's are interpolated over the shutter at each read.
    let positions = tri.positions();
    let (p_object, object_error) = plane_hit_point(&object_ray, positions).unwrap_or_else(|| {
        // Interpolated instead: off by the vertices' rounding (pbrt-v4's bound).
        let [a, b, c] = positions;
        let weights = a.abs() * (1.0 - b1 - b2).abs() + b.abs() * b1.abs() + c.abs() * b2.abs();
        (
            barycentric(a, b, c, b1, b2),
            weights * crate::triangle::gamma(7),
        )
    });
    let (p, p_error) = tri.world_point(p_object, object_error);
    let ng_raw = tri.front_normal(positions);
    let ng = if ng_raw == Vec3::ZERO {
        -ray.dir.normalize()
    } else {
        ng_raw
    };
    let front = ng.dot(ray.dir) < 0.0;

    let prepared = &frame.materials[prim.material as usize];
    let material = &prepared.material;
    // Borrowed where it is the same everywhere: it is large enough that copying it shows.
    let varying_sample;
    let (sample, uniform) = match &prepared.uniform {
        Some(sample) if prim.colors.is_empty() => (sample, true),
        _ => {
            let (uvs, color) = (prim.uvs_at(t, b1, b2), prim.color_at(t, b1, b2));
            varying_sample = material.sample(&scene.textures, uvs, color);
            (&varying_sample, false)
        }
    };

    // Interpolated shading normal; missing or degenerate normals fall back to the face. One
    // facing away from the front face is that normal written reversed (normals flipped
    // against the winding): it is turned to the front, which the winding defines in glTF.
    let mut ns = match tri.normal_at(b1, b2) {
        None => ng,
        Some(n) => {
            // A zero or non-finite normal falls back to the face's (what `normalize_or`
            // gives is always finite).
            let n = math::normalize_or(*tri.normal_to_world() * n, ng);
            if n.dot(ng) < 0.0 {
                -n
            } else {
                n
            }
        }
    };
    let mut shading = Frame::from_normal(ns);
    let unmapped = ns;
    // The tangent frame around normal `n`: tangent, bitangent, normal. glTF's bitangent
    // is cross(normal, tangent) · w in the mesh's space; a mirroring placement (negative
    // determinant) reverses cross products, so w turns with it.
    let tangent_frame = |n: Vec3| -> Option<Frame> {
        let t4 = tri.tangent_at(b1, b2)?;
        let tf = Frame::from_normal_tangent(n, tri.to_world().transform_vector3(t4.truncate()));
        let mirrored = tri.to_world().matrix3.determinant() < 0.0;
        let sign = if (t4.w < 0.0) != mirrored { -1.0 } else { 1.0 };
        Some(Frame {
            y: tf.y * sign,
            ..tf
        })
    };
    // Applies a tangent-space normal map to the interpolated normal.
    let map_normal = |nm: Vec3| -> Option<(Vec3, Vec3)> {
        let tf = tangent_frame(unmapped)?;
        let mapped = tf.to_world(nm);
        // A map that bends the normal below the surface is broken there: it is ignored.
        let m = math::try_normalize(mapped).filter(|m| m.dot(ng) > 0.0)?;
        Some((m, tf.x))
    };
    if let Some((m, tangent)) = sample.normal_map.and_then(map_normal) {
        ns = m;
        shading = Frame::from_normal_tangent(ns, tangent);
    }
    // An anisotropic BSDF is rougher along its frame's x axis: point that axis in the
    // material's direction (tangent space). Without tangents (the loader warns) the frame
    // keeps an arbitrary, continuous tangent.
    if let Some(d) = sample.anisotropy_direction {
        if let Some(tf) = tangent_frame(ns) {
            shading = Frame::from_normal_tangent(ns, tf.x * d.x + tf.y * d.y);
        }
    }
    // The clear coat lies on its own normal map, else on the unmapped normal.
    let coat_normal = if sample.surface.extensions.is_some_and(|l| l.clearcoat > 0.0) {
        sample
            .clearcoat_normal_map
            .and_then(map_normal)
            .map(|(m, _)| m)
            .or((ns != unmapped).then_some(unmapped))
    } else {
        None
    };

    // Opaque surfaces are shaded from the side the ray came from; transmissive ones keep
    // their orientation so the BSDF knows inside from outside.
    let transmissive = sample.surface.transmission > 0.0;
    let (ng, shading, coat_normal) = if !front && !transmissive {
        let flipped = Frame {
            x: shading.x,
            y: -shading.y,
            z: -shading.z,
        };
        (-ng, flipped, coat_normal.map(|n| -n))
    } else {
        (ng, shading, coat_normal)
    };
    // Seen from under its shading normal while above the surface (or the reverse), a point
    // would reflect light into the surface or lose it: it is shaded with the geometric
    // normal, whose frame conserves energy, instead.
    let wo = -ray.dir;
    let shading = if (wo.dot(shading.z) > 0.0) != (wo.dot(ng) > 0.0) {
        Frame::from_normal_tangent(ng, shading.x)
    } else {
        shading
    };
    SurfacePoint {
        p,
        p_error,
        ng,
        curved: shading.z.dot(ng) < FLAT_COS,
        frame: shading,
        // A coat normal facing away from the viewer is the geometric fallback's case too.
        coat_normal: coat_normal.filter(|n| wo.dot(*n) > 0.0),
        front,
        emission: sample.emission,
        varying: (!uniform).then_some(sample.surface),
        single_sided: !material.double_sided,
        material_index: prim.material,
    }
}
