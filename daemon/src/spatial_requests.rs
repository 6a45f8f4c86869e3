//! `chaosctl set`, `dfc` and `obstacle` on a spatial robot: the same all-or-nothing rule as the
//! planar [`crate::requests`].
//!
//! A change is made to a copy of the running [`SpatialSystem`]'s file and checked against its
//! chain by the same `setup` that guards start-up, and at the daemon's own step, so a client can
//! never set what a config file could not. The keys are the spatial file's (`law.*`,
//! `feedback.*`, `task.*`, `safety.*`), short forms as for the planar arm. These functions do no
//! I/O.

use crate::requests::{num, on_off};
use control::system::SpatialSystem;
use control::System;

/// Keys `set` accepts on a spatial robot, for the error message.
pub const KEYS: &str = "mu (a number, or auto), gamma, max_mu (auto's tuning), tau, t_on, feedback (on|off), projection (full|null-space), kp, kv, alpha, \
                        secondary (none|manipulability|centring|obstacles), obstacle_weight, null_damping, null_speed, \
                        metric (auto|identity|speed), damping_threshold, damping_max, track_loss, task.center X Y Z, task.radius, task.period, \
                        safety (on|off), safety.clearance, safety.velocity_scale, safety.plan (auto|on|off), \
                        safety.plan_hz, safety.trap_time, safety.when_blocked (hold|best-effort)";

/// Applies `KEY VALUE… [KEY VALUE…]` to a copy of `s`; `min_tau` is one control period.
pub fn apply_set(s: &SpatialSystem, args: &str, min_tau: f64) -> Result<SpatialSystem, String> {
    let mut n = s.clone();
    let c = &mut n.config;
    let mut it = args.split_whitespace();
    let mut any = false;
    while let Some(key) = it.next() {
        any = true;
        let k = key
            .trim_start_matches("feedback.")
            .trim_start_matches("law.");
        macro_rules! f {
            () => {
                num(key, it.next())
            };
        }
        if crate::requests::feedback_key(&mut c.feedback, key, k, &mut it)?
            || crate::requests::law_key(&mut c.law, key, k, &mut it)?
        {
            continue;
        }
        match k {
            "task.center" | "center" => c.task.center = Some([f!()?, f!()?, f!()?]),
            "task.radius" | "radius" => c.task.radius = f!()?,
            "task.period" | "period" => c.task.period = f!()?,
            "safety" | "safety.enabled" => c.safety.enabled = on_off(key, it.next())?,
            "safety.clearance" => c.safety.clearance = f!()?,
            "safety.velocity_scale" => c.safety.velocity_scale = f!()?,
            "safety.plan" => {
                c.safety.plan = control::safety::policy::PlanMode::parse(key, it.next())?
            }
            "safety.plan_hz" => c.safety.plan_hz = f!()?,
            "safety.trap_time" => c.safety.trap_time = f!()?,
            "safety.when_blocked" => {
                c.safety.when_blocked = control::safety::policy::WhenBlocked::parse(key, it.next())?
            }
            _ => return Err(format!("unknown key {key:?}; keys: {KEYS}")),
        }
    }
    if !any {
        return Err(format!("set needs KEY VALUE pairs; keys: {KEYS}"));
    }
    let f = &n.config.feedback;
    crate::requests::check_tau(f.tau_for(n.config.task.period), f.capacity(), min_tau)?;
    checked(n, min_tau)
}

/// The new set-up, if it validates against the chain and at the daemon's step.
fn checked(n: SpatialSystem, min_tau: f64) -> Result<SpatialSystem, String> {
    match crate::requests::checked(System::Spatial(Box::new(n)), min_tau)? {
        System::Spatial(s) => Ok(*s),
        System::Planar(_) => Err("not a spatial set-up".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn panda() -> SpatialSystem {
        match rt::robot::preset("panda").unwrap() {
            System::Spatial(s) => *s,
            System::Planar(_) => panic!("panda is spatial"),
        }
    }

    #[test]
    fn set_changes_all_or_nothing() {
        let p = panda();
        let n = apply_set(&p, "mu 0.5 law.kp 30 projection full", 1e-3).unwrap();
        assert_eq!((n.config.feedback.mu, n.config.law.kp), (0.5, 30.0));
        assert_eq!(
            n.config.feedback.projection,
            control::config::ProjectionKind::Full
        );
        for (args, says) in [
            ("mu -1", "feedback.mu"),
            ("mu 1e9", "[0, 100]"),
            ("kp", "missing value"),
            ("bogus 1", "unknown key"),
            ("secondary wobble", "centring"),
            ("task.radius 5", "reach"),
            ("", "KEY VALUE"),
            ("kp 1e9", "law.kp"),
        ] {
            let e = apply_set(&p, args, 1e-3).unwrap_err();
            assert!(e.contains(says), "{args}: {e}");
        }
    }

    #[test]
    fn spheres_are_added_and_removed_in_3d() {
        use crate::requests::{apply_obstacle_add as add, apply_obstacle_remove as remove};
        let p = System::Spatial(Box::new(panda()));
        let n = add(&p, "0.5 0.2 0.4 0.05", 1e-3).unwrap();
        let rows = n.obstacle_rows();
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].center, vec![0.5, 0.2, 0.4]);
        assert!(add(&p, "0.5 0.2 0.05 margin=0.1", 1e-3)
            .unwrap_err()
            .contains("X Y Z RADIUS"));
        let m = add(&p, "0.5 0.2 0.4 0.05 margin=0.2", 1e-3).unwrap();
        assert_eq!(m.obstacle_rows()[0].margin, 0.2);
        assert!(add(&p, "0.5 0.2 nan 0.05", 1e-3).is_err());
        assert!(add(&p, "0.5 0.2 0.4 -1", 1e-3).is_err());
        let back = remove(&n, "1", 1e-3).unwrap();
        assert!(back.obstacle_rows().is_empty());
        assert!(remove(&n, "3", 1e-3).unwrap_err().contains("no obstacle 3"));
    }

    #[test]
    fn dfc_needs_a_gain() {
        use crate::requests::apply_dfc;
        let mut p = System::Spatial(Box::new(panda()));
        let on = apply_dfc(&p, true, 12.0, 1e-3).unwrap();
        let f = on.feedback_section();
        assert_eq!((f.enabled, f.t_on), (true, 12.0));
        p.feedback_section_mut().mu = 0.0;
        assert!(apply_dfc(&p, true, 1.0, 1e-3).unwrap_err().contains("mu"));
        let off = apply_dfc(&p, false, 1.0, 1e-3).unwrap();
        assert!(!off.feedback_section().enabled);
    }

    #[test]
    fn tau_fits_the_delay_line_and_a_control_period() {
        let p = panda();
        let n = apply_set(&p, "tau 1.5", 1e-3).unwrap();
        assert_eq!(n.config.feedback.tau, Some(1.5));
        for (args, says) in [
            ("tau 1e-4", "control period"),
            ("tau 61", "feedback.max_tau = 60"),
            ("max_tau 5", "fixed at start-up"),
        ] {
            let e = apply_set(&p, args, 1e-3).unwrap_err();
            assert!(e.contains(says), "{args}: {e}");
        }
    }
}
