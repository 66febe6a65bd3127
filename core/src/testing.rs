//! Helpers of the unit tests.

/// A xorshift64 generator from `seed` (non-zero): each call gives a value
/// below `m` (0 for `m` = 0 or 1).
pub(crate) fn rng(seed: u64) -> impl FnMut(u64) -> u64 {
    let mut x = seed;
    move |m: u64| {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x % m.max(1)
    }
}
