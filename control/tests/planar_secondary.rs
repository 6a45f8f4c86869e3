//! The planar arm takes every secondary task a chain takes: centring on its joint limits and a
//! task the program registered, through the same law and the same config key.

use control::secondary::custom::{self, NullTask, NullTaskInput};
use control::{Config, Secondary, Simulation};

/// η = −q: pulls every joint towards zero; the value is ½|q|².
struct TowardZero;

impl NullTask for TowardZero {
    fn eta(&self, x: &NullTaskInput, eta: &mut [f64]) -> f64 {
        assert_eq!(x.jacobian.len(), 6 * x.q.len(), "a 6 × n Jacobian");
        assert_eq!(x.tip[2], 0.0, "the plane's tool point");
        let mut v = 0.0;
        for (e, q) in eta.iter_mut().zip(x.q) {
            *e = -q;
            v += 0.5 * q * q;
        }
        v
    }
}

static TOWARD_ZERO: TowardZero = TowardZero;

/// The paper's set-up with `law.secondary = secondary`, as a file would say it.
fn paper(secondary: &str) -> Result<Config, control::ConfigError> {
    let text = Config::preset("paper").unwrap().to_toml();
    let key = "secondary = \"manipulability\"";
    assert!(text.contains(key));
    Config::parse(&text.replace(key, &format!("secondary = \"{secondary}\"")))
}

/// Runs 2 s and returns the last secondary value and the final q.
fn run(cfg: &Config) -> (f64, Vec<f64>) {
    let mut sim = Simulation::new(
        cfg.model::<3>(),
        cfg.law_params(),
        cfg.sim.dt,
        cfg.initial_state(),
        cfg.feedback.capacity(),
    );
    let mut value = f64::NAN;
    for _ in 0..2000 {
        value = sim.step().secondary_value;
    }
    (value, sim.state().q.as_slice().to_vec())
}

#[test]
fn a_registered_task_and_centring_drive_the_planar_arm() {
    custom::register(&[("toward-zero", &TOWARD_ZERO)]).unwrap();

    let own = paper("toward-zero").unwrap();
    assert!(matches!(
        own.law_params().core.secondary,
        Secondary::Custom(_)
    ));
    let (value, q) = run(&own);
    let half_q2: f64 = q.iter().map(|v| 0.5 * v * v).sum();
    // The value is the task's at the last step's start, a millisecond before the final q.
    assert!(
        (value - half_q2).abs() < 0.05 * half_q2.max(1e-3),
        "{value} vs {half_q2}"
    );
    let (_, q_none) = run(&paper("none").unwrap());
    assert_ne!(q, q_none, "the task moved the self-motion");

    // Centring needs the joints' limits, and pulls each joint to its range's middle.
    let e = paper("centring").unwrap_err().to_string();
    assert!(e.contains("safety.q_min and safety.q_max"), "{e}");
    let mut cfg = paper("none").unwrap();
    cfg.law.secondary = control::config::SecondaryKind::Centring;
    cfg.safety.q_min = Some(vec![-3.0; 3]);
    cfg.safety.q_max = Some(vec![3.0; 3]);
    cfg.validate().unwrap();
    assert_eq!(cfg.law_params().core.secondary, Secondary::Centring);
    let (c, q) = run(&cfg);
    let expected: f64 = q.iter().map(|v| 0.5 * (v / 6.0) * (v / 6.0)).sum();
    assert!(
        c > 0.0 && (c - expected).abs() < 0.05 * expected,
        "{c} vs {expected}"
    );

    let e = paper("manipulabilty").unwrap_err().to_string();
    assert!(
        e.contains("law.secondary") && e.contains("toward-zero"),
        "{e}"
    );
}
