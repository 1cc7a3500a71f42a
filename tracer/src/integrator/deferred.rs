//! Light gathered now and added later, so that shadow rays can be traced eight at a time.
//!
//! Whether a shadow ray is blocked changes only whether its light is added: never where the
//! path goes next. So a camera sample's paths can be followed to their ends with their
//! shadow rays queued, the shadow rays of several samples traced together in packets
//! (`bvh/packet.rs`, each answered as alone), and each sample's light summed afterwards, in
//! the order it was gathered, leaving out what a blocked ray carried: the same additions
//! as adding each term when it was found, so the same bits.

use std::ops::Range;

use glam::{Vec3, Vec4};

use super::carrier::Colour;
use crate::bvh::{PacketStack, PACKET};
use crate::frame::PreparedFrame;
use crate::geometry::Ray;

/// A term that no shadow ray decides.
const UNSHADOWED: u32 = u32::MAX;

/// The light terms of a batch of camera samples, in the order they were gathered, and the
/// shadow rays that decide them.
#[derive(Debug, Default)]
pub(super) struct Deferred<C> {
    /// Each term and the shadow ray whose blocking drops it ([`UNSHADOWED`] for none).
    terms: Vec<(C, u32)>,
    shadows: Vec<Shadow>,
    /// Per shadow ray, once [`Self::trace_shadows`] ran: whether it is blocked.
    blocked: Vec<bool>,
    /// The shadow rays in the order they are traced.
    order: Vec<u32>,
}

/// A queued shadow ray: what is traced, and the bounce it left (rays of one bounce of a
/// pixel's samples travel together).
#[derive(Debug)]
struct Shadow {
    ray: Ray,
    t_max: f32,
    depth: u32,
}

/// What batches of samples reuse: their light lists, which cost 3% of the box's
/// instructions allocated per batch, and the packets' stack. Owned by the caller (a row of
/// a tile): a thread-local one, reached through a closure, kept the path loop out of its
/// AVX copy.
#[derive(Debug, Default)]
pub struct SampleScratch {
    rgb: Deferred<Vec3>,
    spectral: Deferred<Vec4>,
    stack: PacketStack,
}

impl SampleScratch {
    /// Scratch for one thread's batches.
    pub fn new() -> Self {
        Self::default()
    }
}

/// A colour a path carries, and its list in a [`SampleScratch`].
pub(super) trait Gathered: Colour {
    /// The scratch's list for this colour, emptied, and the packets' stack.
    fn parts(scratch: &mut SampleScratch) -> (&mut Deferred<Self>, &mut PacketStack);
}

impl Gathered for Vec3 {
    fn parts(scratch: &mut SampleScratch) -> (&mut Deferred<Self>, &mut PacketStack) {
        scratch.rgb.clear();
        (&mut scratch.rgb, &mut scratch.stack)
    }
}

impl Gathered for Vec4 {
    fn parts(scratch: &mut SampleScratch) -> (&mut Deferred<Self>, &mut PacketStack) {
        scratch.spectral.clear();
        (&mut scratch.spectral, &mut scratch.stack)
    }
}

impl<C: Colour> Deferred<C> {
    fn clear(&mut self) {
        self.terms.clear();
        self.shadows.clear();
    }

    /// Where the next term goes: a sample's terms are those between its start and the next
    /// sample's.
    pub fn mark(&self) -> usize {
        self.terms.len()
    }

    /// Light `c` that reaches the camera.
    #[inline(always)]
    pub fn add(&mut self, c: C) {
        self.terms.push((c, UNSHADOWED));
    }

    /// Light `c` that reaches the camera unless something blocks `ray` before `t_max`; the
    /// ray left bounce `depth`.
    #[inline(always)]
    pub fn add_unless_blocked(&mut self, c: C, ray: Ray, t_max: f32, depth: u32) {
        self.terms.push((c, self.shadows.len() as u32));
        self.shadows.push(Shadow { ray, t_max, depth });
    }

    /// Traces the queued shadow rays: each bounce's rays together, eight at a time, by
    /// `occluded_packet` (a lone ray by `occluded`, which answers the same).
    #[inline(always)]
    pub fn trace_shadows(
        &mut self,
        frame: &PreparedFrame,
        stack: &mut PacketStack,
        occluded_packet: impl Fn(
            &PreparedFrame,
            &[Ray; PACKET],
            &[f32; PACKET],
            u32,
            &mut PacketStack,
        ) -> u32,
        occluded: impl Fn(&PreparedFrame, &Ray, f32) -> bool,
    ) {
        let shadows = &self.shadows;
        self.order.clear();
        self.order.extend(0..shadows.len() as u32);
        // By bounce, then as queued: a key per ray, so any sort gives this order.
        self.order
            .sort_unstable_by_key(|&i| (shadows[i as usize].depth, i));
        self.blocked.clear();
        self.blocked.resize(shadows.len(), false);
        for packet in self.order.chunks(PACKET) {
            if let [i] = packet {
                let s = &shadows[*i as usize];
                self.blocked[*i as usize] = occluded(frame, &s.ray, s.t_max);
                continue;
            }
            let shadow = |k: usize| &shadows[packet[k.min(packet.len() - 1)] as usize];
            let rays = std::array::from_fn(|k| shadow(k).ray);
            let t_max = std::array::from_fn(|k| shadow(k).t_max);
            let mask = (1 << packet.len()) - 1;
            let blocked = occluded_packet(frame, &rays, &t_max, mask, stack);
            for (k, &i) in packet.iter().enumerate() {
                self.blocked[i as usize] = blocked >> k & 1 == 1;
            }
        }
    }

    /// The light of the terms in `terms` (a sample's, from its [`Self::mark`] to the next),
    /// summed in order, those of blocked shadow rays left out.
    pub fn sum(&self, terms: Range<usize>) -> C {
        let mut sum = C::ZERO;
        for &(c, shadow) in &self.terms[terms] {
            if shadow == UNSHADOWED || !self.blocked[shadow as usize] {
                sum += c;
            }
        }
        sum
    }
}
