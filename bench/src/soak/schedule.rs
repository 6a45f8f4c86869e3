//! The soak's fault plan: which fault, when and for how long, drawn from a seed.
//!
//! The plan is computed before anything starts, so a seed names a run: the same seed and
//! length give the same faults in the same order at the same planned times. Kinds are dealt
//! from a shuffled deck, one of each kind per round, so every kind appears once the run is
//! long enough for one round (about 40 s with all seven kinds), and no kind starves. The soak's
//! [`Options`] are the plan's inputs (length, seed, kinds), so they are defined here too.

use anyhow::{bail, Result};
use std::time::Duration;

/// A small deterministic PRNG (SplitMix64): no dependency, good enough to pick times.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi) seconds.
    pub fn secs(&mut self, lo: f64, hi: f64) -> Duration {
        Duration::from_secs_f64(lo + (hi - lo) * self.unit())
    }

    /// Uniform in 0..n (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// The faults the soak injects.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, clap::ValueEnum)]
pub enum FaultKind {
    /// kill -9 of the plant, restarted after a pause.
    KillPlant,
    /// kill -9 of the daemon, restarted after a pause.
    KillDaemon,
    /// SIGSTOP of the plant, SIGCONT after a pause.
    StopPlant,
    /// SIGSTOP of the daemon, SIGCONT after a pause.
    StopDaemon,
    /// A busy thread pinned to the loop's core, above the loop's priority when permitted.
    Hog,
    /// A rogue publisher of garbage states in place of the plant.
    Rogue,
    /// A burst of status/get/set requests through the control service.
    Burst,
}

impl FaultKind {
    pub const ALL: [FaultKind; 7] = [
        FaultKind::KillPlant,
        FaultKind::KillDaemon,
        FaultKind::StopPlant,
        FaultKind::StopDaemon,
        FaultKind::Hog,
        FaultKind::Rogue,
        FaultKind::Burst,
    ];

    pub fn label(self) -> &'static str {
        match self {
            FaultKind::KillPlant => "kill -9 plant, restart",
            FaultKind::KillDaemon => "kill -9 daemon, restart",
            FaultKind::StopPlant => "SIGSTOP/SIGCONT plant",
            FaultKind::StopDaemon => "SIGSTOP/SIGCONT daemon",
            FaultKind::Hog => "CPU hog on the loop's core",
            FaultKind::Rogue => "rogue publisher of garbage states",
            FaultKind::Burst => "burst of control requests",
        }
    }

    /// How long the fault lasts (the pause before a restart or SIGCONT, the hog's or the
    /// rogue's run), or for a burst, the number of requests.
    fn draw(self, rng: &mut Rng) -> Duration {
        match self {
            FaultKind::KillPlant | FaultKind::KillDaemon => rng.secs(0.2, 1.5),
            FaultKind::StopPlant | FaultKind::StopDaemon => rng.secs(0.1, 1.0),
            FaultKind::Hog => rng.secs(0.1, 0.5),
            FaultKind::Rogue => rng.secs(0.5, 2.0),
            FaultKind::Burst => Duration::ZERO,
        }
    }

    /// A generous guess of the time an episode takes beyond its duration (the restart,
    /// recovery and checks), used only to fit the plan into the run.
    fn overhead(self) -> Duration {
        Duration::from_secs_f64(match self {
            FaultKind::KillDaemon | FaultKind::Rogue => 2.5,
            FaultKind::KillPlant => 1.5,
            _ => 1.0,
        })
    }
}

#[derive(Clone, Debug)]
pub struct Options {
    pub seconds: f64,
    pub seed: u64,
    /// Fault kinds to inject (all when empty).
    pub faults: Vec<FaultKind>,
}

impl Options {
    pub fn validate(&self) -> Result<()> {
        if !(self.seconds.is_finite() && (5.0..=86_400.0).contains(&self.seconds)) {
            bail!(
                "soak --seconds {}: must be between 5 and 86400",
                self.seconds
            );
        }
        Ok(())
    }
}

/// One planned fault.
#[derive(Clone, Debug, PartialEq)]
pub struct Fault {
    /// Planned start, from the start of the fault phase.
    pub at: Duration,
    pub kind: FaultKind,
    /// See [`FaultKind::draw`].
    pub duration: Duration,
    /// Burst size (requests), 0 for other kinds.
    pub requests: usize,
    /// A seed for the fault's own choices (garbage kinds, set values).
    pub seed: u64,
}

/// The quiet time after the last fault, so the last recovery is seen and the daemon's
/// dead-node sweep has run before the clean stop.
pub const TAIL: Duration = Duration::from_secs(3);

/// The plan for a fault phase of `length`, with the kinds in `kinds` (all when empty).
pub fn plan(seed: u64, length: Duration, kinds: &[FaultKind]) -> Vec<Fault> {
    let kinds: Vec<FaultKind> = if kinds.is_empty() {
        FaultKind::ALL.to_vec()
    } else {
        let mut k = kinds.to_vec();
        k.sort();
        k.dedup();
        k
    };
    let mut rng = Rng::new(seed);
    let mut out = Vec::new();
    let mut deck: Vec<FaultKind> = Vec::new();
    let end = length.saturating_sub(TAIL);
    // A first quiet gap lets the system settle before the first fault.
    let mut t = rng.secs(1.0, 2.0);
    loop {
        if deck.is_empty() {
            deck = kinds.clone();
            // Fisher-Yates.
            for i in (1..deck.len()).rev() {
                let j = rng.below(i + 1);
                deck.swap(i, j);
            }
        }
        let kind = deck.pop().expect("refilled above");
        let duration = kind.draw(&mut rng);
        let requests = if kind == FaultKind::Burst {
            50 + rng.below(251)
        } else {
            0
        };
        let seed = rng.next_u64();
        if t + duration + kind.overhead() > end {
            break;
        }
        out.push(Fault {
            at: t,
            kind,
            duration,
            requests,
            seed,
        });
        t += duration + kind.overhead() + rng.secs(0.5, 3.0);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plan_is_a_function_of_the_seed() {
        let a = plan(1, Duration::from_secs(120), &[]);
        let b = plan(1, Duration::from_secs(120), &[]);
        let c = plan(2, Duration::from_secs(120), &[]);
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert!(!a.is_empty());
    }

    #[test]
    fn long_runs_have_every_kind_in_time_order_and_inside_the_run() {
        for seed in 0..50 {
            let len = Duration::from_secs(60);
            let p = plan(seed, len, &[]);
            for k in FaultKind::ALL {
                assert!(
                    p.iter().any(|f| f.kind == k),
                    "seed {seed}: no {k:?} in {p:#?}"
                );
            }
            assert!(p.windows(2).all(|w| w[1].at > w[0].at + w[0].duration));
            let last = p.last().unwrap();
            assert!(last.at + last.duration + last.kind.overhead() <= len - TAIL);
            for f in &p {
                assert_eq!(f.requests > 0, f.kind == FaultKind::Burst, "{f:?}");
                assert!(f.kind == FaultKind::Burst || f.duration >= Duration::from_millis(100));
            }
        }
    }

    #[test]
    fn kinds_can_be_chosen_and_short_runs_stay_short() {
        let p = plan(
            7,
            Duration::from_secs(60),
            &[FaultKind::Hog, FaultKind::Hog],
        );
        assert!(p.len() > 5 && p.iter().all(|f| f.kind == FaultKind::Hog));
        assert!(plan(7, Duration::from_secs(3), &[]).is_empty());
        let short = plan(3, Duration::from_secs(12), &[]);
        assert!(!short.is_empty() && short.len() < 5, "{short:#?}");
    }

    #[test]
    fn the_rng_is_uniform_enough() {
        let mut r = Rng::new(42);
        let mut counts = [0usize; 4];
        for _ in 0..40_000 {
            counts[r.below(4)] += 1;
        }
        assert!(
            counts.iter().all(|&c| (9_000..11_000).contains(&c)),
            "{counts:?}"
        );
        let u: f64 = (0..10_000).map(|_| r.unit()).sum::<f64>() / 10_000.0;
        assert!((u - 0.5).abs() < 0.02);
    }
}
