//! Shadow rays eight at a time: a packet of rays traverses an eight-wide hierarchy
//! together, each child visited once for the rays that entered it, each ray leaving the
//! packet at its first hit (Wald et al., "Interactive Rendering with Coherent Ray Tracing",
//! 2001, on eight-wide nodes).
//!
//! Every ray gets the answer it gets alone. An any-hit search never lowers its bound, so
//! whether it finds a hit does not depend on the order it visits boxes in; each ray enters
//! a child by its own slab test ([`WideRay::enter`], the single ray's), so it visits the
//! boxes it visits alone, and tests the triangles it tests alone by the same operations
//! ([`SharedAxes`](crate::triangle::SharedAxes)). What the packet shares is the walk: one
//! stack entry, one visit and one load of a leaf's triangles for all the rays that reach
//! it, and the triangle test with the rays in SIMD lanes.

use super::node::STACK_CAPACITY;
use super::wide::{WideNode, WideRay, WIDTH};

/// Rays per packet: a bit each in a `u32` mask.
pub const PACKET: usize = 8;

/// A deferred subtree on a packet's stack: its node's lane (`8·node + lane`) and the rays
/// that entered it (bit `r` for ray `r`).
pub(super) type PacketEntry = (u32, u32);

/// A packet query's stack, as `node::with_stack`'s for single rays (the same bound: a node
/// leaves at most seven of its children on it). Its owner passes it to each query: a
/// thread-local one, reached through a closure, kept the query out of the AVX copy of the
/// path loop that calls it.
pub struct PacketStack(Box<[PacketEntry]>);

impl PacketStack {
    /// A stack for packet queries on this thread.
    pub fn new() -> Self {
        Self(vec![(0, 0); STACK_CAPACITY].into_boxed_slice())
    }

    pub(super) fn entries(&mut self) -> &mut [PacketEntry] {
        &mut self.0
    }
}

impl Default for PacketStack {
    fn default() -> Self {
        Self::new()
    }
}

impl std::fmt::Debug for PacketStack {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("PacketStack")
    }
}

/// The rays of `mask`, lowest first.
#[inline(always)]
pub(super) fn each_ray(mut mask: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let r = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            r
        })
    })
}

/// Visits, for the rays of `mask`, the leaves of an eight-wide hierarchy whose boxes each
/// ray enters before its `t_max`: `leaf(start, count, rays, stack)` for the rays `rays`
/// that entered the leaf and have not yet been blocked, returning those it blocks. Returns
/// the rays blocked. Children are visited in reverse lane order, as the single ray's
/// any-hit traversal ([`traverse_wide`](super::wide::traverse_wide)) visits them.
#[inline(always)]
pub(super) fn traverse_packet<const AVX: bool>(
    nodes: &[WideNode],
    rays: &[WideRay; PACKET],
    t_max: &[f32; PACKET],
    mask: u32,
    stack: &mut [PacketEntry],
    mut leaf: impl FnMut(u32, u32, u32, &mut [PacketEntry]) -> u32,
) -> u32 {
    if nodes.is_empty() || mask == 0 {
        return 0;
    }
    // Rays not yet blocked.
    let mut open = mask;
    let mut len = 0;
    let (mut current, mut entering) = (0u32, mask);
    loop {
        let node = &nodes[current as usize];
        // Bit `r` of `entered[lane]`: ray `r` enters child `lane`.
        let mut entered = [0u32; WIDTH];
        for r in each_ray(entering) {
            let (_, mut hits) = rays[r].enter::<AVX>(node, t_max[r]);
            while hits != 0 {
                let lane = hits.trailing_zeros() as usize;
                hits &= hits - 1;
                entered[lane] |= 1 << r;
            }
        }
        for (lane, &rays) in entered.iter().enumerate() {
            if rays != 0 {
                stack[len] = (current * WIDTH as u32 + lane as u32, rays);
                len += 1;
            }
        }
        loop {
            if len == 0 {
                return mask & !open;
            }
            len -= 1;
            let (lane_ref, rays) = stack[len];
            let rays = rays & open;
            if rays == 0 {
                continue;
            }
            let node = &nodes[(lane_ref / WIDTH as u32) as usize];
            let (start, count) = node.child((lane_ref % WIDTH as u32) as usize);
            if count == 0 {
                (current, entering) = (start, rays);
                break;
            }
            open &= !leaf(start, count, rays, &mut stack[len..]);
            if open == 0 {
                return mask;
            }
        }
    }
}

#[cfg(test)]
mod tests;
