//! The fixed-rate control loop on iceoryx2.
//!
//! Thread layout: the calling thread becomes the real-time loop (pinned, SCHED_FIFO when
//! permitted). A reporter thread turns tick records into histograms and status lines, and a
//! housekeeping thread sweeps dead iceoryx2 nodes (a SIGKILLed plant's ports) every
//! `cleanup_every_s`. Both are spawned before the loop thread raises its own priority, so they
//! stay ordinary threads, and both move off the loop's core (`rt::setup::avoid_core`), so that
//! without SCHED_FIFO they never compete with the loop for its CPU.
//!
//! The tick is: wait for the absolute deadline → drain the state subscriber, keeping the newest →
//! `Controller::tick` → loan, write, send the command → `try_send` a record. No locks, no waiting
//! on other threads; the only system calls are the clock, the sleep and iceoryx2's.

use crate::config::DaemonSetup;
use crate::controller::{Controller, ControllerSettings};
use crate::telemetry::{DaemonSummary, LoopRequest, Reporter, TickRecord};
use anyhow::{anyhow, Context, Result};
use control::with_dof;
use iceoryx2::prelude::ipc;
use protocol::{monotonic_ns, ServiceNames};
use rt::clock::Schedule;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Creates this process's iceoryx2 node (see `protocol::node`).
pub fn node(name: &str) -> Result<iceoryx2::node::Node<ipc::Service>> {
    Ok(protocol::node(name)?)
}

/// Runs the daemon until SIGINT/SIGTERM, or for `duration` seconds. `on_line` gets status lines.
pub fn run(
    setup: &DaemonSetup,
    duration: Option<f64>,
    on_line: impl FnMut(&str) + Send + 'static,
) -> Result<DaemonSummary> {
    with_dof!(setup.system.n(), N => run_n::<N>(setup, duration, on_line))
}

fn run_n<const N: usize>(
    setup: &DaemonSetup,
    duration: Option<f64>,
    on_line: impl FnMut(&str) + Send + 'static,
) -> Result<DaemonSummary> {
    let d = setup.daemon.clone();
    rt::files::create_dir_all(&d.output_dir)
        .with_context(|| format!("cannot create output directory {}", d.output_dir.display()))?;
    let names = ServiceNames::new(&d.namespace).map_err(|e| anyhow!("daemon.namespace: {e}"))?;
    rt::signal::install();

    // Ordinary threads first.
    let (tx, rx) = crossbeam::channel::bounded::<TickRecord>(d.telemetry_queue);
    let (params_tx, params_rx) = crossbeam::channel::bounded::<LoopRequest>(16);
    let (rt_tx, rt_rx) = crossbeam::channel::bounded::<rt::setup::RtReport>(1);
    let running = Arc::new(AtomicBool::new(true));
    // The handshake: which plant the loop may control (see `handshake`).
    let (handshake, refusal) = crate::handshake::spawn(
        &setup.system,
        &names,
        params_tx.clone(),
        running.clone(),
        d.core,
    )?;
    let reporter = Reporter::new(setup.system.clone(), d.clone(), params_tx, rt_rx)?
        .resuming(setup.live.as_ref())
        .with_handshake(refusal);
    // Helper threads stay off the loop's core (it is pinned there below).
    let loop_core = d.core;
    let reporter = std::thread::Builder::new()
        .name("chaosd-report".into())
        .spawn(move || {
            rt::setup::avoid_core(loop_core);
            reporter.run(rx, on_line)
        })?;
    let hk = {
        let running = running.clone();
        let every = Duration::from_secs_f64(d.cleanup_every_s);
        std::thread::Builder::new()
            .name("chaosd-cleanup".into())
            .spawn(move || {
                rt::setup::avoid_core(loop_core);
                let Ok(node) = node("chaosd-cleanup") else {
                    return;
                };
                let mut slept = Duration::ZERO;
                while running.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(50));
                    slept += Duration::from_millis(50);
                    if slept >= every {
                        slept = Duration::ZERO;
                        let _ = node.try_cleanup_dead_nodes();
                    }
                }
            })?
    };

    let result = control_loop::<N>(setup, &names, duration, tx, params_rx, rt_tx);
    running.store(false, Ordering::Relaxed);
    let _ = hk.join();
    let _ = handshake.join();
    let summary = reporter
        .join()
        .map_err(|_| anyhow!("the reporter thread panicked"))?;
    let (realtime, counters) = result?;
    let mut summary = summary?;
    summary.realtime = realtime;
    // The loop's own final counters: the reporter may have missed the last records.
    summary.counters = counters;
    crate::telemetry::write_summary(&summary, &d.output_dir)?;
    Ok(summary)
}

fn control_loop<const N: usize>(
    setup: &DaemonSetup,
    names: &ServiceNames,
    duration: Option<f64>,
    tx: crossbeam::channel::Sender<TickRecord>,
    params_rx: crossbeam::channel::Receiver<LoopRequest>,
    rt_tx: crossbeam::channel::Sender<rt::setup::RtReport>,
) -> Result<(rt::setup::RtReport, crate::controller::Counters)> {
    let d = &setup.daemon;
    let node = node("chaosd-daemon")?;
    let state = protocol::open_state_service(&node, names)?;
    let subscriber = state
        .subscriber_builder()
        .create()
        .map_err(|e| anyhow!("cannot subscribe to {}: {e:?}", names.state()))?;
    let command = protocol::open_command_service(&node, names)?;
    let publisher = command.publisher_builder().create().map_err(|e| {
        anyhow!(
            "cannot publish on {}: {e:?} (is another chaosd already running in namespace {:?}?)",
            names.command(),
            names.namespace()
        )
    })?;
    // Only now that this daemon owns the namespace's ports: record what it runs with.
    rt::files::write(&d.output_dir.join("config.toml"), setup.to_toml())
        .context("cannot write the effective config")?;

    let settings = ControllerSettings {
        rate_hz: d.rate_hz,
        first_order_hold: d.hold == crate::config::Hold::FirstOrder,
        hold_after: d.hold_after,
        stale_ns: (d.stale_ms * 1e6) as u64,
        future_slack_ns: d.period_ns(),
        daemon_id: protocol::new_instance_id(),
        t_start: setup.live.as_ref().map_or(0.0, |l| l.t),
    };
    let mut ctl = Controller::<N>::new(
        setup.system.model::<N>(),
        setup.system.law_params(),
        setup.system.feedback.max_tau,
        settings,
    );
    ctl.require_handshake();
    if setup.live.as_ref().is_some_and(|l| l.fault.is_some()) {
        ctl.enter_fault(crate::guard::FaultReason::Restored);
    }

    let rt_report = rt::setup::apply(rt::setup::RtRequest {
        core: d.core,
        priority: d.priority,
        lock_memory: d.lock_memory,
    });
    let _ = rt_tx.try_send(rt_report.clone());
    for w in &rt_report.warnings {
        eprintln!("chaosd: warning: {w}");
    }
    eprintln!(
        "chaosd: namespace {:?}, {} Hz, {} wait, {}",
        names.namespace(),
        d.rate_hz,
        d.wait.name(),
        rt_report.one_line()
    );

    let period = d.period_ns();
    let spin = (d.spin_us * 1000.0) as u64;
    let start = monotonic_ns();
    let end = duration.map(|s| start.saturating_add((s * 1e9) as u64));
    if d.trigger == rt::Trigger::State {
        let ports = crate::trigger::Ports {
            subscriber: &subscriber,
            publisher: &publisher,
            tx: &tx,
        };
        let timing = crate::trigger::Timing {
            period_ns: period,
            wait: d.wait,
            spin_ns: spin,
            end_ns: end,
        };
        // What the control service sent, taken between ticks (as in the clock loop below).
        let between = |ctl: &mut Controller<N>| take_request(ctl, &params_rx);
        crate::trigger::state_loop(&mut ctl, &ports, timing, between);
        leave_braking(&mut ctl, &publisher);
        return Ok((rt_report, ctl.counters));
    }
    let phase = d
        .phase_offset_us
        .map(|us| crate::trigger::PhaseLock::new(period, (us * 1e3) as u64));
    let mut sched = Schedule::new(period, start);
    while !rt::signal::stop_requested() {
        let deadline = sched.deadline();
        if end.is_some_and(|e| deadline >= e) {
            break;
        }
        let woke = rt::wait_until(deadline, d.wait, spin);
        // A validated parameter block (or a resume) from the control service takes effect here,
        // between ticks.
        take_request(&mut ctl, &params_rx);
        let mut newest = None;
        loop {
            match subscriber.receive() {
                Ok(Some(s)) => {
                    // Only the newest sample of a tick is used; older ones are superseded unread.
                    if newest.is_some() {
                        ctl.counters.superseded += 1;
                    }
                    newest = Some(*s);
                }
                Ok(None) => break,
                Err(_) => {
                    ctl.counters.ipc_errors += 1;
                    break;
                }
            }
        }
        let o = ctl.tick(newest.as_ref(), woke);
        if let Some(c) = o.command {
            match publisher.loan_uninit() {
                Ok(s) => {
                    if s.write_payload(c).send().is_err() {
                        ctl.counters.ipc_errors += 1;
                    }
                }
                Err(_) => ctl.counters.ipc_errors += 1,
            }
        }
        let done = monotonic_ns();
        ctl.counters.overruns += sched.advance(done);
        if let (Some(lock), Some(s), Some(_)) = (phase, newest, o.state_age_ns) {
            sched.set_deadline(lock.align(sched.deadline(), s.stamp_ns));
        }
        let times = crate::record::TickTimes {
            due: deadline,
            woke,
            done,
        };
        let rec = crate::record::tick_record(&ctl, &o, newest, times);
        match tx.try_send(rec) {
            Ok(()) => {}
            Err(crossbeam::channel::TrySendError::Full(_)) => ctl.counters.telemetry_dropped += 1,
            // The reporter is gone: no control service, no histograms. Stop cleanly.
            Err(crossbeam::channel::TrySendError::Disconnected(_)) => rt::signal::request_stop(),
        }
    }
    leave_braking(&mut ctl, &publisher);
    Ok((rt_report, ctl.counters))
}

/// Leaves the plant braking, not coasting on the last acceleration.
fn leave_braking<const N: usize>(
    ctl: &mut Controller<N>,
    publisher: &iceoryx2::port::publisher::Publisher<ipc::Service, protocol::CommandSample, ()>,
) {
    let brake = ctl.brake_command(monotonic_ns());
    if let Ok(s) = publisher.loan_uninit() {
        let _ = s.write_payload(brake).send();
    }
}

/// Applies at most one request from the control service (never blocks).
fn take_request<const N: usize>(
    ctl: &mut Controller<N>,
    rx: &crossbeam::channel::Receiver<LoopRequest>,
) {
    match rx.try_recv() {
        Ok(LoopRequest::Params(p)) => ctl.set_params(p),
        Ok(LoopRequest::Resume) => {
            ctl.resume();
        }
        Ok(LoopRequest::Plant { plant_id, agreed }) => ctl.set_plant_verdict(plant_id, agreed),
        Err(_) => {}
    }
}
