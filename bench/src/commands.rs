//! Commanding the Panda as a real arm (issue 24): the acceptance table, every interface against
//! the rigid-body plant side by side in one run, and what the generator and limiter cost per
//! tick next to acceleration mode's pass-through.
//!
//! The runs are the offline sampled-data loop (`control::commanded`: the daemon's law
//! and generator and the plant's device, 1 kHz, 4 substeps), the Panda on the `panda` preset's
//! circle with μ = 1 (null space) from t = 20 s, tracking measured after 10 s. The device
//! emulator's reflex counts come from the live runs (`chaosd demo --bridge udp --mode
//! position [--no-limiter]`), reported by the demo itself.

use crate::stats::{fmt_ns, summary, Bound, Table, Target};
use anyhow::{anyhow, Result};
use control::command::{CommandMode, LimitKind};
use control::commanded::run;
use control::commanded::CommandedRun;
use control::rigid_body::RigidBodyConfig;
use control::System;
use std::hint::black_box;

fn panda(mode: CommandMode, pd_hz: f64) -> Result<System> {
    let resolve: control::system::Resolve = &control::system::builtin_robot;
    let mut s = System::preset("panda", resolve)?;
    let System::Spatial(sp) = &mut s else {
        return Err(anyhow!("the panda preset is not spatial"));
    };
    sp.own_mut().command.mode = mode;
    sp.own_mut().command.pd_bandwidth_hz = pd_hz;
    s.schedule_feedback(control::adapt::MuSetting::Fixed(1.0), 20.0);
    Ok(s)
}

fn go(mode: CommandMode, pd_hz: f64, payload: f64, seconds: f64) -> Result<CommandedRun> {
    let plant = RigidBodyConfig {
        payload,
        ..Default::default()
    };
    Ok(run::<7>(
        &panda(mode, pd_hz)?,
        &plant,
        1e-3,
        4,
        seconds,
        10.0,
    )?)
}

/// The section: the acceptance table, its targets, and the cost per tick.
pub fn section(quick: bool) -> Result<String> {
    let seconds = if quick { 40.0 } else { 60.0 };
    let mut t = Table::new(&[
        "interface (Panda, rigid-body plant)",
        "tracking RMS",
        "peak",
        "residual before → after",
        "limiter clamps (jerk / acc / vel / τ̇)",
        "plant τ at its limit",
    ]);
    let mut rows = Vec::new();
    for (mode, hz, payload, label) in [
        (
            CommandMode::Acceleration,
            10.0,
            0.0,
            "acceleration, exact model".to_string(),
        ),
        (
            CommandMode::Velocity,
            10.0,
            0.0,
            "velocity (arm's 50 Hz servo), exact".into(),
        ),
        (
            CommandMode::Position,
            10.0,
            0.0,
            "position (arm's 50 Hz servo), exact".into(),
        ),
        (
            CommandMode::Torque,
            10.0,
            0.0,
            "torque, exact model, PD 10 Hz".into(),
        ),
        (
            CommandMode::Torque,
            5.0,
            1.0,
            "torque, 1 kg unmodelled payload, PD 5 Hz".into(),
        ),
        (
            CommandMode::Torque,
            10.0,
            1.0,
            "torque, 1 kg unmodelled payload, PD 10 Hz".into(),
        ),
        (
            CommandMode::Torque,
            12.0,
            1.0,
            "torque, 1 kg unmodelled payload, PD 12 Hz".into(),
        ),
    ] {
        let r = go(mode, hz, payload, seconds)?;
        let s = |k: LimitKind| r.saturations[k as usize];
        t.row(vec![
            label.clone(),
            format!("{:.2e} m", r.tracking_rms),
            format!("{:.2e} m", r.tracking_max),
            format!(
                "{:.3} → {:.3} rad/s ({:.0}×)",
                r.residual_before,
                r.residual_after,
                r.residual_before / r.residual_after.max(1e-12)
            ),
            format!(
                "{} / {} / {} / {}",
                s(LimitKind::Jerk),
                s(LimitKind::Acceleration),
                s(LimitKind::Velocity),
                s(LimitKind::TorqueRate)
            ),
            r.plant_torque_saturations.to_string(),
        ]);
        rows.push((mode, hz, payload, r));
    }
    let find = |m: CommandMode, hz: f64, p: f64| {
        rows.iter()
            .find(|(a, b, c, _)| *a == m && *b == hz && *c == p)
            .map(|r| r.3)
            .ok_or_else(|| anyhow!("missing run"))
    };
    let exact = find(CommandMode::Torque, 10.0, 0.0)?;
    let payload = find(CommandMode::Torque, 10.0, 1.0)?;
    let position = find(CommandMode::Position, 10.0, 0.0)?;
    let drop = |r: &CommandedRun| r.residual_before / r.residual_after.max(1e-12);
    let targets = [
        Target::new(
            "torque mode, exact model: tracking RMS",
            exact.tracking_rms * 1e3,
            Bound::AtMost(0.1),
        )
        .in_unit("mm"),
        Target::new(
            "torque mode, 1 kg unmodelled payload (PD 10 Hz): tracking RMS",
            payload.tracking_rms * 1e3,
            Bound::AtMost(2.0),
        )
        .in_unit("mm"),
        Target::new(
            "the feedback in torque mode: residual falls",
            drop(&exact),
            Bound::AtLeast(10.0),
        ),
        Target::new(
            "the feedback in position mode: residual falls",
            drop(&position),
            Bound::AtLeast(10.0),
        ),
    ];
    let mut out = format!(
        "\n### Commanding a real arm\n\n{} s per run, side by side; the PD rows show how the joint gains trade the payload's error (docs/commanding.md).\n\n{}\n",
        seconds,
        t.render()
    );
    for t in &targets {
        out.push_str(&t.line());
        out.push('\n');
    }
    out.push_str(&cost(quick)?);
    Ok(out)
}

/// What the generator and limiter add to a tick, per interface, next to the pass-through.
fn cost(quick: bool) -> Result<String> {
    let (batches, batch) = if quick { (300, 100) } else { (3000, 300) };
    let mut t = Table::new(&["generator + limiter per tick (Panda)", "p50", "p99", "max"]);
    let q = nalgebra::SVector::<f64, 7>::from_column_slice(&control::config::spatial::PANDA_READY);
    let qd = nalgebra::SVector::<f64, 7>::repeat(0.3);
    let a = nalgebra::SVector::<f64, 7>::repeat(0.5);
    let r = nalgebra::SVector::<f64, 7>::repeat(2.0);
    let pass = control::command::MotionGenerator::<7>::passthrough(1e-3);
    let mut gens = vec![("pass-through (the planar arm)", pass)];
    for mode in CommandMode::ALL {
        let System::Spatial(s) = panda(mode, 10.0)? else {
            return Err(anyhow!("not spatial"));
        };
        let g = s.config.generator::<7>(&s.chain, 1e-3)?;
        gens.push((mode.name(), g));
    }
    for (name, mut g) in gens {
        g.restart(&q, &qd);
        let h = crate::timing::per_call(batches, batch, |_| {
            let c = g.next(&q, &qd, &a, &r);
            black_box(c);
        });
        let v = summary(&h);
        t.row(vec![
            name.to_string(),
            fmt_ns(v[0] as f64),
            fmt_ns(v[2] as f64),
            fmt_ns(v[4] as f64),
        ]);
    }
    Ok(format!("\n{}", t.render()))
}
