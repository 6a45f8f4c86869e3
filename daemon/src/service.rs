//! The fixed-rate control loop on iceoryx2.
//!
//! Thread layout: the calling thread becomes the real-time loop (pinned, SCHED_FIFO when
//! permitted). A reporter thread turns tick records into histograms and status lines, and a
//! housekeeping thread sweeps dead iceoryx2 nodes (a SIGKILLed plant's ports) every
//! `cleanup_every_s`. Both are spawned before the loop thread raises its own priority, so they
//! stay ordinary threads, and both move off the loop's core (`rt::setup::avoid_core`), so that
//! without SCHED_FIFO they never compete with the loop for its CPU.
//!
//! The loop is: wait for the absolute deadline → one tick ([`crate::tick::ClockTick::run`]: drain
//! the state subscriber, keeping the newest → `Controller::tick` → loan, write, send the command →
//! `try_send` a record) → advance the schedule. No locks, no waiting on other threads; the only
//! system calls are the clock, the sleep and iceoryx2's.

use crate::config::DaemonSetup;
use crate::controller::{Controller, ControllerSettings};
use crate::ipc::node;
use crate::reporter::Reporter;
use crate::telemetry::{DaemonSummary, LoopRequest, TickRecord};
use anyhow::{anyhow, Context, Result};
use control::with_dof;
use iceoryx2::prelude::ipc;
use protocol::{monotonic_ns, ServiceNames};
use rt::clock::Schedule;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

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
    let settings = setup.controller_settings(protocol::new_instance_id());
    let start_in_fault = setup.live.as_ref().is_some_and(|l| l.fault.is_some());
    let replay = match &setup.record {
        Some(name) => Some(
            crate::replay::ReplayLog::create(
                &d.output_dir,
                name,
                &setup.system,
                &settings,
                start_in_fault,
                true, // the loop requires the handshake (below)
            )
            .map_err(|e| anyhow!("--record: {e}"))?
            .with_max_bytes(d.record_max_bytes),
        ),
        None => None,
    };
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
        .resuming(setup.live.as_ref(), setup.file_fingerprint.clone())
        .recording_replay(replay)
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

    // READY and watchdog pings for systemd, from an ordinary thread (see `watchdog`).
    let notifier = crate::watchdog::spawn(loop_core, running.clone())?;

    let result = control_loop::<N>(setup, settings, &names, duration, tx, params_rx, rt_tx);
    running.store(false, Ordering::Relaxed);
    let _ = hk.join();
    if let Some(h) = notifier {
        let _ = h.join();
    }
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
    settings: ControllerSettings,
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

    let generator = setup.system.generator::<N>(1.0 / d.rate_hz)?;
    let mut ctl = Controller::<N>::new(
        setup.system.tick_law::<N>(),
        setup.system.feedback().max_tau,
        settings,
    )
    .with_generator(generator);
    ctl.require_handshake();
    if setup.live.as_ref().is_some_and(|l| l.fault.is_some()) {
        ctl.enter_fault(crate::guard::FaultReason::Restored);
    }

    let mut rt_report = rt::setup::apply(rt::setup::RtRequest {
        core: d.core,
        priority: d.priority,
        lock_memory: d.lock_memory,
    });
    let lane = if d.trigger == rt::Trigger::State && d.fast_lane {
        protocol::board::DaemonLane::daemon(&node, names)
            .map_err(|e| {
                rt_report
                    .warnings
                    .push(format!("fast lane off, pub-sub only: {e}"))
            })
            .ok()
    } else {
        None
    };
    let period = d.period_ns();
    let spin = (d.spin_us * 1000.0) as u64;
    let fifo = rt_report.sched_fifo.is_some();
    let limit = rt::throttle::RtLimit::read();
    rt_report
        .warnings
        .extend(rt::throttle::warning(limit, fifo, d.wait, spin, period));
    let _ = rt_tx.try_send(rt_report.clone());
    // Said by the reporter thread (`log_started`): the loop thread writes no logs.

    let start = monotonic_ns();
    let end = duration.map(|s| start.saturating_add((s * 1e9) as u64));
    if d.trigger == rt::Trigger::State {
        let lane = lane.as_ref();
        let ports = crate::trigger::Ports {
            subscriber: &subscriber,
            publisher: &publisher,
            tx: &tx,
            lane,
        };
        let timing = crate::trigger::Timing {
            period_ns: period,
            wait: d.wait,
            spin_ns: spin,
            end_ns: end,
        };
        // What the control service sent, taken between ticks (as in the clock loop below).
        let between = |ctl: &mut Controller<N>| crate::tick::take_request(ctl, &params_rx);
        crate::trigger::state_loop(&mut ctl, &ports, timing, between);
        leave_braking(&mut ctl, &publisher, lane);
        return Ok((rt_report, ctl.counters));
    }
    let phase = d
        .phase_offset_us
        .map(|us| crate::trigger::PhaseLock::new(period, (us * 1e3) as u64));
    let mut sched = Schedule::new(period, start);
    let tick = crate::tick::ClockTick {
        subscriber: &subscriber,
        publisher: &publisher,
        tx: &tx,
        requests: &params_rx,
    };
    // The newest answered state: what the wait rehearses the tick on.
    let mut last: Option<protocol::StateSample> = None;
    while !rt::signal::stop_requested() {
        let deadline = sched.deadline();
        if end.is_some_and(|e| deadline >= e) {
            break;
        }
        // The hybrid wait rehearses the tick on the previous state before it spins, so the
        // tick itself runs warm (see `Controller::rehearse`).
        let woke = rt::wait_until_warm(deadline, d.wait, spin, || {
            if let Some(s) = &last {
                ctl.rehearse(s);
            }
        });
        let t = tick.run(&mut ctl, deadline, woke);
        ctl.counters.overruns += sched.advance(t.done);
        if t.answered.is_some() {
            last = t.answered;
        }
        if let (Some(lock), Some(s)) = (phase, t.answered) {
            sched.set_deadline(lock.align(sched.deadline(), s.stamp_ns));
        }
    }
    leave_braking(&mut ctl, &publisher, None);
    Ok((rt_report, ctl.counters))
}

/// Leaves the plant braking, not coasting on the last acceleration. With the fast lane open the
/// brake goes on it too: a plant that takes its answers from the lane looks at pub-sub only now
/// and then, and through the UDP bridge the brake then reached the device after the device had
/// braked on its own for the missed answers (every bridge demo ended with a device brake).
fn leave_braking<const N: usize>(
    ctl: &mut Controller<N>,
    publisher: &iceoryx2::port::publisher::Publisher<ipc::Service, protocol::CommandSample, ()>,
    lane: Option<&protocol::board::DaemonLane>,
) {
    let brake = ctl.brake_command(monotonic_ns());
    if let Some(lane) = lane {
        lane.write(&brake);
    }
    if let Ok(s) = publisher.loan_uninit() {
        let _ = s.write_payload(brake).send();
    }
}
