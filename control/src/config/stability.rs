//! Parameters that cannot be stable at a given step: refused before anything runs.
//!
//! The task error e = p_d − p obeys ë + K_v ė + K_p e = 0 only in continuous time. Sampled every
//! dt with the command held over the period, it is the map
//! (e, ė) ↦ (e + dt ė + dt²/2 u, ė + dt u), u = −K_p e − K_v ė, whose characteristic polynomial is
//! z² − (2 − K_v dt − K_p dt²/2) z + (1 − K_v dt + K_p dt²/2). Jury's test puts its roots inside the
//! unit circle iff K_p dt² > 0, K_v dt < 2 and K_p dt² < 2 K_v dt. chaosd keeps a factor of two
//! from that edge (the measurement is up to a period old, and RK4 offline has a similar bound):
//! K_v·dt < 1 and K_p·dt² < K_v·dt. The same margin applies to the safety filter's barrier gains.
//! A task whose period is only a few control periods cannot be followed either, and a circle
//! outside the annulus the arm can reach would make the law chase it into a singularity.

use crate::basics::excerpt;
use crate::basics::ConfigError;
use crate::config::{Config, ModelKind};

/// K_v·dt (and every first-order gain × dt) must stay below this.
pub const MAX_GAIN_DT: f64 = 1.0;
/// The task period must span at least this many steps.
pub const MIN_TASK_STEPS: f64 = 50.0;

fn refuse(field: &str, value: impl std::fmt::Debug, expected: String) -> ConfigError {
    ConfigError::Invalid {
        field: field.to_string(),
        value: excerpt(&format!("{value:?}")),
        expected,
    }
}

/// A number for a message: fixed-point in the range a person reads, scientific outside it, so
/// that 1e308 prints in a few bytes rather than 309 digits.
fn num(x: f64) -> String {
    if x == 0.0 || (1e-3..1e6).contains(&x.abs()) {
        format!("{x:.3}")
    } else {
        format!("{x:.3e}")
    }
}

/// Checks `cfg` against a loop of step `dt`; `step` names where dt comes from (for messages).
pub fn check(cfg: &Config, dt: f64, step: &str) -> Result<(), ConfigError> {
    let c = &cfg.law;
    let s = &cfg.safety;
    let barriers = [("safety.k1", s.k1), ("safety.k_rate", s.k_rate)];
    check_sampled(
        &Sampled {
            prefix: "law",
            kp: c.kp,
            kv: c.kv,
            period: cfg.period(),
            barriers: if s.enabled { &barriers } else { &[] },
        },
        dt,
        step,
    )?;
    check_reach(cfg)
}

/// What a sampled loop's stability depends on, for either arm: the law's gains (named
/// `{prefix}.kp`, `{prefix}.kv`), the task period and the safety filter's first-order barrier
/// gains (empty when the filter is off).
pub struct Sampled<'a> {
    pub prefix: &'a str,
    pub kp: f64,
    pub kv: f64,
    pub period: f64,
    pub barriers: &'a [(&'a str, f64)],
}

/// The rules of the module doc at step `dt` (`step` names where dt comes from).
pub fn check_sampled(g: &Sampled, dt: f64, step: &str) -> Result<(), ConfigError> {
    if g.kv * dt >= MAX_GAIN_DT {
        return Err(refuse(
            &format!("{}.kv", g.prefix),
            g.kv,
            format!(
                "K_v·dt = {} at {step}: must be < {MAX_GAIN_DT} (the sampled error dynamics are unstable from K_v·dt = 2; chaosd keeps a factor 2), so K_v < {}",
                num(g.kv * dt),
                num(MAX_GAIN_DT / dt)
            ),
        ));
    }
    if g.kp > 0.0 && g.kp * dt * dt >= g.kv * dt {
        return Err(refuse(
            &format!("{}.kp", g.prefix),
            g.kp,
            format!(
                "K_p·dt² = {:.3e} at {step}: must be < K_v·dt = {:.3e} (unstable from 2·K_v·dt; chaosd keeps a factor 2), so K_p < K_v/dt = {}",
                g.kp * dt * dt,
                g.kv * dt,
                num(g.kv / dt)
            ),
        ));
    }
    let min_period = MIN_TASK_STEPS * dt;
    if g.period < min_period {
        return Err(refuse(
            "task.period",
            g.period,
            format!(
                "must span at least {MIN_TASK_STEPS} control steps at {step}: ≥ {min_period} s"
            ),
        ));
    }
    for &(name, k) in g.barriers {
        if k * dt >= MAX_GAIN_DT {
            return Err(refuse(
                name,
                k,
                format!(
                    "{name}·dt = {} at {step}: must be < {MAX_GAIN_DT}, so < {}",
                    num(k * dt),
                    num(MAX_GAIN_DT / dt)
                ),
            ));
        }
    }
    Ok(())
}

/// The circle must lie inside the annulus reachable from joint 1 (fixed base; the floating base
/// moves, and its loss of reach is reported at run time instead).
fn check_reach(cfg: &Config) -> Result<(), ConfigError> {
    // A robot's path is checked against its chain's reach when its set-up is built.
    let Some(p) = cfg.planar() else {
        return Ok(());
    };
    if p.arm.model != ModelKind::Fixed {
        return Ok(());
    }
    let l = &p.arm.links;
    let reach: f64 = l.iter().sum();
    let inner = (2.0 * l.iter().cloned().fold(0.0, f64::max) - reach).max(0.0);
    let [x, y] = p.task.center;
    let d = x.hypot(y);
    let r = p.task.radius;
    if d + r >= reach || d - r <= inner {
        return Err(refuse(
            "task.center",
            [x, y],
            format!(
                "the circle (radius {} m) spans {} … {} m from joint 1; the arm reaches only {inner:.3} … {reach:.3} m (robot.links)",
                num(r),
                num((d - r).max(0.0)),
                num(d + r)
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refused(edit: impl FnOnce(&mut Config), dt: f64) -> String {
        let mut c = Config::preset("demo").unwrap();
        edit(&mut c);
        check(&c, dt, "daemon.rate_hz = 1000")
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn runaway_parameters_are_refused_with_the_limit_named() {
        let dt = 1e-3;
        for p in crate::config::PRESETS {
            check(&Config::preset(p).unwrap(), dt, "1 kHz").unwrap();
        }
        let e = refused(|c| c.law.kv = 3000.0, dt);
        assert!(e.contains("law.kv") && e.contains("K_v < 1000"), "{e}");
        let e = refused(|c| (c.law.kp, c.law.kv) = (1e6, 1e6), dt);
        assert!(e.contains("law.kv"), "{e}");
        let e = refused(|c| (c.law.kp, c.law.kv) = (1e5, 50.0), dt);
        assert!(
            e.contains("law.kp") && e.contains("K_p < K_v/dt = 50000"),
            "{e}"
        );
        let e = refused(|c| c.planar_mut().unwrap().task.period = 0.01, dt);
        assert!(e.contains("task.period") && e.contains("0.05 s"), "{e}");
        let e = refused(|c| c.planar_mut().unwrap().task.center = [1e5, 1e5], dt);
        assert!(
            e.contains("task.center") && e.contains("reaches only"),
            "{e}"
        );
        for huge in [1e308, -1e308, f64::MAX] {
            let e = refused(|c| c.planar_mut().unwrap().task.center = [huge, huge], dt);
            assert!(e.len() < 400 && e.contains("reaches only"), "{e}");
            let e = refused(|c| c.law.kv = huge.abs(), dt);
            assert!(e.len() < 400 && e.contains("law.kv"), "{e}");
        }
        let e = refused(|c| c.planar_mut().unwrap().task.center = [0.1, 0.0], dt);
        assert!(e.contains("task.center"), "{e}");
        let e = refused(|c| c.safety.k_rate = 2000.0, dt);
        assert!(e.contains("safety.k_rate"), "{e}");
        // The limits scale with the rate: kv = 3000 is fine at 10 kHz.
        let mut c = Config::preset("demo").unwrap();
        c.law.kv = 3000.0;
        check(&c, 1e-4, "10 kHz").unwrap();
    }

    #[test]
    fn config_files_get_the_same_checks() {
        let e = Config::parse("[control]\nkv = 3000\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("control.kv") && e.contains("sim.dt"), "{e}");
        let e = Config::parse("[safety]\nk0 = 400\nk1 = 20\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("safety.k1") && e.contains("real roots"), "{e}");
        let e = Config::parse("[safety]\nq_min = [0, 0, 0]\nq_max = [1, -1, 1]\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("safety.q_min[1]"), "{e}");
        let e = Config::parse("[safety]\nqd_max = [1, 2]\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("safety.qd_max") && e.contains("3 entries"),
            "{e}"
        );
        let c = Config::parse("[safety]\nq_max = [inf, 2.0, 2.0]\nqd_max = [5, 6, 7]\n").unwrap();
        let p = c.safety.params(3);
        assert_eq!(
            (p.q_max[0], p.q_max[1], p.qd_max[2]),
            (f64::INFINITY, 2.0, 7.0)
        );
        assert_eq!(Config::parse(&c.to_toml()).unwrap(), c);
    }
}
