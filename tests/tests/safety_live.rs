//! Safety on a live daemon and plant: an obstacle added on the arm's path is never touched, and
//! a runaway ends in a braked FAULT that only `chaosctl resume` leaves.

use control::law::evaluate;
use control::sim::{plant_derivative, rk4_step};
use control::{Config, Kinematics, VecN};
use protocol::{Mode, StateSample};
use std::time::{Duration, Instant};
use tests::live::*;
use tests::*;

/// The demo's start with the feedback off: deterministic from any state, so the test can
/// predict the arm's path with the same law offline.
const TOP: &str = "[sim]\nq0 = [1.550079628, -0.488376467, -0.934331288]\nqd0 = [-2.361482957, 9.229261970, -6.001303515]\n\
                   [feedback]\nmu = 0.0\nenabled = false\n";

fn arm(s: &StateSample) -> (VecN<3>, VecN<3>) {
    (
        VecN::<3>::from_column_slice(&s.q[..3]),
        VecN::<3>::from_column_slice(&s.qd[..3]),
    )
}

/// Smallest distance (m) from the arm at q to a circle's surface.
fn clearance(q: &VecN<3>, center: [f64; 2], radius: f64) -> f64 {
    let cfg = Config::default();
    let mut kin = Kinematics::<3>::default();
    cfg.model::<3>()
        .kinematics(0.0, q, &VecN::zeros(), &mut kin);
    let mut obstacles = control::secondary::ObstacleSet::new();
    let _ = obstacles.push(control::secondary::Obstacle {
        center: control::Vec2::new(center[0], center[1]),
        radius,
        margin: 0.0,
    });
    control::secondary::clearance(&kin, &obstacles).0
}

/// Where the elbow (joint 3) will be `ahead` s after state `s`, taken at controller time `t`,
/// with the filter off: the daemon's law (feedback off) integrated offline.
fn elbow_ahead(s: &StateSample, t: f64, ahead: f64) -> [f64; 2] {
    let mut cfg = Config::preset("demo").unwrap();
    cfg.safety.enabled = false;
    let (model, params, dt) = (cfg.model::<3>(), cfg.law_params(), 1e-4);
    let (q, qd) = arm(s);
    let mut x = control::ArmState { q, qd, phi: 0.0 };
    let mut kin = Kinematics::<3>::default();
    for k in 0..(ahead / dt).round() as usize {
        x = rk4_step(&x, dt, |c, y| {
            let at = t + (k as f64 + c) * dt;
            let o = evaluate(&params, &model, at, 0.0, &y.q, &y.qd, &y.qd, &mut kin);
            plant_derivative(y, &o.qdd, 0.0)
        });
    }
    model.kinematics(0.0, &x.q, &x.qd, &mut kin);
    [kin.points[2].x, kin.points[2].y]
}

/// The stamp (ns) of controller time 0, read off a short recording: t = (stamp − t0)·1e-9.
fn time_origin(sys: &System) -> f64 {
    let (code, _, err) = ctl(&sys.ns, &["record", "start", "clock.csv"]);
    assert_eq!(code, 0, "{err}");
    std::thread::sleep(Duration::from_millis(300));
    let (code, _, err) = ctl(&sys.ns, &["record", "stop"]);
    assert_eq!(code, 0, "{err}");
    let text = std::fs::read_to_string(sys.dir.path().join("out/clock.csv")).unwrap();
    let f: Vec<&str> = text
        .lines()
        .nth(1)
        .expect("a recorded row")
        .split(',')
        .collect();
    let (t, stamp): (f64, f64) = (f[0].parse().unwrap(), f[2].parse().unwrap());
    stamp - t * 1e9
}

/// Rows of a recording after state `from_seq`: (state_seq, q).
fn recorded(path: &std::path::Path, from_seq: u64) -> Vec<(u64, VecN<3>)> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter_map(|f| {
            let seq: u64 = f[1].parse().ok()?;
            let q = VecN::<3>::from_fn(|i, _| f[4 + i].parse().unwrap());
            (seq >= from_seq).then_some((seq, q))
        })
        .collect()
}

/// Adds an obstacle where the elbow is about to pass, records 3 s, and returns the clearances
/// seen from the moment it was added (and the obstacle).
fn obstacle_on_the_path(sys: &System, mon: &mut Monitor) -> (Vec<f64>, [f64; 2]) {
    let t0 = time_origin(sys);
    let (code, _, err) = ctl(&sys.ns, &["record", "start", "path.csv"]);
    assert_eq!(code, 0, "{err}");
    mon.clear();
    mon.wait_for("a state", Duration::from_secs(2), |m| {
        !m.seen_states.is_empty()
    });
    let s = *mon.seen_states.last().unwrap();
    let radius = 0.1;
    // 150 ms ahead, or later if the arm is still too close to that point.
    let center = [0.15, 0.2, 0.25, 0.3, 0.4, 0.5]
        .iter()
        .map(|&a| elbow_ahead(&s, (s.stamp_ns as f64 - t0) * 1e-9, a))
        .find(|&c| clearance(&arm(&s).0, c, radius) > 0.12)
        .expect("an obstacle spot clear of the arm now");
    let (x, y) = (center[0].to_string(), center[1].to_string());
    let r = radius.to_string();
    let (code, _, err) = ctl(&sys.ns, &["obstacle", "add", "--margin", "0", &x, &y, &r]);
    assert_eq!(code, 0, "obstacle add: {err}");
    std::thread::sleep(Duration::from_secs(3));
    let (code, _, err) = ctl(&sys.ns, &["record", "stop"]);
    assert_eq!(code, 0, "{err}");
    let rows = recorded(&sys.dir.path().join("out/path.csv"), s.seq);
    assert!(rows.len() > 2000, "only {} rows recorded", rows.len());
    (
        rows.iter()
            .map(|(_, q)| clearance(q, center, radius))
            .collect(),
        center,
    )
}

#[test]
fn an_obstacle_added_on_the_arms_path_is_never_touched() {
    let _g = serial();
    // The filter on (the service default): no contact, and once clear, never closer than the
    // configured clearance (less 1 mm). Best-effort when blocked, so that the filter drives
    // the arm for the whole recording (the default hold brakes it to rest under the same
    // filter: `blocked_live.rs`).
    let top = format!("{TOP}[safety]\nwhen_blocked = \"best-effort\"\n");
    let sys = start("obstacle-path", &top);
    let mut mon = Monitor::new(&sys.ns);
    std::thread::sleep(Duration::from_millis(1500));
    let (seen, center) = obstacle_on_the_path(&sys, &mut mon);
    let min = seen.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(
        min >= 0.0,
        "a link touched the obstacle at {center:?}: clearance {min}"
    );
    let first_clear = seen.iter().position(|&c| c >= 0.05).unwrap_or(0);
    let after = seen[first_clear..]
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min);
    assert!(
        after >= 0.05 - 1e-3,
        "clearance {after} below 0.05 m after first clearing it"
    );
    let st = status(&sys.ns);
    assert!(
        st["counters"]["safety_active"].as_u64().unwrap() > 0,
        "the filter never acted: {st}"
    );
    assert_eq!(st["mode"], "Run");
    drop(sys);

    // The same with the filter off: the obstacle really was on the path.
    let sys = start("obstacle-path-off", TOP);
    let (code, _, err) = ctl(&sys.ns, &["set", "safety", "off"]);
    assert_eq!(code, 0, "{err}");
    let mut mon = Monitor::new(&sys.ns);
    std::thread::sleep(Duration::from_millis(1500));
    let (seen, _) = obstacle_on_the_path(&sys, &mut mon);
    let contact = seen.iter().filter(|&&c| c < 0.0).count();
    assert!(
        contact > 0,
        "without the filter the arm should have hit the obstacle"
    );
}

#[test]
fn a_runaway_ends_in_a_braked_fault_that_only_resume_leaves() {
    let _g = serial();
    let sys = start("runaway", TOP);
    let mut mon = Monitor::new(&sys.ns);
    std::thread::sleep(Duration::from_millis(1000));
    let (code, out, _) = ctl(&sys.ns, &["resume"]);
    assert_eq!(code, 1, "resume outside FAULT must be refused: {out}");

    // The filter off and a rate limit far below the motion (|q̇| ~ 10 rad/s): a runaway.
    mon.clear();
    let (code, _, err) = ctl(&sys.ns, &["set", "safety", "off", "safety.qd_max", "2"]);
    assert_eq!(code, 0, "{err}");
    let t_set = protocol::monotonic_ns();
    mon.wait_for("a FAULT command", Duration::from_secs(3), |m| {
        m.seen_commands.iter().any(|c| c.mode == Mode::Fault as u32)
    });
    let fault = *mon
        .seen_commands
        .iter()
        .find(|c| c.mode == Mode::Fault as u32)
        .unwrap();
    let ms = (fault.stamp_ns as f64 - t_set as f64) * 1e-6;
    assert!(ms <= 50.0, "FAULT {ms:.1} ms after the limit was set");
    let st = status(&sys.ns);
    assert_eq!(st["mode"], "Fault", "{st}");
    assert!(
        st["fault"].as_str().unwrap().contains("safety.qd_max"),
        "{st}"
    );
    assert_eq!(st["counters"]["faults"], 1);

    // The plant brakes to rest.
    std::thread::sleep(Duration::from_millis(1500));
    mon.clear();
    mon.wait_for("states", Duration::from_secs(2), |m| {
        m.seen_states.len() > 10
    });
    let fastest = mon
        .seen_states
        .iter()
        .map(|s| arm(s).1.amax())
        .fold(0.0, f64::max);
    assert!(fastest < 1e-3, "still moving at {fastest} rad/s in FAULT");
    assert_eq!(status(&sys.ns)["mode"], "Fault", "FAULT must be sticky");

    // Filter back on, resume: RUN again, and the rates stay inside the limit.
    let (code, _, err) = ctl(&sys.ns, &["set", "safety", "on"]);
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = ctl(&sys.ns, &["resume"]);
    assert_eq!(code, 0, "resume: {err}");
    assert!(out.contains("resuming"), "{out}");
    let until = Instant::now() + Duration::from_secs(3);
    while status(&sys.ns)["mode"] != "Run" {
        assert!(Instant::now() < until, "never ran again after resume");
        std::thread::sleep(Duration::from_millis(50));
    }
    mon.clear();
    mon.wait_for("2 s of states", Duration::from_secs(5), |m| {
        m.seen_states.len() > 2000
    });
    let fastest = mon
        .seen_states
        .iter()
        .map(|s| arm(s).1.amax())
        .fold(0.0, f64::max);
    assert!(
        fastest <= 2.0 + 1e-3,
        "|q̇| reached {fastest} rad/s with qd_max = 2"
    );
    // With qd_max = 2 rad/s the joints cannot follow the circle at all (the task needs several
    // rad/s): the planner says so, and the daemon may hold the arm `Blocked` by a joint's rate
    // limit rather than run it off its path. Either way, no second fault.
    let st = status(&sys.ns);
    let blocked_by_rate = st["blocked"]["reason"]
        .as_str()
        .is_some_and(|r| r.contains("rate or acceleration limit"));
    assert!(
        st["mode"] == "Run" || (st["mode"] == "Hold" && blocked_by_rate),
        "{st}"
    );
    assert_eq!(st["counters"]["faults"], 1, "{st}");
    assert_eq!(st["counters"]["resumes"], 1);
}
