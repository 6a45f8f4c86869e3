//! The method on the Panda: the spatial law, its safety filter and the daemon's whole tick, beside
//! the planar arm's in the same run, with the targets (filter ≤ 2 µs p50 with 4 spheres
//! and every joint limit, tick ≤ 3 µs p50 warm, 300 s of simulation ≤ 1 s).
//!
//! States come from the `panda` preset's own run while its feedback is still off (chaotic, held
//! by the filter), so the filter's binding paths are exercised as often as they occur there.

use crate::stats::{fmt_ns, histogram, summary, Bound, Table, Target};
use anyhow::{anyhow, Result};
use control::arm::spatial::SpatialKinematics;
use control::config::spatial::SpatialSetup;
use control::config::spatial::SphereEntry;
use control::law::spatial as law;
use control::model::{builtin, Chain};
use control::resolve::damped_pinv_m;
use control::safety;
use control::sim::Simulation;
use control::tick_law::TickLaw;
use control::{ArmState, Config};
use daemon::controller::{Controller, ControllerSettings};
use protocol::StateSample;
use std::hint::black_box;
use std::time::Instant;

/// The preset with four spheres around the arm's workspace, clear of its start.
fn setup() -> Result<SpatialSetup<7>> {
    let chain = Chain::from_urdf(builtin("panda")?, None, None)?;
    let mut cfg = Config::robot_preset("panda").ok_or_else(|| anyhow!("no panda preset"))?;
    for c in [
        [0.55, 0.3, 0.3],
        [0.55, -0.3, 0.3],
        [0.0, 0.45, 0.6],
        [0.0, -0.45, 0.6],
    ] {
        cfg.spatial_mut()
            .expect("a robot")
            .obstacles
            .push(SphereEntry {
                center: c,
                radius: 0.08,
                margin: 0.1,
            });
    }
    Ok(cfg.setup::<7>(&chain)?)
}

/// States of the preset's run before its feedback (every 37th step of 50 s).
fn states(s: &SpatialSetup<7>, n: usize) -> Vec<ArmState<7>> {
    let mut sim = Simulation::spatial(s.arm, s.params, s.dt, s.q0, s.qd0, 2.0);
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        for _ in 0..37 {
            sim.step();
        }
        out.push(*sim.state());
    }
    out
}

fn settings() -> ControllerSettings {
    ControllerSettings {
        rate_hz: 1000.0,
        first_order_hold: true,
        hold_after: 20,
        stale_ns: 5_000_000,
        future_slack_ns: 1_000_000,
        daemon_id: 1,
        t_start: 0.0,
    }
}

/// Warm per-tick cost of a controller fed `xs` as states, one tick timed at a time.
fn tick_cost<const N: usize>(
    ctl: &mut Controller<N>,
    xs: &[ArmState<N>],
) -> hdrhistogram::Histogram<u64> {
    let mut h = histogram();
    let t0 = protocol::monotonic_ns();
    for (k, x) in xs.iter().enumerate() {
        let mut s = StateSample {
            seq: k as u64,
            stamp_ns: t0 + k as u64 * 1_000_000,
            plant_id: 7,
            n: N as u32,
            ..StateSample::default()
        };
        s.q[..N].copy_from_slice(x.q.as_slice());
        s.qd[..N].copy_from_slice(x.qd.as_slice());
        black_box(Instant::now());
        let start = Instant::now();
        black_box(ctl.tick(Some(&s), s.stamp_ns + 20_000));
        let ns = start.elapsed().as_nanos() as u64;
        if k >= xs.len() / 10 {
            h.saturating_record(ns.max(1));
        }
    }
    h
}

fn planar_states(n: usize) -> Result<(Config, Vec<ArmState<3>>)> {
    let mut cfg = Config::preset("demo")?;
    cfg.feedback.t_on = 0.5;
    let mut sim = control::Simulation::new(
        cfg.model::<3>(),
        cfg.law_params(),
        1e-3,
        cfg.initial_state(),
        2.0,
    );
    let xs = (0..n)
        .map(|_| {
            sim.step();
            *sim.state()
        })
        .collect();
    Ok((cfg, xs))
}

/// The section: a table and the targets.
pub fn section(quick: bool) -> Result<String> {
    let s = setup()?;
    let (batches, batch) = if quick { (300, 100) } else { (3000, 300) };
    let xs = states(&s, 1024);
    let mut t = Table::new(&[
        "operation (Panda: 7 joints, tool point, centring, 4 spheres, every joint limit)",
        "p50",
        "p99",
        "max",
    ]);
    let mut row = |name: &str, h: &hdrhistogram::Histogram<u64>| {
        let v = summary(h);
        t.row(vec![
            name.into(),
            fmt_ns(v[0] as f64),
            fmt_ns(v[2] as f64),
            fmt_ns(v[4] as f64),
        ]);
        v[0] as f64
    };
    let mut k = SpatialKinematics::<7>::default();
    let mut pose = s.params;
    pose.task.kind = control::task::pose::TaskKind::Pose;
    let law3 = crate::timing::per_call(batches, batch, |i| {
        let x = &xs[i % xs.len()];
        black_box(law::evaluate::<7, 3>(
            &s.params, &s.arm, 1.0, &x.q, &x.qd, &x.qd, &mut k,
        ));
    });
    row("spatial law, position task (m = 3), filter on", &law3);
    let law6 = crate::timing::per_call(batches, batch, |i| {
        let x = &xs[i % xs.len()];
        black_box(law::evaluate::<7, 6>(
            &pose, &s.arm, 1.0, &x.q, &x.qd, &x.qd, &mut k,
        ));
    });
    row("spatial law, pose task (m = 6), filter on", &law6);
    // The filter alone, on the law's own unfiltered command at each state.
    let mut off = s.params;
    off.core.safety.enabled = false;
    let (mut binding, mut left, mut infeasible) = (0usize, 0usize, 0usize);
    let cases: Vec<_> = xs
        .iter()
        .map(|x| {
            let mut kin = SpatialKinematics::<7>::default();
            let qdd = law::evaluate::<7, 3>(&off, &s.arm, 1.0, &x.q, &x.qd, &x.qd, &mut kin).qdd;
            let j = kin.jac.fixed_rows::<3>(0).into_owned();
            let (jpinv, _, _) = damped_pinv_m(
                &j,
                s.params.core.damping_threshold,
                s.params.core.damping_max,
            );
            let f = safety::filter_spatial(
                &s.params.core.safety,
                &s.arm,
                &s.params.spheres,
                &kin,
                &x.q,
                &x.qd,
                &j,
                &jpinv,
                &qdd,
            );
            binding += usize::from(f.flags != 0);
            left += usize::from(f.flags & control::basics::flags::SAFETY_LEFT_NULL_SPACE != 0);
            infeasible += usize::from(f.flags & control::basics::flags::SAFETY_INFEASIBLE != 0);
            (kin, j, jpinv, *x, qdd)
        })
        .collect();
    let filter = crate::timing::per_call(batches, batch, |i| {
        let (kin, j, jpinv, x, qdd) = &cases[i % cases.len()];
        black_box(safety::filter_spatial(
            &s.params.core.safety,
            &s.arm,
            &s.params.spheres,
            kin,
            &x.q,
            &x.qd,
            j,
            jpinv,
            qdd,
        ));
    });
    let filter_p50 = row(
        &format!(
            "safety filter alone (binding on {:.0}% of these states, leaving the null space on {:.0}%, infeasible on {:.0}%)",
            100.0 * binding as f64 / cases.len() as f64,
            100.0 * left as f64 / cases.len() as f64,
            100.0 * infeasible as f64 / cases.len() as f64
        ),
        &filter,
    );
    let mut sim = Simulation::spatial(s.arm, s.params, s.dt, s.q0, s.qd0, 2.0);
    let rk4 = crate::timing::per_call(batches, batch / 4, |_| {
        black_box(sim.step());
    });
    row("RK4 step (4 law evaluations)", &rk4);
    let mut panda = Controller::<7>::new(
        TickLaw::Spatial {
            arm: s.arm,
            params: s.params,
        },
        2.0,
        settings(),
    );
    let n = if quick { 1500 } else { 10_000 };
    let mut run = Simulation::spatial(s.arm, s.params, s.dt, s.q0, s.qd0, 2.0);
    let pxs: Vec<_> = (0..n)
        .map(|_| {
            run.step();
            *run.state()
        })
        .collect();
    let tick_h = tick_cost(&mut panda, &pxs);
    if panda.counters.commands < n as u64 || panda.counters.faults > 0 {
        return Err(anyhow!(
            "the Panda's controller did not run its law on every tick ({} commands, {} faults)",
            panda.counters.commands,
            panda.counters.faults
        ));
    }
    let tick_p50 = row(
        "daemon tick, warm (validation, delay line, law, filter, first-order hold, guard, command)",
        &tick_h,
    );
    let (cfg, pl) = planar_states(n)?;
    let mut planar = Controller::<3>::new(cfg.tick_law::<3>(), cfg.feedback.capacity(), settings());
    let planar_tick = summary(&tick_cost(&mut planar, &pl))[0] as f64;
    // 300 s of the preset's simulation, best of 3 (1 in --quick).
    let mut best = f64::INFINITY;
    for _ in 0..if quick { 1 } else { 3 } {
        let mut sim = Simulation::spatial(s.arm, s.params, s.dt, s.q0, s.qd0, 2.0);
        let t0 = Instant::now();
        for _ in 0..300_000 {
            black_box(sim.step());
        }
        best = best.min(t0.elapsed().as_secs_f64());
    }
    let targets = [
        Target::new(
            "safety filter, Panda, 4 spheres and every joint limit, p50",
            filter_p50 / 1e3,
            Bound::AtMost(2.0),
        )
        .in_unit("µs"),
        Target::new(
            "daemon tick for the Panda, warm p50",
            tick_p50 / 1e3,
            Bound::AtMost(3.0),
        )
        .in_unit("µs"),
        Target::new(
            "300 s of Panda simulation (RK4, dt = 1 ms, 4 spheres), wall",
            best,
            Bound::AtMost(1.0),
        )
        .in_unit("s"),
    ];
    let mut out = format!(
        "\n### The method on the Panda\n\n{}\nThe planar demo's warm tick in the same run: {} p50, so the Panda's costs {:.1}× it.\n\n",
        t.render(),
        fmt_ns(planar_tick),
        tick_p50 / planar_tick.max(1.0)
    );
    for t in &targets {
        out.push_str(&t.line());
        out.push('\n');
    }
    Ok(out)
}
