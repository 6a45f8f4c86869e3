//! Independent runs spread over the cores, with a progress bar when stderr is a terminal.
//!
//! Workers take the next item from a shared counter (runs differ in cost: a diverging or chaotic
//! run is no cheaper than a periodic one, but the long tail evens out this way) and send results
//! back over a channel; the calling thread keeps the progress bar and puts results back in input
//! order, so the output does not depend on the number of threads.

use anyhow::{anyhow, Result};
use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// The number of worker threads: `requested`, or every core.
pub fn jobs(requested: Option<usize>) -> usize {
    requested
        .unwrap_or_else(|| {
            std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1)
        })
        .max(1)
}

/// `f` on every item, on `jobs` threads; results in input order.
pub fn run_all<T: Sync, R: Send>(
    items: &[T],
    jobs: usize,
    what: &str,
    f: impl Fn(&T) -> R + Sync,
) -> Result<Vec<R>> {
    let n = items.len();
    let next = AtomicUsize::new(0);
    let (tx, rx) = crossbeam::channel::unbounded::<(usize, R)>();
    let mut results: Vec<Option<R>> = (0..n).map(|_| None).collect();
    let mut progress = Progress::new(what, n);
    crossbeam::scope(|s| {
        for _ in 0..jobs.min(n).max(1) {
            let tx = tx.clone();
            let (next, f) = (&next, &f);
            s.spawn(move |_| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= n {
                    break;
                }
                if tx.send((i, f(&items[i]))).is_err() {
                    break;
                }
            });
        }
        drop(tx);
        for (i, r) in rx.iter() {
            results[i] = Some(r);
            progress.tick();
        }
    })
    .map_err(|_| anyhow!("an analysis worker thread panicked"))?;
    progress.finish();
    results
        .into_iter()
        .map(|r| r.ok_or_else(|| anyhow!("an analysis run produced no result")))
        .collect()
}

/// A one-line progress bar on stderr, drawn only on a terminal (logs and tests stay clean).
pub struct Progress {
    what: String,
    total: usize,
    done: usize,
    start: Instant,
    enabled: bool,
}

impl Progress {
    pub fn new(what: &str, total: usize) -> Self {
        let p = Self {
            what: what.to_string(),
            total,
            done: 0,
            start: Instant::now(),
            enabled: std::io::stderr().is_terminal() && total > 1,
        };
        p.draw();
        p
    }

    pub fn tick(&mut self) {
        self.done += 1;
        self.draw();
    }

    fn draw(&self) {
        if !self.enabled {
            return;
        }
        let width = 30;
        let filled = (self.done * width).checked_div(self.total).unwrap_or(0);
        let elapsed = self.start.elapsed().as_secs_f64();
        let eta = if self.done > 0 {
            format!(
                ", ~{:.0} s left",
                elapsed / self.done as f64 * (self.total - self.done) as f64
            )
        } else {
            String::new()
        };
        let mut err = std::io::stderr().lock();
        let _ = write!(
            err,
            "\r{} [{}{}] {}/{} ({:.1} s{eta})\x1b[K",
            self.what,
            "#".repeat(filled),
            ".".repeat(width - filled),
            self.done,
            self.total,
            elapsed
        );
        let _ = err.flush();
    }

    pub fn finish(&self) {
        if self.enabled {
            let mut err = std::io::stderr().lock();
            let _ = write!(err, "\r\x1b[K");
            let _ = err.flush();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_back_in_order_on_any_thread_count() {
        let items: Vec<u64> = (0..50).collect();
        for j in [1, 2, 7] {
            let out = run_all(&items, j, "test", |x| x * x).unwrap();
            assert_eq!(out, items.iter().map(|x| x * x).collect::<Vec<_>>());
        }
        assert!(run_all(&Vec::<u64>::new(), 2, "empty", |x| *x)
            .unwrap()
            .is_empty());
    }
}
