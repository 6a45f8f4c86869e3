//! One seeded generator for the crate's property tests, so that each test draws its random
//! problems the same way and a failure is repeated by its seed.

/// Uniform numbers in [-1, 1) from `seed` (Knuth's 64-bit linear congruential generator, the top
/// 53 bits): the same seed, the same sequence on every machine.
pub(crate) fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}
