//! The cycle planner's jobs, on a thread of their own ([`crate::worker`]): planning a clean
//! cycle takes milliseconds and allocates. The reporter turns a finished plan into a `Copy`
//! handover for the loop ([`crate::deadlock`]).

use crate::worker::Worker;
use control::plan::{plan_arm, Planned};
use control::System;

/// Why a plan was asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Why {
    /// The daemon started.
    Start,
    /// An obstacle or task edit (any committed change).
    Edit,
    /// The arm was trapped: plan from where it is now.
    Trap,
}

/// One planning job: the running set-up (planar or spatial), from task time `t0` near posture
/// `q_now` (joint values).
#[derive(Clone, Debug)]
pub struct Job {
    /// Which edit of the configuration this plan is for: a stale answer is dropped.
    pub generation: u64,
    pub why: Why,
    pub system: System,
    pub t0: f64,
    pub q_now: Option<Vec<f64>>,
    /// The cycle the loop steers along now, if any: a spatial plan starts from it.
    pub following: Option<control::steer::Steering>,
}

impl Job {
    /// The plan for this job, by the arm's own planner.
    fn plan(&self) -> Result<Planned, control::plan::PlanError> {
        plan_arm(
            &self.system,
            self.t0,
            self.q_now.as_deref(),
            self.following.as_ref(),
        )
    }
}

/// A finished job.
#[derive(Clone, Debug)]
pub struct Done {
    pub generation: u64,
    pub why: Why,
    pub result: Result<Planned, control::plan::PlanError>,
    /// How long the planner took (the planner thread's clock: `control` reads none).
    pub took: std::time::Duration,
}

/// The planner thread ([`crate::worker`]): jobs in, [`Done`] out.
pub type Planner = Worker<Job, Done>;

/// Starts the planner's thread, kept off `loop_core`.
pub fn spawn(loop_core: Option<usize>) -> std::io::Result<Planner> {
    Worker::spawn("chaosd-plan", loop_core, |job: Job| {
        let started = std::time::Instant::now();
        let result = job.plan();
        Done {
            generation: job.generation,
            why: job.why,
            result,
            took: started.elapsed(),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::plan::PlanOutcome;
    use std::time::Duration;

    fn job(generation: u64, obstacles: &[(f64, f64, f64)]) -> Job {
        let mut config = control::Config::preset("demo").unwrap();
        for &(x, y, r) in obstacles {
            config
                .planar_mut()
                .unwrap()
                .obstacles
                .push(control::config::ObstacleConfig::disc(x, y, r));
        }
        Job {
            generation,
            why: Why::Edit,
            system: System::Planar(config),
            t0: 0.0,
            q_now: None,
            following: None,
        }
    }

    fn wait(p: &Planner) -> Done {
        for _ in 0..2000 {
            if let Some(d) = p.try_done() {
                return d;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        panic!("the planner did not answer in 10 s");
    }

    #[test]
    fn the_thread_plans_off_the_caller_and_ends_when_dropped() {
        let p = spawn(None).unwrap();
        p.submit(job(1, &[]));
        let d = wait(&p);
        assert_eq!(d.generation, 1);
        assert!(matches!(d.result.unwrap().outcome, PlanOutcome::Found(_)));
        // A disc over the circle's right-hand point: the hand must pass through it.
        p.submit(job(2, &[(1.5, 2.0, 0.2)]));
        let d = wait(&p);
        assert_eq!(d.generation, 2);
        assert!(matches!(d.result.unwrap().outcome, PlanOutcome::Blocked(_)));
        drop(p); // joins the thread: a hang here fails the test by timeout
    }
}
