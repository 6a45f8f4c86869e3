//! A thread of its own for work that allocates and takes milliseconds to seconds: planning a
//! cycle ([`crate::planner`]) and choosing the gain from the model ([`crate::gains`]).
//!
//! Neither the loop nor the reporter (which answers `chaosctl` and drains tick records every
//! millisecond) may do such work. The thread runs off the loop's core and takes jobs, always the
//! newest one (an edit supersedes the job under way for the one before), and hands back what it
//! found; the reporter turns that into a `Copy` handover for the loop.

use crossbeam::channel::{unbounded, Receiver, RecvTimeoutError, Sender};
use std::thread::JoinHandle;
use std::time::Duration;

/// The thread and its two channels. Dropping it ends the thread (after the job under way).
pub struct Worker<J: Send + 'static, D: Send + 'static> {
    tx: Option<Sender<J>>,
    rx: Receiver<D>,
    handle: Option<JoinHandle<()>>,
}

impl<J: Send + 'static, D: Send + 'static> Worker<J, D> {
    /// Starts the thread `name`, kept off `loop_core`, answering each job with `work`.
    pub fn spawn(
        name: &str,
        loop_core: Option<usize>,
        work: impl Fn(J) -> D + Send + 'static,
    ) -> std::io::Result<Self> {
        let (tx, jobs) = unbounded::<J>();
        let (done_tx, rx) = unbounded::<D>();
        let handle = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                rt::setup::avoid_core(loop_core);
                serve(&jobs, &done_tx, work);
            })?;
        Ok(Self {
            tx: Some(tx),
            rx,
            handle: Some(handle),
        })
    }

    /// Queues a job (never blocks).
    pub fn submit(&self, job: J) {
        if let Some(tx) = &self.tx {
            let _ = tx.send(job);
        }
    }

    /// A finished job, if one is ready (never blocks).
    pub fn try_done(&self) -> Option<D> {
        self.rx.try_recv().ok()
    }
}

impl<J: Send + 'static, D: Send + 'static> Drop for Worker<J, D> {
    fn drop(&mut self) {
        self.tx = None; // the thread sees the channel close and returns
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// Works on the newest job of each batch until the job channel closes.
fn serve<J, D>(jobs: &Receiver<J>, done: &Sender<D>, work: impl Fn(J) -> D) {
    loop {
        let mut job = match jobs.recv_timeout(Duration::from_millis(100)) {
            Ok(j) => j,
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => return,
        };
        while let Ok(newer) = jobs.try_recv() {
            job = newer;
        }
        if done.send(work(job)).is_err() {
            return;
        }
    }
}
