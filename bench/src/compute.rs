//! `compute`: the cost of the math, on one pinned core, chaosd next to the naive alternative.
//!
//! The control law is timed per call in batches (one clock read costs more than a call), on
//! states taken from a chaotic trajectory so that no branch or cache is artificially warm. The
//! naive law is a straight port of the numpy reference (dynamic matrices, SVD pseudo-inverse) and
//! computes the same q̈ (tested in `naive`). The Lyapunov pair is `control::analysis`'s Benettin
//! driver on the arm, the workload of `chaosctl lyapunov | sweep`, next to the plain run it doubles.
//! The robot model's table (Panda: FK + Jacobian + J̇q̇, RNEA, CRBA, ABA against a naive
//! implementation, `k` and pinocchio) is `model_timing`'s.

use crate::book::names;
use crate::naive;
use crate::plot::Panel;
use crate::report::{header, Output, Report};
use crate::stats::{fmt_ns, histogram, summary, Dist, Table};
use crate::timing::per_call;
use anyhow::{anyhow, Result};
use control::analysis::run::LyapunovSpec;
use control::analysis::{ArmFlow, Benettin};
use control::law::evaluate;
use control::{ArmState, Config, Kinematics, Simulation};
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

fn states(n: usize) -> Vec<ArmState<3>> {
    // A chaotic trajectory's states: realistic inputs, not one cached point.
    let cfg = Config::preset("paper").unwrap();
    let mut sim = Simulation::new(
        cfg.model::<3>(),
        cfg.law_params(),
        cfg.sim.dt,
        cfg.initial_state(),
        2.0,
    );
    (0..n)
        .map(|_| {
            for _ in 0..37 {
                sim.step();
            }
            *sim.state()
        })
        .collect()
}

/// Runs the benchmark on a thread pinned to `core` and returns its report.
pub fn run(
    quick: bool,
    core: usize,
    pinocchio: &crate::pinocchio_run::Source,
    out: &Path,
    command: &str,
) -> Result<Output> {
    let (out, command) = (out.to_path_buf(), command.to_string());
    let pinocchio = pinocchio.clone();
    std::thread::Builder::new()
        .name("compute".into())
        .spawn(move || {
            let rt = rt::setup::apply(rt::setup::RtRequest {
                core: Some(core),
                priority: 0,
                lock_memory: false,
            });
            for w in &rt.warnings {
                eprintln!("chaosd-bench: compute: warning: {w}; timings will be noisier");
            }
            let dir = out.join("compute");
            rt::files::create_dir_all(&dir)?;
            let pinocchio = crate::pinocchio_run::obtain(&pinocchio, quick, core, &dir);
            measure(quick, &pinocchio, &out, &command)
        })?
        .join()
        .map_err(|_| anyhow!("the compute thread panicked"))?
}

/// Which path of the filter a timed call takes.
#[derive(Clone, Copy, Debug, PartialEq)]
enum FilterCase {
    /// Every row already met: one pass, the command unchanged.
    Free,
    /// Some row binds and the null space alone meets them all: the closed-form interval.
    NullSpace,
    /// The null space cannot: the QP in the full joint space.
    FullSpace,
}

/// Per-call cost of `control::safety::filter` alone on the paper's arm and obstacle (clearance
/// 0.05 m) on chaotic states, sorted by the path each state takes. A 5 rad/s rate limit against
/// |q̇| up to 40 rad/s makes both binding paths common.
fn filter_cost(
    xs: &[ArmState<3>],
    case: FilterCase,
    batches: usize,
    batch: usize,
) -> Result<hdrhistogram::Histogram<u64>> {
    use control::basics::flags as lf;
    let mut cfg = Config::preset("paper-obstacle")?;
    cfg.safety.enabled = true;
    if case != FilterCase::Free {
        cfg.safety.qd_max = Some(control::safety::config::Limit::All(5.0));
    }
    let (p, m) = (cfg.law_params(), cfg.model::<3>());
    let mut cases = Vec::new();
    for x in xs {
        let mut k = Kinematics::<3>::default();
        m.kinematics(x.phi, &x.q, &x.qd, &mut k);
        let (jpinv, _, _) =
            control::resolve::damped_pinv(&k.j, p.core.damping_threshold, p.core.damping_max);
        let mut off = p;
        off.core.safety.enabled = false;
        let qdd = evaluate(&off, &m, 0.0, x.phi, &x.q, &x.qd, &x.qd, &mut k.clone()).qdd;
        let f = control::safety::filter(
            &p.core.safety,
            &m,
            &p.obstacles,
            &k,
            x.phi,
            &x.q,
            &x.qd,
            &jpinv,
            &qdd,
        );
        let path = if f.flags == 0 {
            FilterCase::Free
        } else if f.flags & lf::SAFETY_LEFT_NULL_SPACE == 0 {
            FilterCase::NullSpace
        } else {
            FilterCase::FullSpace
        };
        if path == case {
            cases.push((k, jpinv, *x, qdd));
        }
    }
    if cases.len() < 16 {
        return Err(anyhow!(
            "only {} states take the filter's {case:?} path",
            cases.len()
        ));
    }
    Ok(per_call(batches, batch, |i| {
        let (k, jpinv, x, qdd) = &cases[i % cases.len()];
        black_box(control::safety::filter(
            &p.core.safety,
            &m,
            &p.obstacles,
            k,
            x.phi,
            &x.q,
            &x.qd,
            jpinv,
            qdd,
        ));
    }))
}

fn measure(
    quick: bool,
    pinocchio: &crate::pinocchio_run::Timings,
    out: &Path,
    command: &str,
) -> Result<Output> {
    let mut report = Report::new(out, "compute")?;
    // First, in a process that has done nothing else yet (as pinocchio's harness runs); its
    // text goes after the tick table.
    let model = crate::model_timing::section(quick, pinocchio, &mut report)?;
    let (batches, batch) = if quick { (300, 200) } else { (3000, 1000) };
    let xs = states(1024);
    let mut table = Table::new(&["operation", "p50", "p99", "max", "vs naive (p50)"]);

    let mut rows: Vec<(String, [u64; 5])> = Vec::new();
    let mut dists = Vec::new();
    for preset in ["paper", "paper-obstacle", "paper-floating"] {
        let mut cfg = Config::preset(preset)?;
        cfg.feedback.mu = 1.0;
        cfg.feedback.t_on = 0.0;
        let (p, m) = (cfg.law_params(), cfg.model::<3>());
        let mut k = Kinematics::<3>::default();
        let h = per_call(batches, batch, |i| {
            let x = &xs[i % xs.len()];
            black_box(evaluate(
                &p,
                &m,
                i as f64 * 1e-3,
                x.phi,
                &x.q,
                &x.qd,
                &x.qd,
                &mut k,
            ));
        });
        let name = format!("control law, {preset} (n = 3)");
        report.hgrm(&format!("law-{preset}"), &h)?;
        dists.push(Dist::of_histogram(&name, &h));
        rows.push((name, summary(&h)));
    }
    for (name, case) in [
        (
            "safety filter alone, paper-obstacle (n = 3), not binding",
            FilterCase::Free,
        ),
        (
            "safety filter alone, paper-obstacle (n = 3), binding, null space (interval)",
            FilterCase::NullSpace,
        ),
        (
            "safety filter alone, paper-obstacle (n = 3), binding, full space (QP)",
            FilterCase::FullSpace,
        ),
    ] {
        let h = filter_cost(&xs, case, batches, batch)?;
        report.hgrm(&format!("filter-{case:?}").to_lowercase(), &h)?;
        dists.push(Dist::of_histogram(name, &h));
        rows.push((name.into(), summary(&h)));
    }
    let cfg = Config::preset("paper")?;
    let (p, m) = (cfg.law_params(), cfg.model::<3>());
    let naive_h = per_call(batches / 4, batch / 4, |i| {
        let x = &xs[i % xs.len()];
        black_box(naive::law(&p, &m, i as f64 * 1e-3, &x.q, &x.qd));
    });
    let naive_s = summary(&naive_h);
    report.hgrm("law-naive", &naive_h)?;

    let mut sim = Simulation::new(m, p, 1e-3, cfg.initial_state(), 2.0);
    let rk4 = per_call(batches, batch, |_| {
        black_box(sim.step());
    });
    rows.push(("RK4 step (4 law evaluations), paper".into(), summary(&rk4)));
    report.hgrm("rk4-step", &rk4)?;
    dists.push(Dist::of_histogram("RK4 step, paper", &rk4));
    dists.push(Dist::of_histogram("naive law (DMatrix + SVD)", &naive_h));

    for (name, s) in &rows {
        let ratio = if name.contains("paper (") {
            format!("{:.1}× faster", naive_s[0] as f64 / s[0] as f64)
        } else {
            String::new()
        };
        table.row(vec![
            name.clone(),
            fmt_ns(s[0] as f64),
            fmt_ns(s[2] as f64),
            fmt_ns(s[4] as f64),
            ratio,
        ]);
    }
    table.row(vec![
        "naive law: DMatrix + SVD pseudo-inverse".into(),
        fmt_ns(naive_s[0] as f64),
        fmt_ns(naive_s[2] as f64),
        fmt_ns(naive_s[4] as f64),
        "1.0×".into(),
    ]);

    // The whole 300 s run of docs/performance.md, best of a few repetitions.
    let reps = if quick { 2 } else { 5 };
    let mut best = f64::INFINITY;
    for _ in 0..reps {
        let mut sim = Simulation::new(m, p, 1e-3, cfg.initial_state(), 2.0);
        let t0 = Instant::now();
        for _ in 0..300_000 {
            black_box(sim.step());
        }
        best = best.min(t0.elapsed().as_secs_f64());
        black_box(sim.state());
    }
    // The Lyapunov pair behind `chaosctl lyapunov | sweep`: reference + partner for 300 s with
    // chaosctl's defaults (d0, renormalisation interval, window), feedback on (μ = 1) so that the
    // delay history is part of the perturbed and renormalised state. Timed per interval and whole.
    let spec = LyapunovSpec::default();
    let mut pair_cfg = Config::preset("paper")?;
    pair_cfg.feedback.mu = 1.0;
    let mut per_interval = histogram();
    let mut pair_best = f64::INFINITY;
    let mut lambda = None;
    for _ in 0..reps {
        let flow = ArmFlow::<3>::new(
            pair_cfg.model(),
            pair_cfg.law_params(),
            pair_cfg.sim.dt,
            pair_cfg.initial_state(),
        );
        let t0 = Instant::now();
        let mut pair = Benettin::new(flow, spec.d0, spec.renorm)?;
        let intervals = (300.0 / spec.renorm).round() as usize;
        for k in 1..=intervals {
            let s = Instant::now();
            pair.advance_to(k as f64 * spec.renorm)?;
            per_interval.saturating_record((s.elapsed().as_nanos() as u64).max(1));
        }
        pair_best = pair_best.min(t0.elapsed().as_secs_f64());
        lambda = Some(pair.estimate(spec.window[0], spec.window[1], spec.blocks)?);
    }
    let lambda = lambda.ok_or_else(|| anyhow!("no Lyapunov repetition ran"))?;
    let li = summary(&per_interval);
    report.hgrm("lyapunov-interval", &per_interval)?;
    table.row(vec![
        format!(
            "Lyapunov pair (μ = 1, history renormalised), one {} s interval = 2 × {:.0} RK4 steps",
            spec.renorm,
            spec.renorm / pair_cfg.sim.dt
        ),
        fmt_ns(li[0] as f64),
        fmt_ns(li[2] as f64),
        fmt_ns(li[4] as f64),
        String::new(),
    ]);

    report.push(&header("Compute", command));
    report.table(names::COMPUTE, &table.render())?;
    report.push(
        "\nThe daemon's whole tick (validation, delay line, law with the safety filter, first-order \
         hold, guard, command), timed alone per tick: warm, after its caches were evicted, and \
         evicted but rehearsed on the previous state, as the loop does after each sleep \
         (`Controller::rehearse`); and warm with `mu = \"auto\"`, the speed-gradient step on the \
         tick (issue 27), against a fixed μ in the same run: the two controllers tick the same \
         states one after the other, who goes first alternating (issue 44 asks ≤ 1.05×).\n\n",
    );
    report.table(names::COMPUTE_TICK, &crate::tick::table(quick)?)?;
    report.push(
        "\nThe chaos monitor's own work, on the reporter thread (the loop never runs it; its cost to \
         the loop's compute, monitor on vs off, is in the e2e report).\n\n",
    );
    report.table(names::COMPUTE_MONITOR, &crate::monitor_cost::table(quick)?)?;
    report.push("\nAn MCAP recording's work, on the reporter thread too.\n\n");
    report.table(names::COMPUTE_RECORD, &crate::record_cost::table(quick)?)?;
    report.push_tables(
        &crate::spatial_timing::section(quick)?,
        &[names::COMPUTE_PANDA],
    )?;
    report.push_tables(
        &crate::commands::section(quick)?,
        &[names::COMPUTE_COMMANDS, names::COMPUTE_COMMANDS_COST],
    )?;
    use crate::cycle_plan::{section as plan_section, PANDA, PLANAR};
    report.push_tables(&plan_section(&PLANAR, quick)?, &[names::COMPUTE_PLAN])?;
    report.push_tables(&plan_section(&PANDA, quick)?, &[names::COMPUTE_PLAN_PANDA])?;
    report.push_tables(&model, &[names::COMPUTE_MODEL])?;
    report.push(&format!(
        "\n300 s simulation (RK4, dt = 1 ms, fixed base, manipulability): {:.3} s wall, {:.0} simulated s per wall s \
         (target < 0.3 s; the plain numpy reference takes about 139 s, numba about 2.6 s: {:.0}× and {:.0}× slower)\n",
        best,
        300.0 / best,
        139.0 / best,
        2.6 / best
    ));
    report.push(&format!(
        "Lyapunov pair over 300 s (Benettin, d0 = {:e}, renormalised every {} s, μ = 1): {:.3} s wall, {:.2}× one plain \
         300 s run (2× would be two plain runs); λ_max = {:.3} ± {:.3} 1/s over {:.0}..{:.0} s\n",
        spec.d0,
        spec.renorm,
        pair_best,
        pair_best / best,
        lambda.lambda_max,
        lambda.stderr,
        lambda.window[0],
        lambda.window[1]
    ));
    let law_p50 = rows[0].1[0];
    report.push(&format!(
        "Targets: control law p50 {} (target < 1 µs: {}), 300 s run {:.3} s (target < 0.3 s: {})\n",
        fmt_ns(law_p50 as f64),
        if law_p50 < 1000 { "met" } else { "MISSED" },
        best,
        if best < 0.3 { "met" } else { "MISSED" }
    ));
    dists.push(Dist::of_histogram(
        "Lyapunov pair, one interval",
        &per_interval,
    ));
    report.plot(
        "chaosd-bench compute: time per call",
        &[Panel {
            title: "per call (batched), one pinned core".into(),
            quantity: "time".into(),
            series: dists,
        }],
    )?;
    report.finish()
}
