//! The demo's report. A newcomer's first run should end on one screen that says whether the
//! method worked (tracking, the period residual, the monitor's verdict), what the real-time path
//! cost, and whether anything went wrong; everything else is a detail, printed with `--details`
//! and always written to `report.txt` beside the histograms. Each line is built once and tagged,
//! so the short report can never disagree with the full one.

use crate::config::DaemonSetup;
use crate::residual;
use crate::telemetry::DaemonSummary;
use serde_json::Value;
use std::path::Path;

/// One line of the report: `label` padded to a column, then the text.
#[derive(Clone, Debug)]
pub struct Line {
    pub label: &'static str,
    pub text: String,
    /// In the short report too (else only with `--details` and in `report.txt`).
    pub brief: bool,
}

impl Line {
    fn brief(label: &'static str, text: String) -> Self {
        Self {
            label,
            text,
            brief: true,
        }
    }
    fn detail(label: &'static str, text: String) -> Self {
        Self {
            label,
            text,
            brief: false,
        }
    }
}

impl std::fmt::Display for Line {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:<21} {}", self.label, self.text)
    }
}

/// The heading every report starts with.
pub const HEADING: &str = "== chaosd demo report ==";

/// What the demo ran, for the report.
pub struct Run<'a> {
    pub setup: &'a DaemonSetup,
    pub daemon: &'a DaemonSummary,
    /// The plant's (or the bridge's) summary, if it wrote one.
    pub plant: Option<&'a Value>,
    /// A `--bridge udp` demo, and chaosd-fakebot's summary if it wrote one.
    pub bridge: bool,
    pub device: Option<&'a Value>,
    pub out: &'a Path,
}

/// Every line of the report, in order, each tagged brief or detail.
pub fn lines(r: &Run) -> Vec<Line> {
    let mut v = vec![Line::brief("arm", arm(r))];
    v.extend(method(r));
    v.extend(timing(r));
    v.extend(faults(r));
    v.extend(safety(r));
    v.extend(robot(r));
    if r.bridge {
        v.extend(device(r.device));
    }
    v.push(Line::detail(
        "real-time set-up",
        r.daemon.realtime.one_line(),
    ));
    v.extend(files(r.out));
    v
}

/// The short report: the brief lines, and a last line saying where the rest is.
pub fn brief(all: &[Line], report_file: &Path) -> Vec<Line> {
    let mut v: Vec<Line> = all.iter().filter(|l| l.brief).cloned().collect();
    v.push(Line::brief(
        "details",
        format!(
            "{} more lines with --details, and in {}",
            all.len() - v.len(),
            report_file.display()
        ),
    ));
    v
}

/// The file chaosd-fakebot writes at exit in a `--bridge udp` demo.
pub const FAKEBOT_SUMMARY: &str = "fakebot-summary.json";

fn arm(r: &Run) -> String {
    let s = r.setup;
    let mode = match s.system.robot() {
        Some(r) => format!(", {} mode", r.own().command.mode),
        None => String::new(),
    };
    format!(
        "{}{mode}, {} Hz, {}; {}",
        s.system.describe_arm(),
        s.daemon.rate_hz,
        match s.daemon.trigger {
            rt::Trigger::State => "state trigger (each state answered in the same cycle)",
            rt::Trigger::Clock => "clock trigger (free-running loops)",
        },
        r.daemon.realtime.one_line()
    )
}

/// Did the method work: tracking, the period residual, the monitor's verdict.
fn method(r: &Run) -> Vec<Line> {
    let d = r.daemon;
    let tracking = match (d.tracking_rms_m, d.tracking, d.tracking_whole_rms_m, d.tracking_whole) {
        (Some(t), Some(s), _, _) => format!(
            "RMS {t:.2e} m, median {:.2e} m, max {:.2e} m (after the first 2 s)",
            s.p50_m, s.max_m
        ),
        (_, _, Some(t), Some(s)) => format!(
            "RMS {t:.2e} m, median {:.2e} m, max {:.2e} m (the start-up transient: the law stopped tracking before 2 s)",
            s.p50_m, s.max_m
        ),
        _ => "n/a (no states received)".into(),
    };
    vec![
        Line::brief("tracking error", tracking),
        Line::brief("period residual", residual(r)),
        Line::brief("chaos monitor", chaos(d)),
    ]
}

fn residual(r: &Run) -> String {
    let d = r.daemon;
    let ratio = |b: f64, a: f64| {
        if a == 0.0 {
            "periodic to rounding".to_string()
        } else if a <= b && b / a >= 1000.0 {
            format!("{:.1e}× smaller", b / a)
        } else if a <= b {
            format!("{:.1}× smaller", b / a)
        } else {
            format!("{:.1}× LARGER: not settled on a period-T orbit", a / b)
        }
    };
    let auto = if r.setup.system.feedback().auto.is_some() {
        " (auto)"
    } else {
        ""
    };
    let from_start = d
        .feedback_on_at_s
        .is_some_and(|t| t < residual::SKIP_S as f64);
    match (d.period_residual_before, d.period_residual_after) {
        (Some(b), Some(a)) => format!(
            "mean |q̇(t) − q̇(t−τ)|: {} rad/s before feedback → {} rad/s over the last 5 s with μ = {}{auto} ({})",
            sig(b),
            sig(a),
            crate::number::short(d.chaos.mu),
            ratio(b, a)
        ),
        (None, Some(a)) if from_start && d.period_residual_start.is_some() => {
            let s = d.period_residual_start.unwrap_or(a);
            format!(
                "mean |q̇(t) − q̇(t−τ)|: {} rad/s over 2-7 s → {} rad/s over the last 5 s, μ = {}{auto} from the start ({})",
                sig(s),
                sig(a),
                crate::number::short(d.chaos.mu),
                ratio(s, a)
            )
        }
        (b, a) => {
            let show = |v: Option<f64>| v.map_or("n/a".to_string(), |x| format!("{x:.3} rad/s"));
            format!(
                "mean |q̇(t) − q̇(t−τ)|: {} before feedback, {} with it (the run stopped before t_on + 5 s: nothing to compare)",
                show(b),
                show(a)
            )
        }
    }
}

/// The monitor's verdict at the end and how it got there (`chaotic at 13 s → …`).
fn chaos(d: &DaemonSummary) -> String {
    let c = &d.chaos;
    let path: Vec<String> = c
        .history
        .iter()
        .map(|e| format!("{} at {:.0} s", e.to.name(), e.t))
        .collect();
    format!(
        "{} ({}){}{}{}",
        c.evidence.verdict.name(),
        crate::chaos::describe(&c.evidence),
        if path.is_empty() {
            String::new()
        } else {
            format!("; {}", path.join(" → "))
        },
        c.target.as_ref().map_or(String::new(), steered),
        c.model_gain
            .as_ref()
            .map_or(String::new(), |w| format!("; the gain from the model: {w}"))
    )
}

/// The steering onto the model's cycle, for the chaos line.
fn steered(t: &crate::targeting::TargetInfo) -> String {
    use crate::targeting::Ended;
    use control::target::Released;
    let how = match t.ended {
        Some(Ended::Released(Released::OnTheCycle)) => "on it, then held by the feedback",
        Some(Ended::Released(Released::TimedOut)) => "not settled on it, left to the feedback",
        Some(Ended::Edited) => "until an edit",
        Some(Ended::Planner) => "until the planner steered",
        None => "to the end",
    };
    let until = t.ended_at.map_or(String::new(), |e| format!("–{e:.1}"));
    format!(
        "; steered onto the model's cycle {:.1}{until} s ({how})",
        t.since
    )
}

/// What the real-time path cost.
fn timing(r: &Run) -> Vec<Line> {
    let (s, d) = (r.setup, r.daemon);
    let c = &d.counters;
    let mut v = vec![];
    if let Some(p) = r.plant {
        v.push(Line::brief(
            "command round trip",
            format!(
                "{}  (state published → command received by the plant{})",
                pct(p, "round_trip"),
                if s.daemon.trigger == rt::Trigger::State {
                    ", same cycle"
                } else {
                    ", at its next tick"
                }
            ),
        ));
    } else {
        v.push(Line::brief(
            "command round trip",
            "n/a (the plant wrote no summary)".into(),
        ));
    }
    v.push(Line::brief("compute per tick", d.compute.one_line()));
    v.push(Line::brief("wake-up lateness", d.lateness.one_line()));
    v.push(Line::detail(
        "overruns",
        format!("{} skipped periods in {} ticks", c.overruns, c.ticks),
    ));
    v.push(Line::detail("state age at tick", d.state_age.one_line()));
    if let Some(p) = r.plant {
        v.push(Line::detail("state → command", pct(p, "state_to_command")));
        if p["step"].is_object() {
            v.push(Line::detail("plant step", pct(p, "step")));
        }
        v.extend(answers(s, p));
    }
    if s.daemon.trigger == rt::Trigger::State {
        v.push(Line::detail(
            "core gone",
            rt::gaps::describe(&c.wait_gaps, &c.late_wakes, s.daemon.period_ns()),
        ));
    }
    v
}

/// The state trigger's figures from the plant's summary: answered in time, late, braked.
fn answers(s: &DaemonSetup, p: &Value) -> Vec<Line> {
    let c = &p["counters"];
    let n = |k: &str| c[k].as_u64().unwrap_or(0);
    let mut v = vec![Line::detail(
        "trigger",
        format!(
            "{}{}",
            s.daemon.trigger.name(),
            match s.daemon.trigger {
                rt::Trigger::State => ": a tick per state, the answer applied in the same cycle",
                rt::Trigger::Clock =>
                    ": free-running loops, each applies the newest sample at its tick",
            }
        ),
    )];
    if let Some(share) = p["in_time_share"].as_f64() {
        v.push(Line::detail(
            "answered in time",
            format!(
                "{:.3} % of {} cycles; {} late cycles, {} late answers dropped, {} brakes after too many late cycles, {} cycles with no controller answering",
                share * 100.0,
                n("answered_in_time") + n("late_cycles"),
                n("late_cycles"),
                n("late_answers"),
                n("late_brakes"),
                n("silent_cycles")
            ),
        ));
    }
    v
}

/// Anything that went wrong, named on one brief line (or "none"); each count in detail.
fn faults(r: &Run) -> Vec<Line> {
    let (s, d) = (r.setup, r.daemon);
    let c = &d.counters;
    let mut v = vec![Line::brief("problems", problems(r))];
    v.push(Line::detail(
        "faults",
        format!(
            "{} samples rejected ({} invalid, {} stale, {} out of order, {} from the future, {} flagged faulty by the plant); {} holds; {} arm brakes{}; {} plant restarts; {} telemetry records dropped",
            c.rejected(), c.rejected_invalid, c.rejected_stale, c.rejected_out_of_order, c.rejected_future, c.plant_faults, c.holds_entered,
            c.arm_brakes, d.last_arm_brake_s.map_or(String::new(), |t| format!(" (the last at t = {t:.1} s)")), c.plant_restarts, c.telemetry_dropped
        ),
    ));
    if c.track_lost + c.out_of_reach + c.nonfinite > 0 {
        v.push(Line::detail(
            "tracking loss",
            format!(
                "error above control.track_loss = {} m on {} ticks, the start-up transient included ({} near-singular, {} with the target out of reach, {} non-finite results)",
                s.system.safety().track_loss, c.track_lost, c.singular, c.out_of_reach, c.nonfinite
            ),
        ));
    }
    v
}

/// The non-zero fault counters in a few words, or "none" with what was checked.
fn problems(r: &Run) -> String {
    let d = r.daemon;
    let c = &d.counters;
    let plant = |k: &str| r.plant.and_then(|p| p["counters"][k].as_u64()).unwrap_or(0);
    let contact = |k: &str| r.plant.and_then(|p| p["contacts"][k].as_u64()).unwrap_or(0);
    let late = plant("late_cycles");
    let seen: Vec<String> = [
        (c.faults, "runaway-guard faults"),
        (d.blocked_entered, "times Blocked"),
        (d.device_stops, "reflex stops"),
        (
            c.safety_infeasible,
            "ticks without a command meeting every limit",
        ),
        (c.rejected(), "samples rejected"),
        (c.holds_entered, "holds"),
        (c.plant_restarts, "plant restarts"),
        (c.overruns, "skipped periods"),
        (late, "late cycles"),
        (
            plant("effort_clamps"),
            "plant substeps with a torque clamped at its effort limit",
        ),
        (
            contact("obstacle_contact_periods"),
            "periods in which MuJoCo saw a link touch an obstacle",
        ),
        (
            contact("self_contact_periods"),
            "periods in which MuJoCo saw the arm touch itself",
        ),
        (c.telemetry_dropped, "telemetry records dropped"),
        (c.nonfinite, "non-finite results"),
    ]
    .iter()
    .filter(|(n, _)| *n > 0)
    .map(|(n, what)| format!("{n} {what}"))
    .chain(d.joint_limits.breaches())
    .chain(
        d.min_clearance_m
            .filter(|&m| m < 0.0)
            .map(|m| format!("a link {:.3} m inside an obstacle", -m)),
    )
    .chain(short_of_clearance(r))
    .collect();
    let blocked = d
        .first_blocked
        .as_ref()
        .map_or(String::new(), |b| format!(" (first Blocked: {b})"));
    if seen.is_empty() {
        "none (no limit breaches, faults, rejected samples, holds, restarts, overruns or dropped records)".into()
    } else {
        format!("{}{blocked}; see --details", seen.join(", "))
    }
}

/// A filter that is on promises its clearance; a run that came closer (by more than a
/// millimetre, the filter's own tolerance on a VM's stalls) says so, though no link touched.
fn short_of_clearance(r: &Run) -> Option<String> {
    let sf = r.setup.system.safety();
    let m = r.daemon.min_clearance_m?;
    (sf.enabled && (0.0..sf.clearance - 1e-3).contains(&m)).then(|| {
        format!(
            "a link {m:.3} m from an obstacle (the filter keeps {} m)",
            sf.clearance
        )
    })
}

fn safety(r: &Run) -> Vec<Line> {
    let (s, d) = (r.setup, r.daemon);
    let c = &d.counters;
    let sf = s.system.safety();
    let mut v = vec![Line::brief(
        "safety",
        format!(
            "filter {}: acted on {} ticks, left the null space on {} (tracking gave way){}",
            if sf.enabled { "on" } else { "OFF" },
            c.safety_active,
            c.safety_left_null_space,
            d.min_clearance_m.map_or(String::new(), |m| format!(
                "; min clearance {m:.3} m (required {} m)",
                sf.clearance
            ))
        ),
    )];
    if let Some(c) = r.plant.map(|p| &p["contacts"]).filter(|c| c.is_object()) {
        v.push(Line::brief("mujoco contact", mujoco_contact(c)));
    }
    if let Some(line) = d.joint_limits.one_line() {
        v.push(Line::detail("joint limits", line));
    }
    v
}

/// MuJoCo's judgement of contact on its own geometry (a `--plant mujoco` run).
fn mujoco_contact(c: &Value) -> String {
    if c["judged"].as_bool() != Some(true) {
        return "not judged: the model has no collision geometry on the arm (--mujoco-model \
                names one with meshes)"
            .into();
    }
    let n = |k: &str| c[k].as_u64().unwrap_or(0);
    let first = |t: &str, p: &str| match (c[t].as_f64(), c[p].as_str()) {
        (Some(t), Some(p)) => format!(" (first at {t:.2} s: {p})"),
        _ => String::new(),
    };
    let distance = c["smallest_distance_m"]
        .as_f64()
        .map_or(String::new(), |d| {
            format!("; smallest distance to an obstacle {d:.3} m")
        });
    // The filter's clearance is the capsules': where the meshes reach out of them, say so.
    let outside = match (
        c["outside_capsules"][0].as_u64(),
        c["outside_capsules"][1].as_f64(),
    ) {
        (Some(link), Some(out)) => format!(
            "; the meshes reach {out:.3} m out of the capsules (link {link}): the filter's \
             clearance is not theirs (fit-radii --capsules)"
        ),
        _ => String::new(),
    };
    format!(
        "{} periods touching an obstacle{}, {} touching itself{} ({} arm geoms, MuJoCo's own \
         geometry; {} pairs touching at the start not counted){distance}{outside}",
        n("obstacle_contact_periods"),
        first("first_contact_s", "first_pair"),
        n("self_contact_periods"),
        first("first_self_contact_s", "first_self_pair"),
        n("robot_geoms"),
        n("overlapping_at_start"),
    )
}

/// A robot set-up's command interface and the device's reflexes.
fn robot(r: &Run) -> Vec<Line> {
    let d = r.daemon;
    if r.setup.system.robot().is_none() {
        return vec![];
    }
    vec![
        Line::detail(
            "command",
            format!("{} mode; {}", d.command.mode, d.command.one_line()),
        ),
        Line::detail(
            "device",
            format!(
                "{} reflex stops{}",
                d.device_stops,
                d.first_device_stop
                    .as_ref()
                    .map_or(String::new(), |f| format!("; the first {f}"))
            ),
        ),
    ]
}

/// The device's side of a `--bridge udp` demo: its round trip and its missed cycles.
fn device(summary: Option<&Value>) -> Vec<Line> {
    let Some(v) = summary else {
        return vec![Line::brief(
            "device (UDP)",
            "n/a (chaosd-fakebot wrote no summary; see fakebot.log)".into(),
        )];
    };
    let c = &v["counters"];
    let n = |k: &str| c[k].as_u64().unwrap_or(0);
    vec![
        Line::brief(
            "device round trip",
            format!(
                "{}  (fakebot: state sent over UDP → answer received)",
                pct(v, "round_trip")
            ),
        ),
        Line::detail(
            "device cycles",
            format!(
                "{} cycles ({} skipped by its own lateness), {} answered in time, {} missed, {} late answers, {} brakes{}; {} states and {} commands lost (injected)",
                n("cycles"), n("skipped"), n("answered_in_time"), n("missed"), n("late_answers"), n("brakes"), brake_times(v), n("states_lost"), n("commands_lost")
            ),
        ),
        Line::detail(
            "device reflexes",
            format!(
                "{} reflex stops{}",
                n("reflex_stops"),
                v["first_reflex"]
                    .as_str()
                    .map_or(String::new(), |f| format!("; the first {f}"))
            ),
        ),
    ]
}

/// When the device braked on missed answers: " (at 5.1 s)", " (first at 5.1 s, last at 57.0 s)".
fn brake_times(v: &Value) -> String {
    match (v["first_brake_s"].as_f64(), v["last_brake_s"].as_f64()) {
        (Some(a), Some(b)) if a == b => format!(" (at {a:.1} s)"),
        (Some(a), Some(b)) => format!(" (first at {a:.1} s, last at {b:.1} s)"),
        _ => String::new(),
    }
}

/// Only the files that were written: a plant that died writes none of its own.
fn files(out: &Path) -> Vec<Line> {
    let listed = |names: &[&str]| {
        names
            .iter()
            .filter(|n| out.join(n).exists())
            .copied()
            .collect::<Vec<_>>()
            .join(", ")
    };
    vec![
        Line::detail(
            "histograms",
            format!(
                "{}/{}",
                out.display(),
                listed(&[
                    "daemon-lateness.hgrm",
                    "daemon-compute.hgrm",
                    "daemon-state-age.hgrm",
                    "daemon.hlog",
                    "plant-round-trip.hgrm",
                    "plant-state-to-command.hgrm",
                    "plant-lateness.hgrm",
                    "plant-step.hgrm",
                ])
            ),
        ),
        Line::detail(
            "summaries",
            format!(
                "{}/{}",
                out.display(),
                listed(&["daemon-summary.json", "plant-summary.json"])
            ),
        ),
    ]
}

/// `p50 … µs, p99 …, p99.9 …, max …` from a summary's percentile object.
pub fn pct(v: &Value, key: &str) -> String {
    let g = |k: &str| v[key][k].as_f64().unwrap_or(f64::NAN);
    format!(
        "p50 {:.1} µs, p99 {:.1} µs, p99.9 {:.1} µs, max {:.1} µs",
        g("p50_us"),
        g("p99_us"),
        g("p999_us"),
        g("max_us")
    )
}

/// A residual with three significant digits at any size (2.3e-4 is not "0.000").
fn sig(x: f64) -> String {
    if x == 0.0 || (1e-2..1e3).contains(&x.abs()) {
        format!("{x:.3}")
    } else {
        format!("{x:.2e}")
    }
}
