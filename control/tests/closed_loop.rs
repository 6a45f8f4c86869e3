//! Closed-loop properties of the control law and the deterministic simulation.

use control::basics::flags;
use control::law::evaluate;
use control::resolve::damped_pinv;
use control::{with_dof, ArmState, Config, Kinematics, RunStats, Simulation, VecN};
use proptest::prelude::*;

fn sim3(cfg: &Config) -> Simulation<3, control::tick_law::TickLaw<3>> {
    Simulation::new(
        cfg.model::<3>(),
        cfg.law_params(),
        cfg.sim.dt,
        cfg.initial_state(),
        cfg.feedback.capacity(),
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn null_space_projector_annihilates_jacobian_range(q in prop::array::uniform3(-3.0f64..3.0), v in prop::array::uniform2(-5.0f64..5.0)) {
        let cfg = Config::preset("paper").unwrap();
        let m = cfg.model::<3>();
        let mut k = Kinematics::default();
        m.kinematics(0.0, &VecN::<3>::from(q), &VecN::<3>::zeros(), &mut k);
        let (jp, smin, lambda) = damped_pinv(&k.j, 1e-9, 1e-9);
        prop_assume!(smin > 1e-3);
        prop_assert_eq!(lambda, 0.0);
        let x = k.j.transpose() * nalgebra::Vector2::from(v);
        let proj = x - jp * (k.j * x);
        prop_assert!(proj.norm() < 1e-9 * (1.0 + x.norm()), "(I − J⁺J)Jᵀv = {}", proj);
        // And J J⁺ = I away from singularities.
        prop_assert!((k.j * jp - nalgebra::Matrix2::identity()).norm() < 1e-9);
    }
}

#[test]
fn tracking_error_converges_on_the_circle() {
    // eq. 11's swapped gains (K_p = 15, K_v = 40) are overdamped: slower, so given longer.
    for (preset, seconds) in [("paper", 20), ("paper-eq11", 60), ("paper-obstacle", 20)] {
        let mut cfg = Config::preset(preset).unwrap();
        cfg.sim.duration = seconds as f64;
        let mut sim = sim3(&cfg);
        let mut first = None;
        let mut last = 0.0;
        for _ in 0..seconds * 1000 {
            let out = sim.step();
            first.get_or_insert(out.tracking_error);
            last = out.tracking_error;
        }
        assert!(
            first.unwrap() > 0.5,
            "{preset}: the start is far from the circle"
        );
        assert!(
            last < 1e-6,
            "{preset}: tracking error {last} m after {seconds} s"
        );
    }
}

#[test]
fn feedback_makes_small_mu_periodic_and_mu_zero_is_not() {
    // docs/science.md, "Measuring chaos": μ = 0 wanders; small μ (0.1) settles on a period-1 orbit.
    let run = |mu: f64| {
        let mut cfg = Config::preset("paper").unwrap();
        cfg.feedback.mu = mu;
        cfg.sim.duration = 300.0;
        let mut sim = sim3(&cfg);
        let x0 = cfg.initial_state::<3>();
        let mut stats = RunStats::new(&cfg.law_params(), cfg.sim.dt, cfg.sim.duration, 20.0, &x0);
        for k in 0..300_000 {
            let x = *sim.state();
            let out = sim.step();
            stats.record(k, &x, &out);
        }
        stats.summary().period_residual_final.unwrap()
    };
    let (chaotic, periodic) = (run(0.0), run(0.1));
    assert!(chaotic > 0.1, "μ = 0 residual {chaotic}");
    assert!(periodic < 1e-3, "μ = 0.1 residual {periodic}");
}

#[test]
fn identical_runs_are_bit_identical() {
    for preset in ["paper", "paper-obstacle", "paper-floating"] {
        let mut cfg = Config::preset(preset).unwrap();
        cfg.feedback.mu = 1.5;
        cfg.feedback.t_on = 2.0;
        let run = || {
            let mut sim = sim3(&cfg);
            for _ in 0..8_000 {
                sim.step();
            }
            let x = *sim.state();
            x.q.iter()
                .chain(x.qd.iter())
                .chain([x.phi].iter())
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()
        };
        assert_eq!(run(), run(), "{preset}");
    }
}

#[test]
fn singular_and_unreachable_targets_give_finite_commands_and_report_loss() {
    // A circle far outside the workspace: the arm stretches out and sits at the singularity.
    let mut cfg = Config::preset("paper").unwrap();
    cfg.planar_mut().unwrap().task.center = [6.0, 0.0];
    cfg.sim.q0 = Some(vec![0.0, 0.0, 0.0]); // stretched: exactly singular
    let mut sim = sim3(&cfg);
    let mut seen = 0;
    for _ in 0..20_000 {
        let out = sim.step();
        assert!(out.qdd.iter().all(|v| v.is_finite()));
        assert_eq!(out.flags & flags::NONFINITE, 0);
        seen |= out.flags;
    }
    assert!(sim.state().is_finite());
    for f in [flags::SINGULAR, flags::OUT_OF_REACH, flags::TRACK_LOST] {
        assert_ne!(seen & f, 0, "flag {f:#x} never reported");
    }

    // Straight at the singular configuration, zero rates, every secondary task.
    for preset in ["paper", "paper-obstacle", "paper-floating"] {
        let cfg = Config::preset(preset).unwrap();
        with_dof!(cfg.n(), N => {
            let m = cfg.model::<N>();
            let mut k = Kinematics::default();
            let z = VecN::<N>::zeros();
            let out = evaluate(&cfg.law_params(), &m, 0.0, 0.0, &z, &z, &z, &mut k);
            assert!(out.qdd.iter().all(|v| v.is_finite()), "{preset}: {:?}", out.qdd);
            assert_ne!(out.flags & flags::SINGULAR, 0, "{preset}");
        });
    }
}

#[test]
fn floating_base_drifts_and_then_loses_tracking_without_nan() {
    // docs/science.md, "The free-floating base": the attitude drifts slowly (≈ −0.005 rad/s) and within minutes the circle
    // leaves the workspace; the controller passes the singularity without NaN and reports it.
    let cfg = Config::preset("paper-floating").unwrap();
    let mut sim = sim3(&cfg);
    let mut lost_at = None;
    let mut phi_at_60 = 0.0;
    for k in 0..240_000u64 {
        let out = sim.step();
        assert!(out.qdd.iter().all(|v| v.is_finite()));
        if k == 60_000 {
            phi_at_60 = sim.state().phi;
        }
        if k > 20_000 && out.flags & flags::TRACK_LOST != 0 && lost_at.is_none() {
            lost_at = Some(k as f64 * cfg.sim.dt);
        }
    }
    let rate = phi_at_60 / 60.0;
    assert!((-0.01..-0.002).contains(&rate), "base drift {rate} rad/s");
    let lost = lost_at.expect("tracking is lost within 4 minutes");
    assert!(lost < 240.0);
    assert!(sim.state().is_finite());
}

#[test]
fn pyragas_term_vanishes_on_a_period_tau_orbit() {
    // Once the μ = 0.1 run has converged, switching μ to 3 changes nothing: the term is non-invasive.
    let mut cfg = Config::preset("paper").unwrap();
    cfg.feedback.mu = 0.1;
    let mut sim = sim3(&cfg);
    for _ in 0..300_000 {
        sim.step();
    }
    let out = sim.step();
    assert!(
        out.period_residual < 1e-4,
        "residual {}",
        out.period_residual
    );
    let x: ArmState<3> = *sim.state();
    let mut strong = sim.clone();
    strong.law.core_mut().mu = 3.0;
    for _ in 0..1000 {
        sim.step();
        strong.step();
    }
    assert!(
        (sim.state().q - strong.state().q).norm() < 1e-4,
        "from {:?}",
        x.q
    );
}

/// Every arm takes every path shape: a planar file names `path = "eight"` as a robot's does,
/// prints it back (a circle, the default, is left out as before), and the law holds the hand on
/// the eight once the start's error has died away. A shape no arm has is refused by its key.
#[test]
fn the_planar_arm_traces_a_figure_eight_named_in_its_file() {
    use control::task::Shape;
    let text = Config::preset("paper").unwrap().to_toml();
    assert!(!text.contains("path ="), "{text}");
    let eight = text.replacen("[task]\n", "[task]\npath = \"eight\"\n", 1);
    let cfg = Config::parse(&eight).unwrap();
    assert_eq!(cfg.planar_part().task.path, Shape::Eight);
    assert!(cfg.to_toml().contains("path = \"eight\""));
    let mut sim = sim3(&cfg);
    let (mut worst, mut far) = (0.0f64, 0.0f64);
    for k in 0..20_000 {
        let out = sim.step();
        if k >= 10_000 {
            worst = worst.max(out.tracking_error);
            // The eight's lobes reach r/2 across the centre's line, where a circle reaches r.
            far = far.max((out.p.y - cfg.planar_part().task.center[1]).abs());
        }
    }
    assert!(worst < 1e-6, "tracking error {worst} m after 10 s");
    assert!(
        (far - 0.25).abs() < 1e-3,
        "the hand reached {far} m off the centre line"
    );
    let square = text.replacen("[task]\n", "[task]\npath = \"square\"\n", 1);
    let e = Config::parse(&square).unwrap_err().to_string();
    assert!(e.contains("path") && e.contains("eight"), "{e}");
}
