//! The seed convention every renderer and sweep shares: one base seed mixed with indices (pattern,
//! frame, realisation) into unrelated streams, so a frame's noise and a print's layout are
//! reproducible from the base seed alone.

/// Mixes seeds (SplitMix64 finaliser) so neighbouring indices give unrelated streams.
pub fn derive_seed(seed: u64, a: u64, b: u64) -> u64 {
    let mut z =
        seed ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
