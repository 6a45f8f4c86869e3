//! Turning control requests into a new configuration, all or nothing.
//!
//! Every change is applied to a copy of the running [`Config`] and then checked by the same
//! `validate` that guards start-up, so a client can never set what a config file could not. Only
//! a fully valid result leaves this module; the reporter then hands the loop a new `LawParams`
//! block, which the loop swaps in at a tick boundary. These functions do no I/O.

use control::config::{FeedbackSection, LawSection, SecondaryKind};
use control::safety::policy::{PlanMode, WhenBlocked};
use control::safety::SafetySection;
use control::System;
use std::path::{Component, Path, PathBuf};

/// Keys `set` accepts (short and dotted forms), for the error message. A key of the other
/// arm's file is refused by the validation, with the reason.
pub const KEYS: &str = "mu (a number, or auto), gamma, max_mu (auto's tuning), tau, t_on, feedback (on|off), projection (full|null-space), kp, kv, alpha, \
                        secondary (none|manipulability|centring|obstacles), damping_threshold, damping_max, track_loss, \
                        w1, w2 (the planar arm), obstacle_weight, null_damping, null_speed, metric (auto|identity|speed) (a robot), \
                        task.center X Y (the planar arm) or X Y Z (a robot), task.radius, task.period, safety (on|off), safety.clearance, \
                        safety.qdd_max (one value for all joints, or one per joint), safety.velocity_scale, \
                        safety.qd_max, safety.q_min, safety.q_max (the planar arm; one per joint, inf = unlimited), safety.k0, safety.k1, \
                        safety.push_out_speed, safety.k_rate, safety.guard_time, safety.guard_tracking_error, safety.guard_growth_time, \
                        safety.plan (auto|on|off), safety.plan_hz, safety.trap_time, safety.when_blocked (hold|best-effort)";

pub(crate) fn on_off(key: &str, v: Option<&str>) -> Result<bool, String> {
    match v {
        Some("on" | "true" | "1") => Ok(true),
        Some("off" | "false" | "0") => Ok(false),
        other => Err(format!("{key}: {other:?} is not on or off")),
    }
}

/// `n` numbers (a value per joint) for `key`; ±inf allowed where `inf_ok`.
fn nums<'a>(
    key: &str,
    it: &mut impl Iterator<Item = &'a str>,
    n: usize,
    inf_ok: bool,
) -> Result<Vec<f64>, String> {
    (0..n)
        .map(|_| {
            let v = it
                .next()
                .ok_or_else(|| format!("{key}: needs {n} values, one per joint"))?;
            match v.parse::<f64>() {
                Ok(x) if x.is_finite() || (inf_ok && x.is_infinite()) => Ok(x),
                _ => Err(format!("{key}: {v:?} is not a finite number")),
            }
        })
        .collect()
}

/// One limit for all joints (`KEY X`) or one per joint (`KEY X1 … Xn`).
fn limit<'a>(
    key: &str,
    it: &mut std::iter::Peekable<impl Iterator<Item = &'a str>>,
    n: usize,
) -> Result<control::safety::config::Limit, String> {
    let first = num(key, it.next())?;
    let more = it.peek().is_some_and(|v| v.parse::<f64>().is_ok());
    if !more {
        return Ok(control::safety::config::Limit::All(first));
    }
    let mut v = vec![first];
    v.extend(nums(key, it, n - 1, false).map_err(|_| {
        format!("{key}: give one value for all joints or {n} values, one per joint")
    })?);
    Ok(control::safety::config::Limit::Each(v))
}

/// `projection full|null-space`, for every arm.
pub(crate) fn projection(
    key: &str,
    v: Option<&str>,
) -> Result<control::config::ProjectionKind, String> {
    v.and_then(control::config::ProjectionKind::parse)
        .ok_or_else(|| format!("{key}: {v:?} is not full or null-space"))
}

pub(crate) fn num(key: &str, v: Option<&str>) -> Result<f64, String> {
    control::basics::live_number(key, v).map_err(String::from)
}

/// Applies `KEY VALUE… [KEY VALUE…]` to a copy of the running set-up, on any arm, and
/// validates the result: the same keys as the file's (`law.*`, `feedback.*`, `task.*`,
/// `safety.*`; the short forms without the section), checked by the same validation that guards
/// start-up and at the daemon's own step. `min_tau` is one control period; `feedback.max_tau`,
/// the delay line's capacity, was fixed at start-up.
pub fn apply_set(system: &System, args: &str, min_tau: f64) -> Result<System, String> {
    let mut n = system.clone();
    let joints = n.n();
    let mut it = args.split_whitespace().peekable();
    if it.peek().is_none() {
        return Err(format!("set needs KEY VALUE pairs; keys: {KEYS}"));
    }
    while let Some(key) = it.next() {
        let k = key
            .trim_start_matches("feedback.")
            .trim_start_matches("law.")
            .trim_start_matches("control.");
        if feedback_key(n.feedback_section_mut(), key, k, &mut it)?
            || law_key(n.law_section_mut(), key, k, &mut it)?
            || safety_key(n.safety_section_mut(), key, &mut it, joints)?
        {
            continue;
        }
        match k {
            "task.center" | "center" => {
                let c = nums(key, &mut it, n.obstacle_dims(), false)
                    .map_err(|_| format!("{key}: needs {} numbers", n.obstacle_dims()))?;
                n.set_task_center(&c).map_err(|e| e.to_string())?
            }
            "task.radius" | "radius" => *n.task_circle_mut().0 = num(key, it.next())?,
            "task.period" | "period" => *n.task_circle_mut().1 = num(key, it.next())?,
            _ => return Err(format!("unknown key {key:?}; keys: {KEYS}")),
        }
    }
    let f = n.feedback_section();
    check_tau(f.tau_for(n.period()), f.capacity(), min_tau)?;
    checked(n, min_tau)
}

/// Applies `key` to `[safety]` if it is one of its keys, the same on every arm (the planar
/// arm's own limits are refused on a robot when the set-up is validated); false if it is not.
fn safety_key<'a>(
    s: &mut SafetySection,
    key: &str,
    it: &mut std::iter::Peekable<impl Iterator<Item = &'a str>>,
    joints: usize,
) -> Result<bool, String> {
    match key {
        "safety" | "safety.enabled" => s.enabled = on_off(key, it.next())?,
        "safety.clearance" => s.clearance = num(key, it.next())?,
        "safety.qd_max" => s.qd_max = Some(limit(key, it, joints)?),
        "safety.qdd_max" => s.qdd_max = Some(limit(key, it, joints)?),
        "safety.q_min" => s.q_min = Some(nums(key, it, joints, true)?),
        "safety.q_max" => s.q_max = Some(nums(key, it, joints, true)?),
        "safety.velocity_scale" => s.velocity_scale = num(key, it.next())?,
        "safety.k0" => s.k0 = num(key, it.next())?,
        "safety.k1" => s.k1 = num(key, it.next())?,
        "safety.push_out_speed" => s.push_out_speed = num(key, it.next())?,
        "safety.k_rate" => s.k_rate = num(key, it.next())?,
        "safety.guard_time" => s.guard_time = num(key, it.next())?,
        "safety.guard_tracking_error" => s.guard_tracking_error = num(key, it.next())?,
        "safety.guard_growth_time" => s.guard_growth_time = num(key, it.next())?,
        "safety.plan" => s.plan = PlanMode::parse(key, it.next())?,
        "safety.plan_hz" => s.plan_hz = num(key, it.next())?,
        "safety.trap_time" => s.trap_time = num(key, it.next())?,
        "safety.when_blocked" => s.when_blocked = WhenBlocked::parse(key, it.next())?,
        _ => return Ok(false),
    }
    Ok(true)
}

/// Applies `key` (`k` without its section) to `[feedback]` if it is one of its keys, the same
/// on every arm; false if it is not.
pub(crate) fn feedback_key<'a>(
    f: &mut FeedbackSection,
    key: &str,
    k: &str,
    it: &mut impl Iterator<Item = &'a str>,
) -> Result<bool, String> {
    match k {
        "mu" | "gamma" | "max_mu" => {
            control::adapt::set_live(k, it.next(), &mut f.mu, &mut f.auto)?
        }
        "tau" => f.tau = Some(num(key, it.next())?),
        "t_on" => f.t_on = num(key, it.next())?,
        "feedback" | "enabled" | "dfc" => f.enabled = on_off(key, it.next())?,
        "projection" => f.projection = projection(key, it.next())?,
        "max_tau" => {
            return Err(format!(
                "feedback.max_tau = {} s is the delay-line capacity, fixed at start-up",
                f.capacity()
            ))
        }
        _ => return Ok(false),
    }
    Ok(true)
}

/// Applies `key` to `[law]` if it is one of its keys, the same on every arm (a key of the other
/// arm's law is refused when the set-up is validated); false if it is not.
pub(crate) fn law_key<'a>(
    l: &mut LawSection,
    key: &str,
    k: &str,
    it: &mut impl Iterator<Item = &'a str>,
) -> Result<bool, String> {
    match k {
        "kp" => l.kp = num(key, it.next())?,
        "kv" => l.kv = num(key, it.next())?,
        "alpha" => l.alpha = num(key, it.next())?,
        "w1" => l.w1 = Some(num(key, it.next())?),
        "w2" => l.w2 = Some(num(key, it.next())?),
        "obstacle_weight" => l.obstacle_weight = Some(num(key, it.next())?),
        "null_damping" => l.null_damping = num(key, it.next())?,
        "null_speed" => l.null_speed = num(key, it.next())?,
        "metric" => l.metric = word(key, it.next(), &["auto", "identity", "speed"])?,
        "damping_threshold" => l.damping_threshold = num(key, it.next())?,
        "damping_max" => l.damping_max = num(key, it.next())?,
        "track_loss" => l.track_loss = num(key, it.next())?,
        "secondary" => {
            l.secondary = match it.next() {
                Some(name) if SecondaryKind::from(name).task().is_some() => name.into(),
                other => {
                    let names = control::Secondary::names();
                    return Err(format!("{key}: {other:?} is not {names}"));
                }
            }
        }
        _ => return Ok(false),
    }
    Ok(true)
}

/// A word out of `allowed` for `key`.
pub(crate) fn word(key: &str, v: Option<&str>, allowed: &[&str]) -> Result<String, String> {
    match v {
        Some(w) if allowed.contains(&w) => Ok(w.to_string()),
        other => Err(format!(
            "{key}: {other:?} is not one of {}",
            allowed.join(", ")
        )),
    }
}

/// A new τ must fit the delay line the daemon sized at start-up and span a control period.
pub(crate) fn check_tau(tau: f64, capacity: f64, min_tau: f64) -> Result<(), String> {
    if tau > capacity {
        return Err(format!(
            "feedback.tau = {tau} s exceeds the delay-line capacity feedback.max_tau = {capacity} s fixed at start-up"
        ));
    }
    if tau < min_tau {
        return Err(format!(
            "feedback.tau = {tau} s is shorter than one control period ({min_tau} s)"
        ));
    }
    Ok(())
}

/// Feedback on from controller time `now`, or off, on any arm; `min_tau` is one control period.
pub fn apply_dfc(system: &System, on: bool, now: f64, min_tau: f64) -> Result<System, String> {
    let mut n = system.clone();
    let f = n.feedback_section_mut();
    f.enabled = on;
    if on {
        f.t_on = now.max(0.0);
        if f.mu == 0.0 && f.auto.is_none() {
            return Err(
                "feedback.mu is 0: set a gain first (chaosctl set mu 0.2, or mu auto)".into(),
            );
        }
    }
    checked(n, min_tau)
}

/// An obstacle's positional numbers and its margin: `margin=M` anywhere, or one more number
/// after the `positions` (the older form), else 0.1 m.
pub(crate) fn obstacle_args<'a>(
    args: &'a str,
    positions: usize,
    usage: &str,
) -> Result<(Vec<&'a str>, f64), String> {
    let mut v: Vec<&str> = Vec::new();
    let mut margin = None;
    for w in args.split_whitespace() {
        match w.strip_prefix("margin=") {
            Some(m) => margin = Some(num("margin", Some(m))?),
            None => v.push(w),
        }
    }
    if margin.is_none() && v.len() == positions + 1 {
        margin = Some(num("margin", v.pop())?);
    }
    if v.len() != positions {
        return Err(format!(
            "obstacle add needs {usage}, got {} numbers",
            v.len()
        ));
    }
    Ok((v, margin.unwrap_or(0.1)))
}

/// `X Y RADIUS [MARGIN]` on the planar arm, `X Y Z RADIUS [MARGIN]` on a robot (m).
pub fn apply_obstacle_add(system: &System, args: &str, min_tau: f64) -> Result<System, String> {
    let dims = system.obstacle_dims();
    let usage = match dims {
        2 => "X Y RADIUS [MARGIN] (m) for the planar arm",
        _ => "X Y Z RADIUS [MARGIN] (m) on a spatial robot",
    };
    let (v, margin) = obstacle_args(args, dims + 1, usage)?;
    let center = v[..dims]
        .iter()
        .zip(["x", "y", "z"])
        .map(|(w, name)| num(name, Some(w)))
        .collect::<Result<Vec<_>, _>>()?;
    let radius = num("radius", Some(v[dims]))?;
    let mut n = system.clone();
    n.add_obstacle(&center, radius, margin)
        .map_err(|e| e.to_string())?;
    checked(n, min_tau)
}

/// `obstacle rm N`: the obstacle's number as `obstacle ls`, status and every message give it,
/// counted from 1; its 0-based place in a list of `count`.
pub(crate) fn obstacle_number(args: &str, count: usize) -> Result<usize, String> {
    let n: usize = args.trim().parse().map_err(|_| {
        format!(
            "obstacle rm needs an obstacle's number (obstacle ls), got {:?}",
            args.trim()
        )
    })?;
    match n {
        0 => Err("obstacles are numbered from 1, as obstacle ls lists them".into()),
        n if n > count => Err(format!("no obstacle {n}: there are {count}")),
        n => Ok(n - 1),
    }
}

/// `N`, as listed by `obstacle ls` (from 1).
pub fn apply_obstacle_remove(system: &System, args: &str, min_tau: f64) -> Result<System, String> {
    let mut n = system.clone();
    let i = obstacle_number(args, n.obstacle_rows().len())?;
    n.remove_obstacle(i);
    checked(n, min_tau).map_err(|e| {
        format!("{e} (set secondary to none or manipulability before removing the last obstacle)")
    })
}

/// A changed set-up, if it validates and runs at the daemon's step (`min_tau`, one period).
pub(crate) fn checked(n: System, min_tau: f64) -> Result<System, String> {
    n.validate().map_err(|e| e.to_string())?;
    let step = format!("the daemon's {:.0} Hz", 1.0 / min_tau);
    n.check_step(min_tau, &step).map_err(|e| e.to_string())?;
    Ok(n)
}

/// Where a recording named by a client goes: inside `out_dir`, never outside it.
pub fn recording_path(out_dir: &Path, name: &str) -> Result<PathBuf, String> {
    let name = name.trim();
    if name.is_empty() {
        return Err("empty recording name".into());
    }
    let p = Path::new(name);
    if p.is_absolute() || p.components().any(|c| !matches!(c, Component::Normal(_))) {
        return Err(format!("recording path {name:?} must be a relative path inside the output directory {} (no '..', no absolute paths)", out_dir.display()));
    }
    if name.chars().any(|c| c.is_control()) {
        return Err(format!(
            "recording path {name:?} contains control characters"
        ));
    }
    // A link inside the output directory (made by anyone who can write there) must not carry a
    // recording out of it: every part of the path that already exists must be a real directory.
    let mut prefix = out_dir.to_path_buf();
    for c in p.components() {
        prefix.push(c);
        if let Ok(m) = std::fs::symlink_metadata(&prefix) {
            if m.file_type().is_symlink() {
                return Err(format!(
                    "recording path {name:?}: {} is a symbolic link; recordings stay inside the output directory",
                    prefix.display()
                ));
            }
        }
    }
    let full = out_dir.join(p);
    if full.exists() {
        return Err(format!(
            "{} already exists; choose another name",
            full.display()
        ));
    }
    Ok(full)
}

/// Longest stall `debug-stall` accepts (ms).
pub const MAX_STALL_MS: u64 = 10_000;

/// `MS` of a `debug-stall` request: a whole number of milliseconds, 1..=[`MAX_STALL_MS`].
pub fn parse_stall(args: &str) -> Result<u64, String> {
    let v = args.trim();
    match v.parse::<u64>() {
        Ok(ms) if (1..=MAX_STALL_MS).contains(&ms) => Ok(ms),
        _ => Err(format!(
            "debug-stall: {:?} is not a whole number of milliseconds in 1..={MAX_STALL_MS}",
            v.chars().take(40).collect::<String>()
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::Config;

    /// `set` on the planar arm's `c`, at a step of `min_tau`.
    fn set(c: &Config, args: &str, min_tau: f64) -> Result<Config, String> {
        apply_set(&System::Planar(c.clone()), args, min_tau).map(|s| s.planar().unwrap().clone())
    }

    #[test]
    fn the_deadlock_settings_are_set_live_and_checked() {
        let c = Config::preset("demo").unwrap();
        let n = set(
            &c,
            "safety.trap_time 3.5 safety.when_blocked best-effort",
            1e-3,
        )
        .unwrap();
        assert_eq!(n.safety.trap_time, 3.5);
        assert_eq!(
            n.safety.when_blocked,
            control::safety::policy::WhenBlocked::BestEffort
        );
        let e = set(&c, "safety.when_blocked later", 1e-3).unwrap_err();
        assert!(e.contains("hold or best-effort"), "{e}");
        assert_eq!(c.safety.plan, PlanMode::Auto);
        for (v, mode) in [
            ("off", PlanMode::Off),
            ("on", PlanMode::On),
            ("auto", PlanMode::Auto),
        ] {
            let n = set(&c, &format!("safety.plan {v}"), 1e-3).unwrap();
            assert_eq!(n.safety.plan, mode, "{v}");
        }
        let e = set(&c, "safety.plan sometimes", 1e-3).unwrap_err();
        assert!(e.contains("auto, on or off"), "{e}");
        for bad in ["0", "0.05", "61", "nan"] {
            let e = set(&c, &format!("safety.trap_time {bad}"), 1e-3).unwrap_err();
            assert!(e.contains("safety.trap_time"), "{bad}: {e}");
        }
    }

    #[test]
    fn stalls_are_bounded() {
        assert_eq!(parse_stall(" 250 "), Ok(250));
        assert_eq!(parse_stall("10000"), Ok(10_000));
        for bad in [
            "",
            "0",
            "10001",
            "-5",
            "1.5",
            "soon",
            "99999999999999999999999",
        ] {
            assert!(parse_stall(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn recordings_cannot_leave_the_output_directory_through_a_link() {
        let dir = std::env::temp_dir().join(format!("chaosd-rec-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("real")).unwrap();
        std::os::unix::fs::symlink(std::env::temp_dir(), dir.join("out")).unwrap();
        let e = recording_path(&dir, "out/x.csv").unwrap_err();
        assert!(e.contains("symbolic link"), "{e}");
        std::os::unix::fs::symlink("/etc/passwd", dir.join("file.csv")).unwrap();
        assert!(recording_path(&dir, "file.csv")
            .unwrap_err()
            .contains("symbolic link"));
        assert!(recording_path(&dir, "real/ok.csv").is_ok());
        assert!(recording_path(&dir, "new/ok.csv").is_ok());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn runaway_settings_are_refused_with_the_limit_named() {
        let c = Config::preset("demo").unwrap();
        for (args, want) in [
            ("kv 3000", "K_v < 1000"),
            ("task.period 0.01", "≥ 0.05 s"),
            ("kp 1000000 kv 1000000", "law.kv"),
            ("task.center 1e5 1e5", "reaches only"),
            ("safety.k1 5", "real roots"),
            ("safety.push_out_speed 0", "safety.push_out_speed"),
            ("safety.push_out_speed -1", "must be a finite number > 0"),
            ("safety.qd_max 0", "safety.qd_max[0]"),
            ("safety.qd_max 1 2", "or 3 values"),
            ("safety.q_max 1 1 nan", "not a finite number"),
            ("projection sideways", "full or null-space"),
        ] {
            let e = set(&c, args, 1e-3).unwrap_err();
            assert!(e.contains(want), "{args}: {e}");
        }
        // At 10 kHz (and an offline step to match) the same kv is stable.
        let mut fast = c.clone();
        fast.sim.dt = 1e-4;
        assert!(set(&fast, "kv 3000", 1e-4).is_ok());
        let n = set(
            &c,
            "safety off safety.qd_max 5 6 7 safety.q_max inf 2 2 projection null-space safety.push_out_speed 0.05",
            1e-3,
        )
        .unwrap();
        assert!(!n.safety.enabled);
        assert_eq!(n.safety.params(3).gains().push_out_speed, 0.05);
        assert_eq!(n.safety.params(3).qd_max[..3], [5.0, 6.0, 7.0]);
        assert_eq!(n.safety.params(3).q_max[..3], [f64::INFINITY, 2.0, 2.0]);
        assert_eq!(
            n.feedback.projection,
            control::config::ProjectionKind::NullSpace
        );
    }

    #[test]
    fn set_is_all_or_nothing_and_validated() {
        let c = Config::default();
        let n = set(
            &c,
            "mu 1.5 tau 1.2 kp 30 task.center 1 1.5 secondary none feedback off",
            1e-3,
        )
        .unwrap();
        assert_eq!(
            (
                n.feedback.mu,
                n.tau(),
                n.law.kp,
                n.planar_part().task.center
            ),
            (1.5, 1.2, 30.0, [1.0, 1.5])
        );
        assert!(!n.feedback.enabled);
        assert_eq!(n.law.secondary, SecondaryKind::None);
        for (args, want) in [
            ("mu -1", "feedback.mu"),
            ("mu 1 kp -5", "law.kp"),
            ("mu 1 law.kp -5", "law.kp"),
            ("mu 1 control.kp -5", "law.kp"),
            ("tau 3", "max_tau"),
            ("tau 0.0001", "control period"),
            ("bogus 1", "unknown key"),
            ("mu", "missing value"),
            ("mu abc", "not a number"),
            ("mu nan", "finite"),
            ("secondary obstacles", "[[obstacles]]"),
            ("max_tau 5", "fixed at start-up"),
            ("", "KEY VALUE"),
        ] {
            let e = set(&c, args, 1e-3).unwrap_err();
            assert!(e.contains(want), "{args:?} → {e}");
        }
    }

    #[test]
    fn obstacles_and_dfc() {
        let system = |c: Config| System::Planar(c);
        let planar = |s: System| s.planar().unwrap().clone();
        let one = apply_obstacle_add(&system(Config::default()), "0 1.6 0.25", 1e-3).unwrap();
        let c = planar(one.clone());
        assert_eq!(c.planar_part().obstacles.len(), 1);
        assert!(apply_obstacle_add(&one, "0 1.6 -1", 1e-3)
            .unwrap_err()
            .contains("obstacle.radius"));
        assert!(apply_obstacle_add(&one, "0 1.6", 1e-3)
            .unwrap_err()
            .contains("X Y RADIUS"));
        let c2 = system(set(&c, "secondary obstacles", 1e-3).unwrap());
        assert!(apply_obstacle_remove(&c2, "1", 1e-3)
            .unwrap_err()
            .contains("secondary"));
        assert!(apply_obstacle_remove(&c2, "3", 1e-3)
            .unwrap_err()
            .contains("no obstacle 3"));
        assert!(apply_obstacle_remove(&one, "0", 1e-3)
            .unwrap_err()
            .contains("numbered from 1"));
        assert!(apply_obstacle_remove(&one, "1", 1e-3)
            .unwrap()
            .obstacle_rows()
            .is_empty());
        assert!(apply_dfc(&system(Config::default()), true, 3.0, 1e-3)
            .unwrap_err()
            .contains("mu is 0"));
        let with_gain = system(set(&c, "mu 0.2", 1e-3).unwrap());
        let on = apply_dfc(&with_gain, true, 3.0, 1e-3).unwrap();
        let f = on.feedback_section();
        assert_eq!((f.enabled, f.t_on), (true, 3.0));
        let off = apply_dfc(&on, false, 4.0, 1e-3).unwrap();
        assert!(!off.feedback_section().enabled);
    }

    #[test]
    fn recordings_stay_inside_the_output_directory() {
        let out = std::env::temp_dir().join(format!("chaosd-rec-{}", std::process::id()));
        assert_eq!(
            recording_path(&out, "run1.csv").unwrap(),
            out.join("run1.csv")
        );
        assert_eq!(
            recording_path(&out, "sub/run1.csv").unwrap(),
            out.join("sub/run1.csv")
        );
        for bad in ["../x.csv", "/etc/passwd", "a/../../x", "./x", "", "a\nb"] {
            assert!(recording_path(&out, bad).is_err(), "{bad:?} accepted");
        }
    }

    fn panda() -> System {
        rt::robot::preset("panda").unwrap()
    }

    /// The robot's file after a change.
    fn robot(s: System) -> control::Config {
        match s {
            System::Spatial(s) => s.config,
            System::Planar(_) => panic!("the Panda is a robot"),
        }
    }

    #[test]
    fn set_changes_all_or_nothing() {
        let p = panda();
        let n = robot(apply_set(&p, "mu 0.5 law.kp 30 projection full", 1e-3).unwrap());
        assert_eq!((n.feedback.mu, n.law.kp), (0.5, 30.0));
        assert_eq!(n.feedback.projection, control::config::ProjectionKind::Full);
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
        let (add, remove) = (apply_obstacle_add, apply_obstacle_remove);
        let p = panda();
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
        let mut p = panda();
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
        let n = robot(apply_set(&p, "tau 1.5", 1e-3).unwrap());
        assert_eq!(n.feedback.tau, Some(1.5));
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
