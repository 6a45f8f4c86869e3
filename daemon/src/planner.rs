//! The cycle planner's own thread.
//!
//! Planning a clean cycle takes milliseconds and allocates, so neither the loop nor the
//! reporter (which answers `chaosctl` and drains tick records every millisecond) may do it.
//! This thread, off the loop's core, takes jobs, always the newest one (an edit supersedes the
//! plan under way for the one before), and hands back what it found. The reporter turns that
//! into a `Copy` handover for the loop ([`crate::deadlock`]).

use control::plan::{plan_arm, Planned};
use control::System;
use crossbeam::channel::{unbounded, Receiver, RecvTimeoutError, Sender};
use std::thread::JoinHandle;
use std::time::Duration;

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

/// The planner thread and its two channels. Dropping it ends the thread.
pub struct Planner {
    tx: Option<Sender<Job>>,
    rx: Receiver<Done>,
    handle: Option<JoinHandle<()>>,
}

impl Planner {
    /// Starts the thread, kept off `loop_core`.
    pub fn spawn(loop_core: Option<usize>) -> std::io::Result<Self> {
        let (tx, jobs) = unbounded::<Job>();
        let (done_tx, rx) = unbounded::<Done>();
        let handle = std::thread::Builder::new()
            .name("chaosd-plan".into())
            .spawn(move || {
                rt::setup::avoid_core(loop_core);
                serve(&jobs, &done_tx);
            })?;
        Ok(Self {
            tx: Some(tx),
            rx,
            handle: Some(handle),
        })
    }

    /// Queues a job (never blocks).
    pub fn submit(&self, job: Job) {
        if let Some(tx) = &self.tx {
            let _ = tx.send(job);
        }
    }

    /// A finished job, if one is ready (never blocks).
    pub fn try_done(&self) -> Option<Done> {
        self.rx.try_recv().ok()
    }
}

impl Drop for Planner {
    fn drop(&mut self) {
        self.tx = None; // the thread sees the channel close and returns
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// Plans the newest job of each batch until the job channel closes.
fn serve(jobs: &Receiver<Job>, done: &Sender<Done>) {
    loop {
        let mut job = match jobs.recv_timeout(Duration::from_millis(100)) {
            Ok(j) => j,
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => return,
        };
        while let Ok(newer) = jobs.try_recv() {
            job = newer;
        }
        let started = std::time::Instant::now();
        let result = job.plan();
        let answer = Done {
            generation: job.generation,
            why: job.why,
            result,
            took: started.elapsed(),
        };
        if done.send(answer).is_err() {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::plan::PlanOutcome;

    fn job(generation: u64, obstacles: &[(f64, f64, f64)]) -> Job {
        let mut config = control::Config::preset("demo").unwrap();
        for &(x, y, r) in obstacles {
            config
                .control
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
        let p = Planner::spawn(None).unwrap();
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
