//! One seeded generator for whatever draws at random: the crate's property tests and the
//! client's random starts. The same seed gives the same numbers on every machine, so a failing
//! test or a study's start is repeated by its seed alone.

/// Uniform numbers in [-1, 1) from `seed` (Knuth's 64-bit linear congruential generator, the top
/// 53 bits).
///
/// ```
/// let mut u = control::basics::rng::uniform(7);
/// let (a, b) = (u(), u());
/// assert!((-1.0..1.0).contains(&a) && a != b);
/// assert_eq!(control::basics::rng::uniform(7)(), a);
/// ```
pub fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// A seed for the `k`-th of many draws under `seed` (SplitMix64's finaliser): neighbouring
/// `k` give unrelated seeds, so draw k does not depend on how many others there are.
///
/// ```
/// use control::basics::rng::mix;
/// assert_eq!(mix(1, 5), mix(1, 5));
/// assert_ne!(mix(1, 5), mix(1, 6));
/// assert_ne!(mix(1, 5), mix(2, 5));
/// ```
pub fn mix(seed: u64, k: u64) -> u64 {
    let mut z = seed
        .wrapping_mul(0x9e37_79b9_7f4a_7c15)
        .wrapping_add(k.wrapping_add(1).wrapping_mul(0xbf58_476d_1ce4_e5b9));
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}
