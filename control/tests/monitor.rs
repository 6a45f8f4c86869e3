//! The chaos monitor and `mu = "auto"` on the simulated planar arm: the real law, the real
//! simulation, the monitor the daemon runs (what `chaosctl monitor` measures at scale).

use control::adapt::AutoMu;
use control::monitor::run::{watch, Edit, PeriodPoint};
use control::monitor::{MonitorSettings, Verdict};
use control::sim::ClosedLoopLaw;
use control::{Config, System};

fn paper(q0: [f64; 3], mu: f64) -> System {
    let mut cfg = Config::preset("paper").unwrap();
    cfg.sim.q0 = Some(q0.to_vec());
    cfg.feedback.mu = mu;
    cfg.validate().unwrap();
    System::Planar(cfg)
}

#[test]
fn free_self_motion_is_called_chaotic_within_eight_periods() {
    // Issue 44's target: the first verdict within 8 periods (τ = 1 s), from the samples at every
    // phase of the path before twelve once-a-period returns are there.
    for q0 in [
        [0.3, 1.2, 1.9],
        [-0.5, 2.0, 1.0],
        [0.6, 1.0, 2.2],
        [-0.2, 1.8, 1.4],
    ] {
        let w = watch(&paper(q0, 0.0), 60.0, MonitorSettings::default(), &[]);
        let first = w.edges.first().expect("a verdict");
        assert_eq!(first.to, Verdict::Chaotic, "{q0:?}: {:?}", w.edges);
        assert!(first.t <= 8.0, "{q0:?}: chaotic only at {} s", first.t);
        assert_eq!(w.last.verdict, Verdict::Chaotic, "{q0:?}: {:?}", w.last);
        assert!(
            w.last.lambda.unwrap() > 0.0 && w.last.k.unwrap() > 0.5,
            "{:?}",
            w.last
        );
    }
}

#[test]
fn a_stabilising_gain_is_called_periodic_and_a_torus_regular() {
    // μ = 0.1 from this start: captured by the period-1 orbit after a chaotic transient.
    let w = watch(
        &paper([0.3, 1.2, 1.9], 0.1),
        150.0,
        MonitorSettings::default(),
        &[],
    );
    let seen: Vec<Verdict> = w.edges.iter().map(|e| e.to).collect();
    assert_eq!(w.last.verdict, Verdict::Periodic, "{seen:?}");
    assert_eq!(seen[0], Verdict::Chaotic, "{seen:?}");
    // μ = 0.45: quasi-periodic (the offline section says so); Rosenstein's λ alone would call it
    // chaotic, the 0–1 test does not.
    let w = watch(
        &paper([0.3, 1.2, 1.9], 0.45),
        300.0,
        MonitorSettings::default(),
        &[],
    );
    assert_eq!(w.last.verdict, Verdict::Regular, "{:?}", w.last);
    assert!(w.last.k.unwrap() < 0.2, "{:?}", w.last);
}

#[test]
fn auto_mu_finds_a_stabilising_gain_from_every_start_and_after_an_edit() {
    for q0 in [[0.6, 1.0, 2.2], [-0.5, 2.0, 1.0], [-0.8, 2.3, 1.2]] {
        let mut system = paper(q0, 0.0);
        system.feedback_section_mut().auto = Some(AutoMu::default());
        system.validate().unwrap();
        let radius = |s: &mut System| {
            *s.task_circle_mut().0 *= 1.1;
            Ok(())
        };
        let edit = [Edit::of(&system, 300.0, radius).unwrap()];
        let w = watch(&system, 600.0, MonitorSettings::default(), &edit);
        let max = AutoMu::default().max_mu;
        assert!(
            w.trace.iter().all(|p| p.mu <= max),
            "{q0:?}: μ passed max_mu"
        );
        let before: Vec<_> = w.trace.iter().filter(|p| p.t < 300.0).collect();
        assert_eq!(
            before.last().unwrap().verdict,
            Verdict::Periodic,
            "{q0:?} before the edit"
        );
        assert_eq!(
            w.last.verdict,
            Verdict::Periodic,
            "{q0:?} after the edit: {:?}",
            w.last
        );
        assert!(w.mu_final > 0.0 && w.effort.is_finite());
        // As in the daemon: the model's gain at the start and for the edited set-up after the
        // edit, and μ ends within the correction's band around the newest one.
        assert_eq!(w.model.len(), 2, "{q0:?}: {:?}", w.model);
        let after = &w.model[1];
        let mu = after
            .mu
            .unwrap_or_else(|| panic!("{q0:?}: {:?}", after.error));
        assert!(after.t >= 300.0, "{q0:?}: {after:?}");
        assert!(
            (w.mu_final / mu - 1.0).abs() <= control::adapt::BAND + 1e-12,
            "{q0:?}: μ ended at {} against the model's {mu}",
            w.mu_final
        );
    }
}

/// `mu = "auto"` steers the arm onto the model's cycle and hands it to the feedback once it
/// repeats itself (`control::target`): from chaotic starts the monitor's first verdict is
/// `periodic` and it never changes, and the pull is gone within a few periods. With
/// `feedback.target = false` the feedback catches the arm alone, as before.
#[test]
fn auto_steers_onto_the_models_cycle_and_hands_it_to_the_feedback() {
    use control::target::{Released, MAX_STEER_PERIODS};
    for q0 in [[-0.5, 2.0, 1.0], [-0.2, 1.8, 1.4], [0.8, 0.9, 1.8]] {
        let mut system = paper(q0, 0.0);
        system.feedback_section_mut().auto = Some(AutoMu::default());
        system.validate().unwrap();
        let w = watch(&system, 60.0, MonitorSettings::default(), &[]);
        let target = w.model[0]
            .target
            .as_ref()
            .unwrap_or_else(|| panic!("{q0:?}: {:?}", w.model));
        assert_eq!(
            target.released,
            Some(Released::OnTheCycle),
            "{q0:?}: {target:?}"
        );
        let released = target.released_at.unwrap();
        assert!(
            released < MAX_STEER_PERIODS,
            "{q0:?}: released at {released} s"
        );
        assert!(target.miss.unwrap() < 1e-4, "{q0:?}: {target:?}");
        // Held by the feedback alone after the release: one verdict, periodic, to the end.
        assert_eq!(w.edges.len(), 1, "{q0:?}: {:?}", w.edges);
        assert_eq!(w.edges[0].to, Verdict::Periodic, "{q0:?}");
        assert!(
            w.edges[0].t <= 8.0,
            "{q0:?}: first verdict at {} s",
            w.edges[0].t
        );
        assert!(w.last.residual < 1e-4, "{q0:?}: {:?}", w.last);
        assert!(w
            .trace
            .iter()
            .all(|p: &PeriodPoint| p.t < released || p.residual < 2e-2));
    }
    let mut alone = paper([-0.5, 2.0, 1.0], 0.0);
    alone.feedback_section_mut().auto = Some(AutoMu::default());
    alone.feedback_section_mut().target = false;
    let w = watch(&alone, 20.0, MonitorSettings::default(), &[]);
    assert!(w.model[0].mu.is_some() && w.model[0].target.is_none());
    assert_eq!(w.edges.first().map(|e| e.to), Some(Verdict::Chaotic));
}

#[test]
fn without_adaptation_the_gain_never_moves() {
    let w = watch(
        &paper([0.3, 1.2, 1.9], 0.2),
        20.0,
        MonitorSettings::default(),
        &[],
    );
    assert!(w.trace.iter().all(|p| p.mu == 0.2));
}

#[test]
fn auto_in_a_config_file_parses_round_trips_and_refuses_bad_gains() {
    let text = "[feedback]\nmu = \"auto\"\ngamma = 1e-4\nmax_mu = 0.3\n";
    let c = Config::parse(text).unwrap();
    assert_eq!(
        c.feedback.auto,
        Some(AutoMu {
            gamma: 1e-4,
            gamma_given: true,
            max_mu: 0.3,
            anchor: None,
        })
    );
    assert_eq!(c.feedback.mu, 0.0);
    assert!(c.law_params().core.feedback_active(c.feedback.t_on + 1.0));
    let again = Config::parse(&c.to_toml()).unwrap();
    assert_eq!(again.feedback, c.feedback);
    assert!(again.feedback.target && !c.to_toml().contains("target"));
    // `target = false` is kept and printed; it tunes "auto" only.
    let off = Config::parse("[feedback]\nmu = \"auto\"\ntarget = false\n").unwrap();
    assert!(!off.feedback.target && off.to_toml().contains("target = false"));
    assert_eq!(
        Config::parse(&off.to_toml()).unwrap().feedback,
        off.feedback
    );
    let plain = Config::parse("[feedback]\nmu = 0.2\n").unwrap();
    assert_eq!((plain.feedback.mu, plain.feedback.auto), (0.2, None));
    for (bad, says) in [
        ("mu = \"fast\"", "\"auto\""),
        ("mu = 0.2\ngamma = 1e-4", "gamma"),
        ("mu = 0.2\ntarget = false", "feedback.target"),
        ("mu = \"auto\"\ntarget = 1", "target"),
        ("mu = \"auto\"\ngamma = 0.5", "feedback.gamma"),
        ("mu = \"auto\"\ngamma = -1", "feedback.gamma"),
        ("mu = \"auto\"\nmax_mu = 0", "feedback.max_mu"),
        ("mu = \"auto\"\nmax_mu = nan", "feedback.max_mu"),
    ] {
        let e = Config::parse(&format!("[feedback]\n{bad}\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains(says), "{bad}: {e}");
        assert!(e.len() < 400, "{e}");
    }
}

#[test]
fn the_spatial_feedback_section_takes_auto_too() {
    let text =
        control::config::spatial::PANDA_PAPER.replace("mu = 1.0", "mu = \"auto\"\nmax_mu = 2.0");
    let c = control::Config::from_robot_toml(&text).unwrap();
    assert_eq!(c.feedback.auto.map(|a| a.max_mu), Some(2.0));
    assert_eq!(c.feedback.mu, 0.0);
}

#[test]
fn the_tick_adapts_mu_only_while_tracking() {
    let mut cfg = paper([0.3, 1.2, 1.9], 0.0);
    cfg.feedback_section_mut().auto = Some(AutoMu::default());
    cfg.feedback_section_mut().t_on = 0.0;
    let mut law = cfg.tick_law::<3>();
    let x = cfg.initial_state::<3>();
    let delayed = control::VecN::<3>::new(1.0, -1.0, 0.5);
    let out = law.evaluate(1.0, &x, &delayed, &mut Default::default());
    assert!(out.period_residual > 0.5);
    law.set_pause(true);
    law.adapt(&out, 1e-3);
    assert_eq!(
        law.feedback().0,
        0.0,
        "a paused (blocked) arm's braking must not raise μ"
    );
    law.set_pause(false);
    law.adapt(&out, 1e-3);
    assert!(law.feedback().0 > 0.0);
}

/// An edit reaches a robot's law as the daemon's live change does: the new block from its time
/// on, and a block made for another kind of arm not at all.
#[test]
fn an_edit_reaches_a_robots_law_and_a_block_for_another_arm_does_not() {
    let robots = &control::system::builtin_robot;
    let panda = System::preset("panda", robots).unwrap();
    let before = panda.feedback().mu;
    let raise = |s: &mut System| {
        s.feedback_section_mut().mu = 0.5;
        Ok(())
    };
    let edit = Edit::of(&panda, 6.0, raise).unwrap();
    let w = watch(&panda, 12.0, MonitorSettings::default(), &[edit]);
    assert!(!w.diverged);
    let (early, late): (Vec<PeriodPoint>, Vec<PeriodPoint>) =
        w.trace.iter().partition(|p| p.t < 6.0);
    assert!(!early.is_empty() && !late.is_empty(), "{:?}", w.trace);
    assert!(early.iter().all(|p| p.mu == before), "{early:?}");
    assert!(late.iter().all(|p| p.mu == 0.5), "{late:?}");
    let paper = System::preset("paper", robots).unwrap();
    let foreign = Edit::of(&paper, 6.0, raise).unwrap();
    let w = watch(&panda, 12.0, MonitorSettings::default(), &[foreign]);
    assert!(w.trace.iter().all(|p| p.mu == before), "{:?}", w.trace);
}
