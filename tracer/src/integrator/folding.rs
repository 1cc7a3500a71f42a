//! Directions in the wedge between the shading and the geometric tangent planes, folded
//! through the geometric one (see [`fold`]): the scattering `g` that a bounce samples and
//! light sampling evaluates, and its density.

use glam::Vec3;

use super::surface::SurfacePoint;
use crate::bsdf::BsdfAt;

/// Whether a direction is on the geometric side its shading-frame sign claims: stops
/// light leaking through surfaces whose shading normal disagrees with the geometry.
pub(super) fn consistent_side(sp: &SurfacePoint, wi: Vec3, wi_local: Vec3) -> bool {
    (wi.dot(sp.ng) > 0.0) == (wi_local.z > 0.0)
}

/// The mirror image of `w` through the geometric tangent plane.
///
/// Where the shading normal differs from the geometric one, the BSDF (in the shading
/// frame) sends some light into the wedge between the two tangent planes: a reflection
/// that would pass below the geometric surface, or a refraction that would stay above
/// it. Ending those paths loses their energy, bounce after bounce where light is trapped
/// (rough glass of IOR 10 read 0.955 in a white furnace), and following them leaks light
/// through the surface. Instead each such direction is folded through the geometric
/// tangent plane, which carries it to the side the BSDF meant and out of the wedge (the
/// mirror of a wedge direction is consistent). The fold keeps solid angle, so the
/// surface scatters `g(v) = f(v)|cos v| + f(u)|cos u|`, `u` the mirror of `v` where `u`
/// lies in the wedge: the same energy as `f`, moved off the wedge. A sample keeps its
/// weight `f(w)|cos w| / p(w)` (unbiased for `g`, whichever way it reached `v`); light
/// sampling evaluates `g` and both strategies' MIS weights use `g`'s density
/// ([`eval_folded`], [`pdf_folded`]). This is our own construction, not a published one.
pub(super) fn fold(sp: &SurfacePoint, w: Vec3) -> Vec3 {
    w - 2.0 * w.dot(sp.ng) * sp.ng
}

/// The mirror of a consistent `v`, in local coordinates, where it lies in the wedge, so
/// that `g` at `v` gathers it too (see [`fold`]); `None` on a flat point or where the
/// mirror is consistent itself.
fn wedge_mirror(sp: &SurfacePoint, v: Vec3) -> Option<Vec3> {
    if !sp.curved {
        return None;
    }
    let u = fold(sp, v);
    let u_local = sp.frame.to_local(u);
    (!consistent_side(sp, u, u_local)).then_some(u_local)
}

/// `g(wi)` (cosine included) and its density, for a consistent `wi` (see [`fold`]).
#[inline(always)]
pub(super) fn eval_folded(
    sp: &SurfacePoint,
    scatter: &BsdfAt<'_>,
    wi: Vec3,
    wi_local: Vec3,
) -> (Vec3, f32) {
    let (f, pdf) = scatter.eval_and_pdf(wi_local);
    let mut f = f * wi_local.z.abs();
    let mut pdf = pdf;
    if let Some(u_local) = wedge_mirror(sp, wi) {
        let (fu, pu) = scatter.eval_and_pdf(u_local);
        f += fu * u_local.z.abs();
        pdf += pu;
    }
    (f, pdf)
}

/// The density of `g` at a consistent `v` that a sample reached with density `sampled` at
/// `w` (`v` itself, or its fold).
#[inline(always)]
pub(super) fn pdf_folded(
    sp: &SurfacePoint,
    scatter: &BsdfAt<'_>,
    v: Vec3,
    folded: bool,
    sampled: f32,
) -> f32 {
    if !sp.curved {
        return sampled;
    }
    if folded {
        // The mirror of `v` is `w`, in the wedge: both ways count.
        return sampled + scatter.pdf(sp.frame.to_local(v));
    }
    sampled + wedge_mirror(sp, v).map_or(0.0, |u_local| scatter.pdf(u_local))
}
