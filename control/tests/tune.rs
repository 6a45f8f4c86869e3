//! The gain from the model ([`control::tune`]) on both arms: the chosen gain is the best the
//! analysis found, a simulation measures the convergence its multiplier promised, and set-ups
//! without a cycle for the feedback to stabilise are refused with the reason.

use control::analysis::{orbit_stability, StabilitySpec};
use control::system::builtin_robot;
use control::tune::{choose_gain, Seed, TuneError, TuneSpec};
use control::{Config, System};

fn system(preset: &str) -> System {
    System::preset(preset, &builtin_robot).unwrap()
}

#[test]
fn the_planar_gain_is_the_scans_best_and_a_run_on_the_cycle_converges_as_promised() {
    let s = system("paper");
    let spec = TuneSpec::of(&s);
    let c = choose_gain(&s, None, &spec).unwrap();
    assert!(c.mu > 0.0 && c.mu <= spec.max_mu, "{}", c.why());
    assert!(c.multiplier < 0.9, "{}", c.why());
    // The best of every gain tried, and more than the grid: the search refined between steps.
    for p in &c.scanned {
        assert!(c.multiplier <= p.multiplier, "{p:?} beats {}", c.why());
    }
    let step = spec.max_mu / spec.grid as f64;
    assert!(c.scanned.len() > spec.grid + 1, "{:?}", c.scanned);
    assert!(
        c.scanned
            .iter()
            .any(|p| (p.mu / step - (p.mu / step).round()).abs() > 1e-6),
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

fn spec_quick(s: &System) -> TuneSpec {
    TuneSpec {
        grid: 4,
        refine: 3,
        ..TuneSpec::of(s)
    }
}

#[test]
fn the_pandas_gain_converges_faster_than_its_presets() {
    let s = system("panda");
    let preset_mu = s.feedback().mu;
    let c = choose_gain(&s, None, &spec_quick(&s)).unwrap();
    let at_preset = c.scanned.iter().min_by(|a, b| {
        (a.mu - preset_mu)
            .abs()
            .total_cmp(&(b.mu - preset_mu).abs())
    });
    assert!(c.multiplier < 1.0 && c.rate < -0.75, "{}", c.why());
    assert!(
        c.multiplier <= at_preset.unwrap().multiplier,
        "{} against {at_preset:?}",
        c.why()
    );
    assert!(matches!(c.seed, Seed::Settled { .. }), "{:?}", c.seed);
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
