//! Proves the daemon's tick allocates nothing, with a counting global allocator armed per thread
//! (its own test binary, because a global allocator applies to the whole binary).
//!
//! Two claims, both exact:
//! 1. `Controller::tick` (validation, mode machine, delay line, control law, command) makes zero
//!    allocations, on fresh, missing, invalid, stale and restarted-plant inputs.
//! 2. The clock loop's own tick, `daemon::tick::ClockTick::run` (take a request, drain the
//!    subscriber, tick, loan → write → send, `try_send` the record), with the schedule's advance,
//!    on real iceoryx2 ports, makes exactly one allocation per published command: iceoryx2 0.10's
//!    `loan_uninit` creates an `Rc` for each sample (`SampleMutUninit::new`). `receive`, `send`
//!    and dropping samples make none. If a future iceoryx2 removes it, this test fails and the
//!    ARCHITECTURE.md's note can go.

use control::Config;
use daemon::controller::{Controller, ControllerSettings};
use protocol::{monotonic_ns, ServiceNames, StateSample};
use rt::alloc_count::{allocations, Counting};

#[global_allocator]
static GLOBAL: Counting = Counting;

fn controller(preset: &str) -> Controller<3> {
    let mut cfg = Config::preset(preset).unwrap();
    cfg.feedback.mu = 1.0;
    cfg.feedback.t_on = 0.5;
    Controller::new(cfg.tick_law::<3>(), 2.0, settings())
}

/// 1 kHz, first-order hold, HOLD after 10 missed ticks.
fn settings() -> ControllerSettings {
    ControllerSettings {
        rate_hz: 1000.0,
        first_order_hold: true,
        hold_after: 10,
        stale_ns: 5_000_000,
        future_slack_ns: 1_000_000,
        daemon_id: 1,
        t_start: 0.0,
    }
}

fn state(seq: u64, stamp: u64, plant_id: u64) -> StateSample {
    let mut s = StateSample {
        seq,
        stamp_ns: stamp,
        plant_id,
        n: 3,
        ..StateSample::default()
    };
    s.q[1] = 1.57;
    s.q[2] = 1.57;
    s.qd[0] = 0.3;
    s
}

#[test]
fn the_counter_sees_allocations() {
    assert_eq!(
        allocations(|| drop(std::hint::black_box(Box::new(7u64)))),
        1
    );
}

#[test]
fn controller_tick_allocates_nothing() {
    for preset in ["paper", "paper-obstacle", "paper-floating"] {
        let mut c = controller(preset);
        let t0 = 1_000_000_000u64;
        c.tick(Some(&state(0, t0, 5)), t0); // first contact resets the delay line
        let n = allocations(|| {
            for k in 1..3000u64 {
                let now = t0 + k * 1_000_000;
                let input = match k % 100 {
                    0..=69 => Some(state(k, now, 5)),
                    70 => {
                        let mut s = state(k, now, 5);
                        s.qd[2] = f64::NAN;
                        Some(s)
                    }
                    71 => Some(state(k, now - 50_000_000, 5)), // stale
                    72 => Some(state(1, now, 5)),              // out of order
                    73..=89 => None,                           // a gap long enough for HOLD
                    _ => Some(state(k, now, 5 + k / 1000)),    // and plant restarts
                };
                std::hint::black_box(c.tick(input.as_ref(), now));
            }
        });
        assert_eq!(n, 0, "{preset}: Controller::tick allocated {n} times");
        assert!(
            c.counters.holds_entered > 0
                && c.counters.plant_restarts > 0
                && c.counters.rejected_invalid > 0
        );
    }
}

#[test]
fn adapting_the_gain_on_the_tick_allocates_nothing() {
    let mut cfg = Config::preset("paper").unwrap();
    cfg.feedback.auto = Some(control::adapt::AutoMu::default());
    cfg.feedback.t_on = 0.5;
    let mut c = Controller::new(cfg.tick_law::<3>(), 2.0, settings());
    let t0 = 1_000_000_000u64;
    c.tick(Some(&state(0, t0, 5)), t0);
    let n = allocations(|| {
        for k in 1..3000u64 {
            let now = t0 + k * 1_000_000;
            let mut s = state(k, now, 5);
            s.qd[0] = (k as f64 * 0.01).sin(); // never τ-periodic: μ must grow
            std::hint::black_box(c.tick(Some(&s), now));
        }
    });
    assert_eq!(n, 0, "the adapting tick allocated {n} times");
    let mu = c.law().feedback().0;
    assert!(
        mu > 0.0 && mu <= cfg.feedback.auto.unwrap().max_mu,
        "μ = {mu}"
    );
}

/// The Panda's controller: the `panda` preset's spatial law behind the same `Controller`.
fn panda_controller() -> (Controller<7>, [f64; 7]) {
    use control::model::{builtin, Chain};
    use control::Config;
    let chain = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap();
    let mut cfg = Config::robot_preset("panda").unwrap();
    cfg.feedback.t_on = 0.5;
    // A sphere beside the forearm: the capsule rows are built on every tick.
    cfg.spatial_mut()
        .unwrap()
        .obstacles
        .push(control::config::spatial::SphereEntry {
            center: [0.45, 0.2, 0.5],
            radius: 0.05,
            margin: 0.1,
        });
    // Torque mode: computed torque (RNEA), the joint PD and the limiter run on every tick.
    cfg.spatial_mut().unwrap().command.mode = control::command::CommandMode::Torque;
    let s = cfg.setup::<7>(&chain).unwrap();
    let law = control::tick_law::TickLaw::Spatial {
        arm: s.arm,
        params: s.params,
    };
    let q0 = std::array::from_fn(|i| s.q0[i]);
    let generator = cfg.generator::<7>(&chain, 1e-3).unwrap();
    let mut c = Controller::new(law, 2.0, settings()).with_generator(generator);
    // Steered onto a planned cycle: the spline and the pull run on every tick too.
    let settings = control::plan::PlanSettings::default();
    let planned = control::plan::spatial::plan_setup(&s, 0.0, Some(s.q0), None, &settings);
    let control::plan::PlanOutcome::Found(cycle) = planned.outcome else {
        panic!("no cycle for the Panda beside one sphere");
    };
    let steer = control::steer::SpatialSteer::of(&cycle, 1.0).unwrap();
    c.set_steer(Some(control::steer::Steering::Spatial(steer)));
    (c, q0)
}

#[test]
fn the_panda_controller_tick_allocates_nothing() {
    let (mut c, q0) = panda_controller();
    let t0 = 1_000_000_000u64;
    let (mut q, mut qd) = (q0, [0.0f64; 7]);
    let sample = |seq: u64, now: u64, q: &[f64; 7], qd: &[f64; 7]| {
        let mut s = StateSample {
            seq,
            stamp_ns: now,
            plant_id: 5,
            n: 7,
            ..StateSample::default()
        };
        s.q[..7].copy_from_slice(q);
        s.qd[..7].copy_from_slice(qd);
        s
    };
    c.tick(Some(&sample(0, t0, &q, &qd)), t0);
    let n = allocations(|| {
        for k in 1..3000u64 {
            let now = t0 + k * 1_000_000;
            let input = (k % 100 < 90).then(|| sample(k, now, &q, &qd));
            let out = c.tick(input.as_ref(), now);
            // Follow the commands (a kinematic plant, Euler), so the arm moves as it would.
            if let Some(cmd) = out.command {
                for i in 0..7 {
                    qd[i] += cmd.qdd[i] * 1e-3;
                    q[i] += qd[i] * 1e-3;
                }
            }
        }
    });
    assert_eq!(n, 0, "the Panda's Controller::tick allocated {n} times");
    assert!(c.counters.commands > 2500 && c.counters.holds_entered > 0);
    assert_eq!(c.generator().mode(), control::command::CommandMode::Torque);
    assert_eq!(c.counters.nonfinite, 0);
}

#[test]
fn the_clock_loops_tick_allocates_only_iceoryx2s_loan() {
    // `ClockTick::run` is the function `service::control_loop` calls every period, on real
    // iceoryx2 ports in a namespace of its own; only the wait for the deadline is left out.
    use daemon::telemetry::{LoopRequest, TickRecord};
    use daemon::tick::ClockTick;
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let node = daemon::ipc::node("no-alloc-test").unwrap();
    let ns = format!(
        "t-noalloc-{}-{}",
        std::process::id(),
        monotonic_ns() % 1_000_000_000
    );
    let names = ServiceNames::new(&ns).unwrap();
    let state_svc = protocol::open_state_service(&node, &names).unwrap();
    let cmd_svc = protocol::open_command_service(&node, &names).unwrap();
    let plant_pub = state_svc.publisher_builder().create().unwrap();
    let sub = state_svc.subscriber_builder().create().unwrap();
    let publisher = cmd_svc.publisher_builder().create().unwrap();
    let cmd_sub = cmd_svc.subscriber_builder().create().unwrap();
    let mut c = controller("paper");
    let mut seq = 0u64;
    // The loop's channels and schedule, as `service::control_loop` makes them.
    let (params_tx, params_rx) = crossbeam::channel::bounded::<LoopRequest>(16);
    let (tel_tx, tel_rx) = crossbeam::channel::bounded::<TickRecord>(4096);
    let tick = ClockTick {
        subscriber: &sub,
        publisher: &publisher,
        tx: &tel_tx,
        requests: &params_rx,
    };
    let mut sched = rt::clock::Schedule::new(1_000_000, monotonic_ns());
    let params = *c.law().planar_params().unwrap();
    // Warm up: the first sends set up connections (and allocate for that).
    for _ in 0..50 {
        plant_pub.send_copy(state(seq, monotonic_ns(), 9)).unwrap();
        seq += 1;
        let now = monotonic_ns();
        tick.run(&mut c, now, now);
        while let Ok(Some(_)) = cmd_sub.receive() {}
    }
    let (mut published, mut allocs, mut records) = (0, 0, 0);
    for i in 0..2000 {
        if i % 100 == 0 {
            // A control-service change now and then, and a resume (a no-op outside FAULT).
            params_tx
                .try_send(LoopRequest::Params(control::tick_law::ParamBlock::Planar(
                    params,
                )))
                .unwrap();
        } else if i % 100 == 50 {
            params_tx.try_send(LoopRequest::Resume).unwrap();
        }
        records += tel_rx.try_iter().count();
        plant_pub.send_copy(state(seq, monotonic_ns(), 9)).unwrap();
        seq += 1;
        let before = c.counters.commands;
        allocs += allocations(|| {
            let due = sched.deadline();
            let t = tick.run(&mut c, due, monotonic_ns());
            c.counters.overruns += sched.advance(t.done);
        });
        published += c.counters.commands - before;
        while let Ok(Some(_)) = cmd_sub.receive() {}
    }
    records += tel_rx.try_iter().count();
    assert_eq!(published, 2000);
    assert_eq!(
        records, 2050,
        "every tick handed its record to the reporter"
    );
    assert_eq!(c.counters.params_applied, 20);
    assert_eq!(
        allocs, published,
        "expected exactly one allocation (iceoryx2's per-loan Rc) per published command"
    );
}

#[test]
fn the_state_triggered_path_from_state_to_command_allocates_nothing() {
    state_triggered_path(false);
}

#[test]
fn the_state_triggered_path_over_the_fast_lane_allocates_nothing() {
    // The same, with the lane: the state comes from the board (its pub-sub copy is dropped), the
    // command goes out on the board, and its pub-sub copy is sent in `after`.
    state_triggered_path(true);
}

fn state_triggered_path(fast_lane: bool) {
    // `StateLoop::answer` and `StateLoop::after` are what `trigger::state_loop` runs, on real
    // iceoryx2 ports with the loop's channels. The command sample is loaned before the state
    // arrives, so the path (wait → receive → tick → write → send) makes no allocation at all;
    // the next loan (iceoryx2's one `Rc`) happens in `after`, off the path.
    use daemon::telemetry::{LoopRequest, TickRecord};
    use daemon::trigger::{Ports, StateLoop, Timing};
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let node = daemon::ipc::node("no-alloc-state").unwrap();
    let ns = format!(
        "t-noalloc-st{}-{}-{}",
        u8::from(fast_lane),
        std::process::id(),
        monotonic_ns() % 1_000_000_000
    );
    let names = ServiceNames::new(&ns).unwrap();
    let state_svc = protocol::open_state_service(&node, &names).unwrap();
    let cmd_svc = protocol::open_command_service(&node, &names).unwrap();
    let plant_pub = state_svc.publisher_builder().create().unwrap();
    let sub = state_svc.subscriber_builder().create().unwrap();
    let publisher = cmd_svc.publisher_builder().create().unwrap();
    let cmd_sub = cmd_svc.subscriber_builder().create().unwrap();
    let (params_tx, params_rx) = crossbeam::channel::bounded::<LoopRequest>(16);
    let (tel_tx, tel_rx) = crossbeam::channel::bounded::<TickRecord>(4096);
    let lane = fast_lane.then(|| protocol::board::DaemonLane::daemon(&node, &names).unwrap());
    let plant_lane = fast_lane.then(|| protocol::board::PlantLane::plant(&node, &names).unwrap());
    // What the plant does: with the lane, the state goes on the board, and its pub-sub copy
    // once the answer is in (`copy`); without, on pub-sub at once.
    let publish = |s: protocol::StateSample| match &plant_lane {
        Some(p) => p.write(&s),
        None => plant_pub.send_copy(s).map(drop).unwrap(),
    };
    let copy = |s: protocol::StateSample| {
        if plant_lane.is_some() {
            plant_pub.send_copy(s).unwrap();
        }
    };
    let ports = Ports {
        subscriber: &sub,
        publisher: &publisher,
        tx: &tel_tx,
        lane: lane.as_ref(),
    };
    // The daemon's default wait around each expected arrival, at 1 kHz.
    let timing = Timing {
        period_ns: 1_000_000,
        wait: rt::WaitStrategy::Hybrid,
        spin_ns: 50_000,
        end_ns: None,
    };
    let mut c = controller("paper");
    let params = *c.law().planar_params().unwrap();
    let mut between = |c: &mut Controller<3>| daemon::tick::take_request(c, &params_rx);
    let mut l = StateLoop::new(&ports, timing);
    // Warm up: the first sends set up connections (and allocate for that).
    for seq in 0..50 {
        let s = state(seq, monotonic_ns(), 9);
        publish(s);
        let a = l.answer(&mut c);
        copy(s);
        l.after(&mut c, a, &mut between);
        while let Ok(Some(_)) = cmd_sub.receive() {}
    }
    let (mut sent, mut on_path, mut off_path, mut records) = (0, 0, 0, 0);
    for seq in 50..2050 {
        if seq % 100 == 0 {
            params_tx
                .try_send(LoopRequest::Params(control::tick_law::ParamBlock::Planar(
                    params,
                )))
                .unwrap();
        }
        records += tel_rx.try_iter().count();
        let s = state(seq, monotonic_ns(), 9);
        publish(s);
        let before = c.counters.commands;
        let mut answered = None;
        on_path += allocations(|| answered = Some(l.answer(&mut c)));
        copy(s);
        sent += c.counters.commands - before;
        let a = answered.unwrap();
        assert!(a.got.is_some(), "the state was there to answer");
        off_path += allocations(|| l.after(&mut c, a, &mut between));
        // Every command also reached pub-sub (with the lane: its copy, sent in `after`).
        let mut copies = 0;
        while let Ok(Some(_)) = cmd_sub.receive() {
            copies += 1;
        }
        assert_eq!(copies, 1, "tick {seq}");
        if let Some(p) = &plant_lane {
            assert_eq!(
                p.take().map(|c| c.state_seq),
                Some(seq),
                "the board's answer"
            );
        }
    }
    records += tel_rx.try_iter().count();
    assert_eq!(sent, 2000);
    if fast_lane {
        // Nothing new on the board, only the pub-sub copies of states the lane brought: they
        // are neither answered again nor counted as repeats or superseded states.
        let ticks = c.counters.fresh_states;
        let a = l.answer(&mut c);
        assert!(
            a.got.is_none(),
            "a copy was taken for a new state: {:?}",
            a.got
        );
        l.after(&mut c, a, &mut between);
        assert_eq!(c.counters.fresh_states, ticks);
    }
    assert_eq!(c.counters.rejected_out_of_order, 0);
    assert_eq!(c.counters.rejected_stale, 0);
    assert_eq!(c.counters.superseded, 0);
    assert_eq!(
        records, 2050,
        "every tick handed its record to the reporter"
    );
    assert_eq!(c.counters.params_applied, 20);
    assert_eq!(
        on_path, 0,
        "the state → command path allocated {on_path} times"
    );
    assert_eq!(
        off_path, sent,
        "off the path: exactly one allocation (iceoryx2's per-loan Rc) per command sent"
    );
}
