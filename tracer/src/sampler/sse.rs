//! A bounce's dimensions ([`PixelSampler::next_bounce_sse41`](super::PixelSampler::next_bounce_sse41))
//! in two SSE registers of four lanes: the same integer operations as the portable code
//! (`PixelSampler::next_bounce`), lane for lane, so the same bits.

use std::arch::x86_64::{
    __m128i, _mm_add_epi32, _mm_and_si128, _mm_cvtepi32_ps, _mm_extract_epi32, _mm_insert_epi32,
    _mm_loadu_si128, _mm_mul_ps, _mm_mullo_epi32, _mm_or_si128, _mm_set1_epi32, _mm_set1_epi8,
    _mm_set1_ps, _mm_setr_epi32, _mm_setr_epi8, _mm_shuffle_epi8, _mm_slli_epi32, _mm_srli_epi16,
    _mm_srli_epi32, _mm_storeu_ps, _mm_xor_si128,
};

use super::{sobol1_reversed, BounceDimensions, Lanes, FIRST_COORDINATE, LANES};
use super::{SECOND_COORDINATE, TO_UNIT};

/// The coordinates of a bounce for a sample whose pixel seed is `pixel_seed` and whose
/// index, bit-reversed, is `index_reversed`, from its lanes' dimension hashes `hashed`
/// (see `LANE_DIMENSION`).
///
/// # Safety
/// The CPU must have SSE4.1 and SSSE3.
#[target_feature(enable = "sse4.1,ssse3")]
#[inline]
pub(super) unsafe fn bounce(
    pixel_seed: u32,
    index_reversed: u32,
    hashed: Lanes,
) -> BounceDimensions {
    let [low, high] = halves(hashed);
    let seed = [low, high].map(|h| combine(splat(pixel_seed), h));
    let shuffled = seed.map(|s| scramble_reversed(splat(index_reversed), s));
    // Lanes 5 to 7 (the high half's 1 to 3) take the second Sobol dimension of the
    // shuffled index: lane 7 is lane 6 again.
    let second = |lane| sobol1_reversed(lane as u32) as i32;
    let (v5, v6) = (
        second(_mm_extract_epi32::<1>(shuffled[1])),
        second(_mm_extract_epi32::<2>(shuffled[1])),
    );
    let high_value = _mm_insert_epi32::<3>(
        _mm_insert_epi32::<2>(_mm_insert_epi32::<1>(shuffled[1], v5), v6),
        v6,
    );
    let value = [shuffled[0], high_value];
    let value_seed = [
        combine(seed[0], splat(FIRST_COORDINATE)),
        combine(
            seed[1],
            _mm_setr_epi32(
                FIRST_COORDINATE as i32,
                SECOND_COORDINATE as i32,
                SECOND_COORDINATE as i32,
                SECOND_COORDINATE as i32,
            ),
        ),
    ];
    let mut u = [0.0f32; LANES];
    for (half, (v, s)) in value.into_iter().zip(value_seed).enumerate() {
        // `to_unit`: the top 24 bits, exact in an i32 and in an f32, scaled.
        let bits = _mm_srli_epi32::<8>(scramble_reversed(v, s));
        let unit = _mm_mul_ps(_mm_cvtepi32_ps(bits), _mm_set1_ps(TO_UNIT));
        _mm_storeu_ps(u[4 * half..].as_mut_ptr(), unit);
    }
    BounceDimensions::from_lanes(u)
}

#[inline(always)]
unsafe fn splat(x: u32) -> __m128i {
    _mm_set1_epi32(x as i32)
}

/// Lanes 0 to 3 and 4 to 7.
#[inline(always)]
unsafe fn halves(lanes: Lanes) -> [__m128i; 2] {
    [0, 4].map(|k| _mm_loadu_si128(lanes[k..].as_ptr().cast()))
}

/// `combine_hashed` lane by lane.
#[inline(always)]
unsafe fn combine(seed: __m128i, hashed: __m128i) -> __m128i {
    let sum = _mm_add_epi32(
        _mm_add_epi32(
            _mm_add_epi32(hashed, splat(0x9e37_79b9)),
            _mm_slli_epi32::<6>(seed),
        ),
        _mm_srli_epi32::<2>(seed),
    );
    _mm_xor_si128(seed, sum)
}

/// `scramble_reversed` lane by lane: the Laine-Karras permutation, then the bits reversed.
#[inline(always)]
unsafe fn scramble_reversed(x: __m128i, seed: __m128i) -> __m128i {
    let mut x = _mm_add_epi32(x, seed);
    for m in [0x6c50_b47c_u32, 0xb82f_1e52, 0xc7af_e638, 0x8d22_f6e6] {
        x = _mm_xor_si128(x, _mm_mullo_epi32(x, splat(m)));
    }
    reverse_bits(x)
}

/// `u32::reverse_bits` lane by lane: the bytes in reverse order, then each byte's two
/// nibbles reversed through a table and swapped.
#[inline(always)]
unsafe fn reverse_bits(x: __m128i) -> __m128i {
    let bytes = _mm_shuffle_epi8(
        x,
        _mm_setr_epi8(3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12),
    );
    let nibble = _mm_set1_epi8(0x0f);
    let low = _mm_and_si128(bytes, nibble);
    let high = _mm_and_si128(_mm_srli_epi16::<4>(bytes), nibble);
    // Entry `i`: the four bits of `i` reversed, as a byte's high nibble and as its low one.
    let reversed = |shift: u32| {
        let r = |i: u8| ((i.reverse_bits() >> 4) << shift) as i8;
        _mm_setr_epi8(
            r(0),
            r(1),
            r(2),
            r(3),
            r(4),
            r(5),
            r(6),
            r(7),
            r(8),
            r(9),
            r(10),
            r(11),
            r(12),
            r(13),
            r(14),
            r(15),
        )
    };
    _mm_or_si128(
        _mm_shuffle_epi8(reversed(4), low),
        _mm_shuffle_epi8(reversed(0), high),
    )
}
