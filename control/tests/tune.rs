//! The gain from the model ([`control::tune`]) on both arms: the chosen gain is the best the
//! analysis found, a simulation measures the convergence its multiplier promised, and set-ups
//! without a cycle for the feedback to stabilise are refused with the reason.

use control::analysis::{orbit_stability, StabilitySpec};
use control::system::builtin_robot;
use control::tune::{choose_gain, Seed, TuneError, TuneSpec, KNEE};
use control::{Config, System};

fn system(preset: &str) -> System {
    System::preset(preset, &builtin_robot).unwrap()
}

#[test]
fn the_planar_gain_is_the_knee_of_the_scan_and_a_run_on_the_cycle_converges_as_promised() {
    let s = system("paper");
    let spec = TuneSpec::of(&s);
    let c = choose_gain(&s, None, &spec).unwrap();
    assert!(c.mu > 0.0 && c.mu <= spec.max_mu, "{}", c.why());
    assert!(c.multiplier < 0.9, "{}", c.why());
    // The cycle sweeps at about 11 rad/s RMS: the model's γ puts the correction's band edge
    // there ([`control::adapt::model_gamma`]).
    assert!((5.0..20.0).contains(&c.speed), "{} rad/s", c.speed);
    assert_eq!(Some(c.gamma), control::adapt::model_gamma(c.mu, c.speed));
    // The fastest is the best of every gain tried; the choice is the smallest gain with KNEE of
    // its rate, below it on the plateau (the paper's: 0.11 against 0.23).
    let target = KNEE * c.fastest.rate;
    for p in &c.scanned {
        assert!(
            c.fastest.multiplier <= p.multiplier,
            "{p:?} beats {}",
            c.why()
        );
        if p.mu > 0.0 && p.mu < c.mu {
            assert!(
                p.rate > target,
                "{p:?} is smaller and fast enough: {}",
                c.why()
            );
        }
    }
    assert!(
        c.rate <= target && c.mu < 0.75 * c.fastest.mu,
        "{}",
        c.why()
    );
    // More than the grid: the search refined between steps.
    let grid = spec.grid_gains();
    assert!(c.scanned.len() > spec.grid + 1, "{:?}", c.scanned);
    assert!(
        c.scanned
            .iter()
            .any(|p| p.mu > 0.0 && !grid.contains(&p.mu)),
        "no gain off the grid: {:?}",
        c.scanned
    );
    // The paper's elliptic orbit: |ρ| = 1 at μ = 0, which the feedback damps.
    let at_zero = c.scanned.iter().find(|p| p.mu == 0.0).unwrap();
    assert!((at_zero.multiplier - 1.0).abs() < 1e-3, "{at_zero:?}");
    // A simulation started on the cycle with its own history, at the chosen gain: the offset's
    // measured decay on the section is the rate the multiplier promised.
    let mut cfg = Config::preset("paper").unwrap();
    cfg.feedback.mu = c.mu;
    let spec = StabilitySpec {
        duration: 40.0,
        ..StabilitySpec::default()
    };
    let p = cfg.law_params();
    let run = orbit_stability(&cfg.model::<3>(), &p, cfg.sim.dt, &c.orbit, &spec).unwrap();
    let measured = run.section_rate.expect("a measurable decay");
    assert!(
        (measured - c.rate).abs() < 0.01,
        "measured {measured:.4}/s against the promised {:.4}/s",
        c.rate
    );
    // Seeded with the cycle's own point (the daemon's newest return), Newton starts there.
    let again = choose_gain(&s, Some(&c.orbit.coords()), &spec_quick(&s)).unwrap();
    assert_eq!(again.seed, Seed::Given);
    assert!((again.orbit.coords()[0] - c.orbit.coords()[0]).abs() < 1e-8);
}

/// From the planar start (0.3, 1.2, 1.9) the seeding runs at half the bound and at the bound
/// end near a cycle no gain makes stable (above the best gain the cycle's basin shrinks); the
/// search goes on to a run at a smaller gain, which ends on a cycle the feedback can hold, so
/// the daemon steers this start from the beginning as it does the others.
#[test]
fn a_start_whose_first_seeding_runs_miss_gets_a_gain_from_a_smaller_one() {
    let mut cfg = Config::preset("paper").unwrap();
    cfg.sim.q0 = Some(vec![0.3, 1.2, 1.9]);
    let s = System::Planar(cfg);
    let spec = TuneSpec::of(&s);
    let c = choose_gain(&s, None, &spec).unwrap();
    let Seed::Settled { mu } = c.seed else {
        panic!("seeded by {:?}", c.seed);
    };
    assert!(
        mu < 0.5 * spec.seed_mu + 1e-12,
        "seeded at μ = {mu}: {}",
        c.why()
    );
    assert!(c.multiplier < 0.9 && c.mu > 0.0, "{}", c.why());
}

/// A generous bound must not hide the small gains: with `max_mu` = 100 the paper's arm still gets
/// the gain near 0.23 that the default bound finds (a linear grid stepped 12.5 over it and chose
/// 1.8, ×0.87 a period against ×0.73).
#[test]
fn a_generous_bound_finds_the_same_gain_as_the_default_one() {
    let s = system("paper");
    let narrow = choose_gain(&s, None, &TuneSpec::of(&s)).unwrap();
    let wide = TuneSpec {
        max_mu: 100.0,
        ..TuneSpec::of(&s)
    };
    let c = choose_gain(&s, None, &wide).unwrap();
    assert!(
        (c.mu - narrow.mu).abs() < 0.05 && c.multiplier < narrow.multiplier + 0.01,
        "bound 100: {}; default bound: {}",
        c.why(),
        narrow.why()
    );
}

fn spec_quick(s: &System) -> TuneSpec {
    TuneSpec {
        grid: 4,
        refine: 3,
        ..TuneSpec::of(s)
    }
}

/// The Panda's cycle converges without feedback too (×0.27 a period, the centring's damping);
/// the feedback speeds it up, and the knee lands near the preset's hand-picked 0.25.
#[test]
fn the_pandas_gain_keeps_most_of_the_fastest_rate_near_its_presets_gain() {
    let s = system("panda");
    let preset_mu = s.feedback().mu;
    let c = choose_gain(&s, None, &spec_quick(&s)).unwrap();
    let at_zero = c.scanned.iter().find(|p| p.mu == 0.0).unwrap();
    assert!(
        c.multiplier < at_zero.multiplier && c.rate < -0.7,
        "{}",
        c.why()
    );
    assert!(c.rate <= KNEE * c.fastest.rate, "{}", c.why());
    assert!(
        (c.mu - preset_mu).abs() < 0.1 && c.fastest.mu > c.mu,
        "{} against the preset's μ = {preset_mu}",
        c.why()
    );
    assert!(matches!(c.seed, Seed::Settled { .. }), "{:?}", c.seed);
    // The correction's γ is scaled to this arm's cycle, slower than the planar one's, so it is
    // far above the planar default (which would move μ by 5e-3 at the Panda's chaotic residual).
    assert!((0.5..2.0).contains(&c.speed), "{} rad/s", c.speed);
    assert_eq!(Some(c.gamma), control::adapt::model_gamma(c.mu, c.speed));
    assert!(
        c.gamma > 10.0 * control::adapt::DEFAULT_GAMMA,
        "γ = {}",
        c.gamma
    );
    // A seed of the wrong length or with a NaN is no seed: the search runs the set-up instead.
    let nan = [f64::NAN; 14];
    let c = choose_gain(&s, Some(&nan), &spec_quick(&s)).unwrap();
    assert!(matches!(c.seed, Seed::Settled { .. }), "{:?}", c.seed);
}

#[test]
fn set_ups_without_a_cycle_for_the_feedback_are_refused_with_the_reason() {
    let said = |s: &System| match choose_gain(s, None, &spec_quick(s)) {
        Err(TuneError::Invalid(e)) => e,
        other => panic!("{other:?}"),
    };
    let floating = system("paper-floating");
    assert!(
        said(&floating).contains("floating base"),
        "{}",
        said(&floating)
    );
    let mut off = system("paper");
    off.feedback_section_mut().enabled = false;
    assert!(said(&off).contains("feedback is off"), "{}", said(&off));
    let mut other_tau = system("paper");
    other_tau.feedback_section_mut().tau = Some(0.7);
    assert!(said(&other_tau).contains("differs from the task period"));
    let s = system("paper");
    let bad = TuneSpec {
        max_mu: f64::NAN,
        ..TuneSpec::of(&s)
    };
    assert!(matches!(
        choose_gain(&s, None, &bad),
        Err(TuneError::Invalid(_))
    ));
}

/// γ is the model's unless the file (or a live `set`) gives one: a file that leaves it out
/// prints without it, so a saved live state or `chaosctl config` does not freeze the stand-in.
#[test]
fn the_models_gamma_replaces_the_stand_in_but_never_the_users() {
    let mut cfg = Config::preset("paper").unwrap();
    let f = &mut cfg.feedback;
    control::adapt::set_live("mu", Some("auto"), &mut f.mu, &mut f.auto).unwrap();
    let s = System::Planar(cfg);
    assert!(!s.to_toml().contains("gamma"));
    let model = s.with_model_gain(0.11, 5e-5).unwrap();
    assert_eq!(model.feedback().auto.unwrap().gamma, 5e-5);
    assert!(!model.to_toml().contains("gamma"));
    let mut given = s.clone();
    let f = given.feedback_section_mut();
    control::adapt::set_live("gamma", Some("1e-4"), &mut f.mu, &mut f.auto).unwrap();
    let kept = given.with_model_gain(0.11, 5e-5).unwrap();
    assert_eq!(kept.feedback().auto.unwrap().gamma, 1e-4);
    assert!(kept.to_toml().contains("gamma = 0.0001"));
}
