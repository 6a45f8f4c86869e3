//! The law in a sampled-data loop (what the daemon and plant do): a first-order hold at 1 kHz
//! follows the continuous system; a zero-order hold does not.

use control::hold::{command, integrate};
use control::tick_law::LawScratch;
use control::{ArmState, Config, DelayLine, RunStats, Simulation};

/// Runs the sampled loop for `seconds`: law at each tick, hold over the period. Returns
/// (RMS tracking error after 2 s, mean period residual over the last 3 s).
fn sampled(rate: f64, first_order: bool, seconds: f64) -> (f64, f64) {
    let cfg = near_orbit();
    let (law, m) = (cfg.tick_law::<3>(), cfg.model::<3>());
    let dt = 1.0 / rate;
    let mut x: ArmState<3> = cfg.initial_state();
    let mut dl = DelayLine::<3>::new(2.0 / dt, x.qd);
    let mut k = LawScratch::default();
    let (mut sq, mut n, mut res, mut nr) = (0.0, 0, 0.0, 0);
    for i in 0..(seconds / dt) as usize {
        let t = i as f64 * dt;
        dl.push(x.qd);
        let c = command(&law, t, &x, dt, first_order, |s| dl.sample(s / dt), &mut k);
        if t > 2.0 {
            sq += c.output.tracking_error.powi(2);
            n += 1;
        }
        if t > seconds - 3.0 {
            res += c.output.period_residual;
            nr += 1;
        }
        x = integrate(&m, &x, &c.qdd, &c.qddd, 0.0, 2.0 * dt, dt, 4);
    }
    ((sq / n as f64).sqrt(), res / nr as f64)
}

/// A point near the μ = 0.1 period-1 orbit, nudged off it.
fn near_orbit() -> Config {
    let mut cfg = Config::preset("paper").unwrap();
    cfg.sim.q0 = Some(vec![1.550079628, -0.488376467, -0.934331288]);
    cfg.sim.qd0 = Some(vec![-4.311482957, 9.229261970, -4.051303515]);
    cfg
}

#[test]
fn first_order_hold_follows_the_continuous_system() {
    let cfg = near_orbit();
    let mut sim = Simulation::new(
        cfg.model::<3>(),
        cfg.law_params(),
        1e-3,
        cfg.initial_state(),
        2.0,
    );
    let x0 = cfg.initial_state::<3>();
    let mut stats = RunStats::new(&cfg.law_params(), 1e-3, 10.0, 2.0, &x0);
    for k in 0..10_000 {
        let x = *sim.state();
        let o = sim.step();
        stats.record(k, &x, &o);
    }
    let cont = stats.summary().period_residual_final.unwrap();
    let (foh_track, foh_res) = sampled(1000.0, true, 10.0);
    let (zoh_track, zoh_res) = sampled(1000.0, false, 10.0);
    assert!(foh_track < 1e-4, "first-order hold tracks to {foh_track} m");
    assert!(
        zoh_track > 10.0 * foh_track,
        "zero-order hold {zoh_track} m vs first-order {foh_track} m"
    );
    assert!(
        (foh_res - cont).abs() < 0.3 * cont,
        "residual: sampled {foh_res}, continuous {cont}"
    );
    assert!(
        zoh_res > 3.0 * cont,
        "the zero-order hold should lose the orbit (residual {zoh_res} vs {cont})"
    );
}

#[test]
fn a_late_command_is_applied_where_its_ramp_left_off() {
    // Integrating one period with the ramp offset by one period equals integrating the second
    // half of a two-period interval.
    let cfg = Config::preset("paper").unwrap();
    let m = cfg.model::<3>();
    let x: ArmState<3> = cfg.initial_state();
    let (u, j) = (
        nalgebra::Vector3::new(1.0, -2.0, 0.5),
        nalgebra::Vector3::new(100.0, 50.0, -80.0),
    );
    let two = integrate(&m, &x, &u, &j, 0.0, 1.0, 2e-3, 8);
    let first = integrate(&m, &x, &u, &j, 0.0, 1.0, 1e-3, 4);
    let second = integrate(&m, &first, &u, &j, 1e-3, 1.0, 1e-3, 4);
    assert!((two.qd - second.qd).norm() < 1e-12 && (two.q - second.q).norm() < 1e-12);
    // The clamp stops the ramp.
    let clamped = integrate(&m, &x, &u, &j, 0.0, 0.0, 1e-3, 4);
    let zoh = integrate(&m, &x, &u, &(j * 0.0), 0.0, 1.0, 1e-3, 4);
    assert_eq!(clamped.qd, zoh.qd);
}
