//! Why a state-triggered run's cycles were late: the controller, or the machine.
//!
//! Why this table exists: the same-cycle target (≥ 99.9 % answered in time) leaves 10 late cycles
//! in 10 000, and on a shared VM the host alone can take more than that. A late cycle is an
//! answer that missed the plant's deadline, half a period after the state went out. The daemon
//! counts each stretch of its loop without its core (between two clock reads, outside its
//! sleeps) and each of its sleeps that ended late (`rt::gaps`); a stretch of at least half a
//! period, or a sleep that ended that late, can cost one cycle or more.
//! `/proc/stat` counts the time the host ran something else on each vCPU (steal, in 10 ms
//! steps). Side by side with the late cycles,
//! they say whose the late cycles were.

use super::result::RateResult;
use crate::stats::Table;
use serde_json::Value;

/// One row per state-triggered run: late cycles, the daemon's lost stretches while polling and
/// its late wake-ups, steal on the daemon's and the plant's vCPU, and the plant's overruns.
pub fn late_table(results: &[RateResult]) -> String {
    let mut t = Table::new(&[
        "rate",
        "mode",
        "late cycles",
        "daemon without its core for ≥ half a period: polling / waking from a sleep",
        "longest",
        "host steal on the daemon's / plant's vCPU",
        "plant overruns",
    ]);
    for r in results.iter().filter(|r| r.plant["in_time_share"].is_f64()) {
        let (d, p) = (&r.daemon, &r.plant);
        let (g, w) = (&d["counters"]["wait_gaps"], &d["counters"]["late_wakes"]);
        let half_period_ns = (0.5e9 / r.rate_hz) as u64;
        let longest = num(&g["max_ns"]).max(num(&w["max_ns"]));
        t.row(vec![
            format!("{} kHz", r.rate_hz / 1000.0),
            r.mode.name().into(),
            count(&p["counters"]["late_cycles"]),
            format!(
                "{} / {}",
                at_least(g, half_period_ns),
                at_least(w, half_period_ns)
            ),
            format!("{:.0} µs", longest / 1e3),
            format!(
                "{} / {}",
                steal(r, &d["realtime"]["pinned_core"]),
                steal(r, &p["realtime"]["pinned_core"])
            ),
            count(&p["counters"]["overruns"]),
        ]);
    }
    t.render()
}

/// How many of the gaps were at least `ns` long, from `by_length` (`rt::gaps::Gaps`), counted
/// from `Gaps::bound_for(ns)`; when that is not `ns` itself, the bound used is named.
fn at_least(g: &Value, ns: u64) -> String {
    let parsed = serde_json::from_value::<rt::gaps::Gaps>(g.clone());
    let (Some(g), true) = (parsed.ok(), g["by_length"].is_array()) else {
        return "-".into();
    };
    let (bound, n) = (rt::gaps::Gaps::bound_for(ns), g.at_least(ns));
    if bound == ns {
        n.to_string()
    } else {
        format!("{n} (≥ {} µs)", bound / 1000)
    }
}

fn steal(r: &RateResult, core: &Value) -> String {
    core.as_u64()
        .and_then(|c| r.steal_ms.get(c as usize))
        .map_or_else(|| "-".into(), |ms| format!("{ms:.0} ms"))
}

fn count(v: &Value) -> String {
    v.as_u64().map_or_else(|| "-".into(), |n| n.to_string())
}

fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::e2e::result::Mode;
    use serde_json::json;
    use std::path::PathBuf;

    #[test]
    fn rows_for_state_triggered_runs_only() {
        let gaps = json!({"count": 639, "total_ns": 13_898_989u64, "max_ns": 888_126,
                          "by_length": [549, 71, 14, 1, 0, 4, 0, 0]});
        let state = RateResult {
            rate_hz: 10_000.0,
            mode: Mode::State,
            device: None,
            requests: None,
            viewed: None,
            scrapes: None,
            daemon: json!({"counters": {"wait_gaps": gaps, "late_wakes": {"max_ns": 1_200_000,
                           "by_length": [900, 30, 6, 2, 1, 0, 1, 0]}},
                           "realtime": {"pinned_core": 1}}),
            plant: json!({"in_time_share": 0.998, "realtime": {"pinned_core": 0},
                          "counters": {"late_cycles": 180, "overruns": 755}}),
            cpu_daemon: 0.5,
            cpu_plant: 0.5,
            steal_ms: vec![40.0, 10.0],
            dir: PathBuf::new(),
        };
        let clock = RateResult {
            mode: Mode::Clock,
            plant: json!({}),
            ..state.clone()
        };
        let mut one_khz = state.clone();
        one_khz.rate_hz = 1_000.0;
        let t = late_table(&[clock, state, one_khz]);
        // 10 kHz: half a period is 50 µs, a bound: exact. 1 kHz: 500 µs, also a bound.
        assert!(
            t.contains("| 10 kHz | state-triggered (iceoryx2, fast lane) | 180 | 19 / 10 | 1200 µs | 10 ms / 40 ms | 755 |"),
            "{t}"
        );
        assert!(
            t.contains("| 1 kHz | state-triggered (iceoryx2, fast lane) | 180 | 4 / 1 |"),
            "{t}"
        );
        assert!(!t.contains("free-running"), "{t}");
        // 2 kHz: 250 µs is no bound; counted from 500 µs, and said so. 100 Hz: from 2 ms.
        assert_eq!(at_least(&gaps, 250_000), "4 (≥ 500 µs)");
        assert_eq!(at_least(&gaps, 5_000_000), "0 (≥ 2000 µs)");
        assert_eq!(at_least(&json!({}), 50_000), "-");
    }
}
