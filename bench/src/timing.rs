//! The batched per-call timer the compute sections share, in a leaf of its own so that
//! `compute` and the sections it gathers (`commands`, `spatial_timing`) need not import each other.

use crate::stats::histogram;
use std::time::Instant;

/// Per-call latency of `f`, measured in batches (the clock costs more than one call).
pub(crate) fn per_call(
    batches: usize,
    batch: usize,
    mut f: impl FnMut(usize),
) -> hdrhistogram::Histogram<u64> {
    let mut h = histogram();
    for i in 0..batches / 10 {
        f(i); // warm-up
    }
    for b in 0..batches {
        let t0 = Instant::now();
        for i in 0..batch {
            f(b * batch + i);
        }
        let ns = t0.elapsed().as_nanos() as u64 / batch as u64;
        h.saturating_record(ns.max(1));
    }
    h
}
