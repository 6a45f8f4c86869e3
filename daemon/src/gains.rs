//! `mu = "auto"`: the daemon chooses its Pyragas gain from its own model ([`control::tune`]).
//!
//! At start and after every committed edit, a thread of its own ([`crate::worker`], off the
//! loop's core) finds the cycle the set-up settles on and the gain that makes it converge
//! fastest; the reporter hands that gain to the loop as a parameter block (the loop only ever
//! does a `try_recv`, so nothing waits on a lock), with the speed-gradient law anchored on it
//! ([`control::adapt::AutoMu::anchor`]): the plant then corrects from the measured residual,
//! above the model's gain while the motion is not periodic and back to it once it is. The
//! model's answer is a starting point, not a verdict: the monitor still judges the arm.
//!
//! The search is seeded with the arm's own state at the newest whole period of controller
//! time (the task's phase 0), so after an edit it looks for the cycle near where the arm is.
//!
//! The same thread makes the steering onto the chosen cycle ([`control::target`]): the reporter
//! hands it to the loop with the gain, through the deadlock watch that owns the loop's
//! steering ([`crate::deadlock::Deadlock::target`]), and takes it away once the arm is on the
//! cycle, so the feedback holds an arm it did not have to wait for.

use crate::telemetry::TickRecord;
use crate::worker::Worker;
use control::target::{target, target_wanted, Target, TargetError};
use control::tune::{choose_gain, GainChoice, TuneError, TuneSpec, RETRY_PERIODS};
use control::System;
use std::time::Duration;

/// Why a choice was asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Why {
    Start,
    Edit,
    /// The search before found no cycle to stabilise; tried again from where the arm is now
    /// ([`control::tune::RETRY_PERIODS`]).
    Retry,
}

/// One search: the running set-up, seeded with (q, q̇) at a whole period when there is one.
pub struct Job {
    pub generation: u64,
    pub why: Why,
    pub system: System,
    pub seed: Option<Vec<f64>>,
    /// Retries before this one since the start or the edit.
    pub tries: u32,
}

/// A finished search.
pub struct Done {
    pub generation: u64,
    pub why: Why,
    pub tries: u32,
    pub result: Result<GainChoice, TuneError>,
    /// The steering onto the chosen cycle, where the set-up wants one
    /// ([`control::target::target_wanted`]).
    pub target: Option<Result<Target, TargetError>>,
    pub took: Duration,
}

/// The gain in use, and how it was found.
#[derive(Clone, Debug)]
pub struct Chosen {
    pub choice: GainChoice,
    pub why: Why,
    pub took: Duration,
    /// Controller time at which it was handed to the loop (s); NaN while it waits.
    pub t: f64,
    /// The steering onto the chosen cycle, or why there is none (None: not wanted).
    pub target: Option<Result<Target, String>>,
}

/// The search's thread (started on the first job), its newest answer and the arm's newest
/// return at the task's phase 0.
pub struct GainTuning {
    worker: Option<Worker<Job, Done>>,
    loop_core: Option<usize>,
    generation: u64,
    /// A search is under way for the current generation.
    pub searching: Option<Why>,
    /// An answer not yet handed over (the loop had not taken the previous block).
    pub waiting: Option<Chosen>,
    pub chosen: Option<Chosen>,
    pub error: Option<String>,
    /// (period index, q and q̇) of the newest state at or just after a whole period.
    phase_zero: Option<(i64, Vec<f64>)>,
    /// The set-up searched for, and when to search it again (period index, retries so far)
    /// after a search that found no cycle to stabilise.
    system: Option<System>,
    retry: Option<(i64, u32)>,
}

impl GainTuning {
    pub fn new(loop_core: Option<usize>) -> Self {
        Self {
            worker: None,
            loop_core,
            generation: 0,
            searching: None,
            waiting: None,
            chosen: None,
            error: None,
            phase_zero: None,
            system: None,
            retry: None,
        }
    }

    /// The set-up changed (or the daemon started): a search for it when μ is "auto"; any
    /// answer under way is for another set-up and will be dropped.
    pub fn edited(&mut self, system: &System, why: Why) {
        self.generation += 1;
        self.waiting = None;
        self.searching = None;
        self.retry = None;
        self.system = None;
        // The steering onto the old set-up's cycle is no way back for the new one.
        if let Some(c) = self.chosen.as_mut() {
            c.target = None;
        }
        if system.feedback().auto.is_none() {
            self.chosen = None;
            self.error = None;
            return;
        }
        self.system = Some(system.clone());
        self.submit(why, 0);
    }

    /// Hands the search's thread the set-up (started on the first job), seeded with the
    /// arm's newest state at a whole period.
    fn submit(&mut self, why: Why, tries: u32) {
        let Some(system) = self.system.clone() else {
            return;
        };
        if self.worker.is_none() {
            match Worker::spawn("chaosd-tune", self.loop_core, search) {
                Ok(w) => self.worker = Some(w),
                Err(e) => {
                    self.error = Some(format!("cannot start the gain search's thread: {e}"));
                    return;
                }
            }
        }
        let seed = self.phase_zero.as_ref().map(|(_, x)| x.clone());
        if let Some(w) = &self.worker {
            w.submit(Job {
                generation: self.generation,
                why,
                system,
                seed,
                tries,
            });
            self.searching = Some(why);
        }
    }

    /// Keeps the newest state the law ran on at the task's phase 0 (a whole period of
    /// controller time), the search's seed.
    pub fn observe(&mut self, r: &TickRecord, period: f64, n: usize) {
        let Some(s) = r.state.as_ref().filter(|_| r.ran_law && period > 0.0) else {
            return;
        };
        let k = (r.t / period).floor() as i64;
        if self.phase_zero.as_ref().is_some_and(|(at, _)| *at == k) {
            return;
        }
        let x: Vec<f64> = s.q[..n].iter().chain(&s.qd[..n]).copied().collect();
        self.phase_zero = Some((k, x));
        let due = self
            .retry
            .filter(|(at, _)| k >= *at && self.searching.is_none());
        if let Some((_, tries)) = due {
            self.retry = None;
            self.submit(Why::Retry, tries);
        }
    }

    /// A choice for the current set-up to hand to the loop, if one is ready (never blocks).
    /// Failures are kept for `status` and said once in the log.
    pub fn poll(&mut self) -> Option<Chosen> {
        while let Some(done) = self.worker.as_ref().and_then(Worker::try_done) {
            if done.generation != self.generation {
                continue;
            }
            self.searching = None;
            match done.result {
                Ok(choice) => {
                    self.error = None;
                    let target = done.target.map(|t| t.map_err(|e| e.to_string()));
                    if let Some(Err(e)) = &target {
                        tracing::warn!(
                            "mu = \"auto\": no steering onto the model's cycle ({e}); the \
                             feedback catches the arm alone"
                        );
                    }
                    self.waiting = Some(Chosen {
                        choice,
                        why: done.why,
                        took: done.took,
                        t: f64::NAN,
                        target,
                    });
                }
                Err(e) => {
                    let now = self.phase_zero.as_ref().map_or(0, |(k, _)| *k);
                    let again = e.retry(now, done.tries);
                    tracing::warn!(
                        "mu = \"auto\": no gain from the model ({e}); the speed-gradient law \
                         adapts μ alone{}",
                        if again.is_some() {
                            format!(
                                "; searching again from the arm's state in {RETRY_PERIODS} periods"
                            )
                        } else {
                            String::new()
                        }
                    );
                    self.retry = again;
                    self.error = Some(e.to_string());
                }
            }
        }
        self.waiting.clone()
    }

    /// The loop took the chosen gain at controller time `t`.
    pub fn handed_over(&mut self, t: f64) {
        if let Some(mut c) = self.waiting.take() {
            c.t = t;
            tracing::info!(
                "mu = \"auto\": the gain from the model, {} (searched in {:.1} s)",
                c.choice.why(),
                c.took.as_secs_f64()
            );
            self.chosen = Some(c);
        }
    }

    /// The model's gain for telemetry (NaN until there is one).
    pub fn mu_model(&self) -> f64 {
        self.chosen.as_ref().map_or(f64::NAN, |c| c.choice.mu)
    }

    /// `status`'s `gains` object: what was chosen, why, and every gain tried.
    pub fn to_json(&self) -> serde_json::Value {
        let chosen = self.chosen.as_ref().map(|c| {
            serde_json::json!({
                "mu": c.choice.mu,
                "multiplier": c.choice.multiplier,
                "rate_per_second": c.choice.rate,
                "period": c.choice.period,
                "gamma": c.choice.gamma,
                "cycle_speed": c.choice.speed,
                "why": c.choice.why(),
                "asked_at": c.why,
                "adopted_at_t": c.t,
                "took_s": c.took.as_secs_f64(),
                "seed": c.choice.seed,
                "target_error": c.target.as_ref().and_then(|t| t.as_ref().err()),
                "target_miss": c.target.as_ref().and_then(|t| t.as_ref().ok()).map(|t| t.miss),
                "cycle": {"q": c.choice.orbit.q, "qd": c.choice.orbit.qd,
                          "residual": c.choice.orbit.residual},
                "scanned": c.choice.scanned,
            })
        });
        serde_json::json!({
            "searching": self.searching,
            "chosen": chosen,
            "error": self.error,
        })
    }
}

fn search(job: Job) -> Done {
    let started = std::time::Instant::now();
    let spec = TuneSpec::of(&job.system);
    let result = choose_gain(&job.system, job.seed.as_deref(), &spec);
    let target = match &result {
        Ok(c) if target_wanted(&job.system) => Some(target(&job.system, &c.orbit)),
        _ => None,
    };
    Done {
        generation: job.generation,
        why: job.why,
        tries: job.tries,
        result,
        target,
        took: started.elapsed(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wait(g: &mut GainTuning) -> Chosen {
        for _ in 0..2000 {
            if let Some(c) = g.poll() {
                return c;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        panic!("no answer in 10 s: {:?}", g.error);
    }

    #[test]
    fn the_search_runs_off_the_caller_and_an_edit_drops_the_answer_under_way() {
        let mut system = System::preset("paper", &control::system::builtin_robot).unwrap();
        let mut g = GainTuning::new(None);
        g.edited(&system, Why::Start); // a fixed gain: nothing to search
        assert!(g.searching.is_none() && g.worker.is_none());
        system.schedule_feedback(control::adapt::MuSetting::Auto, 0.0);
        g.edited(&system, Why::Start);
        g.edited(&system, Why::Edit); // supersedes the first
        let c = wait(&mut g);
        assert_eq!(c.why, Why::Edit);
        assert!(c.choice.multiplier < 1.0, "{}", c.choice.why());
        g.handed_over(3.0);
        assert_eq!(g.mu_model(), c.choice.mu);
        assert_eq!(g.to_json()["chosen"]["adopted_at_t"], 3.0);
        let s = system.with_model_gain(c.choice.mu, c.choice.gamma).unwrap();
        let auto = s.feedback().auto.unwrap();
        assert_eq!(
            (s.feedback().mu, auto.anchor),
            (c.choice.mu, Some(c.choice.mu))
        );
        // Back to a fixed gain: no model gain, and no search.
        let fixed = System::preset("paper", &control::system::builtin_robot).unwrap();
        g.edited(&fixed, Why::Edit);
        assert!(g.mu_model().is_nan() && g.searching.is_none());
        assert!(fixed.with_model_gain(0.1, 1e-3).is_none());
    }
}
