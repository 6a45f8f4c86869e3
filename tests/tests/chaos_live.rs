//! The chaos monitor and `mu = "auto"` on a live daemon and plant (issue 27): the daemon says,
//! with its evidence, that the self-motion is periodic under the feedback and chaotic without
//! it, in status, watch, the metrics' telemetry, the log and the exit summary; `set mu auto`
//! adapts the gain live, carried on from the gain it had.

use serde_json::Value;
use std::time::Duration;
use tests::live::*;
use tests::*;

fn verdict(v: &Value) -> &str {
    v["chaos"]["verdict"].as_str().unwrap_or("")
}

#[test]
fn the_daemon_says_periodic_with_feedback_and_chaotic_without_and_adapts_mu_live() {
    let _g = serial();
    // On the period-1 orbit's neighbourhood with μ = 0.2 from the start: it settles in seconds.
    let near = NEAR_ORBIT
        .replace("mu = 0.0", "mu = 0.2\nt_on = 0.0")
        .replace("enabled = false", "enabled = true");
    // The verdict is the subject, not HOLD: a loaded machine that keeps the plant's states
    // from the loop for 20 ms (the default `hold_after`) holds the arm, and a few holds kick it
    // out of the orbit's basin (seen: 5 holds in 2 s, no verdict in 40 s).
    let sys = start_with_daemon("chaos", &near, "hold_after = 500");
    let ns = sys.ns.as_str();
    // Usually within 15 s. Late ticks while the processes start (40 overruns in the first
    // 0.5 s of a loaded full run) can push the arm out of the orbit's neighbourhood, and μ = 0.2
    // then needs a chaotic transient to find the orbit again (seen: still "regular" at 40 s).
    let (v, took) = poll_status(ns, Duration::from_secs(120), |v| verdict(v) == "periodic");
    assert_eq!(verdict(&v), "periodic", "{v}\n{}", sys.daemon.log());
    let c = &v["chaos"];
    assert!(
        c["residual"].as_f64().unwrap() < 2e-2 && c["periods"].as_u64().unwrap() >= 3,
        "{c}"
    );
    assert_eq!(c["mu_auto"], false);
    eprintln!("periodic after {took:?}: {c}");

    // The human status, watch (telemetry) and the log say it too.
    let (code, out, err) = ctl(ns, &["status"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("\nchaos     periodic since t = "), "{out}");
    let (code, out, err) = ctl(ns, &["watch", "--json", "--count", "2"]);
    assert_eq!(code, 0, "{err}");
    let last: Value = serde_json::from_str(out.lines().last().unwrap()).unwrap();
    assert_eq!(last["chaos"], "periodic", "{last}");
    assert_eq!(last["mu_auto"], false);
    let (code, out, _) = ctl(ns, &["watch", "--count", "1"]);
    assert!(code == 0 && out.contains("| periodic"), "{out}");
    assert!(
        sys.daemon.log().contains("→ periodic at t = "),
        "{}",
        sys.daemon.log()
    );

    // mu auto: the daemon chooses the gain from its model on its own thread (well under a
    // second on the planar arm), says why in status, and μ starts from it; the window goes on.
    let before = status(ns);
    let t_set = before["t"].as_f64().unwrap();
    let overruns_at_set = before["counters"]["overruns"].as_u64().unwrap();
    let (code, _, err) = ctl(ns, &["set", "mu", "auto"]);
    assert_eq!(code, 0, "{err}");
    let (v, _) = poll_status(ns, Duration::from_secs(30), |v| {
        v["chaos"]["mu_auto"] == true && v["gains"]["chosen"]["mu"].is_f64()
    });
    assert_eq!(v["chaos"]["mu_auto"], true, "{v}");
    let chosen = &v["gains"]["chosen"];
    let model = chosen["mu"].as_f64().unwrap_or(f64::NAN);
    assert!(
        model > 0.0 && model <= 0.4 && chosen["multiplier"].as_f64() < Some(1.0),
        "{}",
        v["gains"]
    );
    assert!(
        chosen["why"]
            .as_str()
            .unwrap()
            .contains("of the fastest rate"),
        "{chosen}"
    );
    assert_eq!(chosen["asked_at"], "edit");
    assert!(
        sys.daemon.log().contains("the gain from the model, μ = "),
        "{}",
        sys.daemon.log()
    );
    // Usually periodic again within 20 periods. A host stall on a loaded machine (CI saw one
    // of 26 ms, 211 overruns) can knock the arm off the orbit; the gain then grows while the
    // residual is large, and the orbit takes a chaotic transient to find again.
    let (v, took) = poll_status(ns, Duration::from_secs(120), |v| {
        verdict(v) == "periodic" && v["chaos"]["since"].as_f64() > Some(t_set)
    });
    assert_eq!(verdict(&v), "periodic", "{v}\n{}", sys.daemon.log());
    let mu = v["mu"].as_f64().unwrap();
    eprintln!("periodic {took:?} after mu auto, μ = {mu}, the model's {model}");
    // Within the bound; kept on the orbit (periodic again within 20 periods) it stays at the
    // model's gain, which the adaptation leaks back to once the residual is gone.
    assert!((0.0..=0.4).contains(&mu), "μ = {mu}");
    let kept = took < Duration::from_secs(20);
    assert!(
        !kept || (mu - model).abs() < 0.01,
        "μ = {mu}: on the orbit it should stay at the model's {model}"
    );
    // It also steered the arm onto the model's cycle with the gain, and took the pull away
    // once the arm repeated itself (control::target): status and the log say so.
    let (v, _) = poll_status(ns, Duration::from_secs(30), |v| {
        !v["gains"]["target"]["last"]["ended"].is_null()
    });
    let target = &v["gains"]["target"];
    let ended = &target["last"]["ended"];
    let log = sys.daemon.log();
    assert!(
        log.contains("steering the arm onto the model's cycle"),
        "{log}"
    );
    assert_eq!(target["steering"], false, "{target}");
    // A host that takes the loop's core for many periods while the arm is steered (seen: 33 %
    // steal, 400 skipped periods) keeps the arm from repeating itself to 1e-3 rad/s for a
    // period, and the steering rightly times out; on a host that lets the loop run, it must
    // release the arm on the cycle.
    let skipped = v["counters"]["overruns"].as_u64().unwrap() - overruns_at_set;
    if ended == &serde_json::json!({"released": "timed_out"}) && skipped >= 100 {
        eprintln!(
            "the steering timed out after {skipped} skipped periods: {}",
            v["gains"]
        );
    } else {
        assert_eq!(
            ended,
            &serde_json::json!({"released": "on_the_cycle"}),
            "{skipped} periods skipped since `set mu auto`: {}\n{log}",
            v["gains"],
        );
        assert!(log.contains("the arm is on the model's cycle"), "{log}");
    }
    let (code, _, err) = ctl(ns, &["set", "gamma", "1"]);
    assert!(code != 0 && err.contains("feedback.gamma"), "{err}");

    // Feedback off: the orbit is unstable, and the monitor says chaotic, with λ > 0. A small
    // task change pushes the arm off the orbit at the same time: left exactly on it, a quiet
    // run could stay near the unstable orbit for minutes (seen twice in one session, 113 s).
    let (code, _, err) = ctl(ns, &["set", "dfc", "off", "task.radius", "0.52"]);
    assert_eq!(code, 0, "{err}");
    let (v, took) = poll_status(ns, Duration::from_secs(90), |v| verdict(v) == "chaotic");
    assert_eq!(verdict(&v), "chaotic", "{v}");
    eprintln!(
        "chaotic {took:?} after the feedback went off: {}",
        v["chaos"]
    );
    assert!(v["chaos"]["lyapunov"].as_f64().unwrap() > 0.0, "{v}");

    let (code, _, err) = ctl(ns, &["shutdown"]);
    assert_eq!(code, 0, "{err}");
    let mut daemon = sys.daemon;
    assert!(daemon.wait_exit(Duration::from_secs(15)).success());
    let summary = read_json(&sys.dir.path().join("out/daemon-summary.json"));
    let seen: Vec<&str> = summary["chaos"]["history"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["to"].as_str().unwrap())
        .collect();
    assert!(
        seen.contains(&"periodic") && seen.last() == Some(&"chaotic"),
        "{seen:?}"
    );
    assert_eq!(summary["chaos"]["evidence"]["verdict"], "chaotic");
}
