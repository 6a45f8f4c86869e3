//! The runaway guard: the last line behind the validation and the safety filter.
//!
//! Validation refuses gains that cannot be stable at the loop's rate, and the filter keeps the
//! command inside the joint limits; but a plant that does not follow its commands, a model that
//! does not match the arm, or a filter switched off can still run away. The guard watches what the
//! loop measures and computes, and trips the daemon into FAULT (the plant brakes) when:
//! - the law's result is not finite (at once);
//! - a measured joint rate stays beyond `safety.qd_max` (5 % slack) for `safety.guard_time`;
//! - the law asks for more than `safety.qdd_max` for `safety.guard_time`, unless a feasible
//!   filter clamps the command while the arm tracks its path: then the plant never gets the
//!   excess, and clamping it is the filter's job on every tick it acts (a steered arm passing an
//!   obstacle asks 1.1× for a few ticks and tracks to a fraction of a millimetre). A clamped
//!   demand with tracking lost still counts: the law is fighting something;
//! - the tracking error stays above `safety.guard_tracking_error` and keeps growing for
//!   `safety.guard_growth_time`.
//!
//! Times are controller time (the states' stamps), so a stalled loop cannot fake a duration.
//!
//! Re-entry: when the controller takes over an arm that was not following it (a restarted plant,
//! the end of a HOLD, a plant that braked on its own because commands stopped coming, e.g. while
//! this daemon was stalled, or states that went missing for five periods or more while either
//! process was stalled, at most once every 5 s), the law asks for a burst of acceleration to
//! catch the circle again.
//! That burst is the filter's job to clamp, not a runaway, so for [`REENTRY_S`] after a re-entry
//! the demand criterion alone is not applied; the rate, growth and non-finite criteria are.
//! The same holds after the safety filter left the null space: it took the hand off its path on
//! purpose (an obstacle in the way, a new one put on the arm), and the law's demand to get back
//! is the filter's to clamp, as it does on every tick it acts.
//! FAULT is sticky: only an operator's `chaosctl resume` leaves it.

use control::basics::flags;
use control::safety::SafetyParams;
use control::{ControlOutput, VecN};

/// Measured rates up to this factor of `qd_max` are tolerated (sampling, the filter's margin).
pub const RATE_SLACK: f64 = 1.05;
/// How long after a re-entry (controller time, s) the demand criterion waits.
pub const REENTRY_S: f64 = 0.5;
/// The tracking error is compared with its value this long ago (s) to decide "growing".
const GROWTH_STEP: f64 = 0.01;

/// Why the guard tripped. Small and `Copy`: it rides in a tick record to the reporter, which
/// formats it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FaultReason {
    /// The daemon was in FAULT when it last stopped (`persist`): a restart does not clear it.
    Restored,
    NonFinite,
    Rate {
        joint: usize,
        value: f64,
        limit: f64,
        for_s: f64,
    },
    Demand {
        ratio: f64,
        for_s: f64,
    },
    TrackingGrowth {
        error: f64,
        limit: f64,
        for_s: f64,
    },
    /// The device stopped with a reflex error (the state sample's `device` status), on
    /// `joint` (1-based; 0: not one joint).
    Device {
        status: protocol::DeviceStatus,
        joint: u32,
    },
}

impl std::fmt::Display for FaultReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            FaultReason::Restored => write!(f, "the daemon was in FAULT when it last stopped, and nobody resumed it"),
            FaultReason::NonFinite => write!(f, "the control law produced a non-finite command"),
            FaultReason::Rate { joint, value, limit, for_s } => write!(
                f,
                "joint {} rate {value:.2} rad/s beyond safety.qd_max = {limit} rad/s for {:.0} ms",
                joint + 1,
                for_s * 1e3
            ),
            FaultReason::Demand { ratio, for_s } => write!(
                f,
                "the law asked for {ratio:.1}× safety.qdd_max for {:.0} ms",
                for_s * 1e3
            ),
            FaultReason::TrackingGrowth { error, limit, for_s } => write!(
                f,
                "tracking error {error:.3} m above safety.guard_tracking_error = {limit} m and growing for {for_s:.2} s"
            ),
            FaultReason::Device { status, joint: 0 } => write!(f, "the device stopped: {status}"),
            FaultReason::Device { status, joint } => {
                write!(f, "the device stopped: joint {joint} {status}")
            }
        }
    }
}

/// The guard's memory between ticks.
#[derive(Clone, Copy, Debug, Default)]
pub struct Guard {
    rate_since: Option<f64>,
    demand_since: Option<f64>,
    growth_since: Option<f64>,
    /// (controller time, tracking error) of the last growth comparison.
    growth_ref: Option<(f64, f64)>,
    /// Until this controller time the demand criterion is not applied (a re-entry).
    reentry_until: Option<f64>,
}

impl Guard {
    /// Forgets everything (after a resume or a restarted plant).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// The controller takes over an arm that was not following it at controller time `t`: see
    /// the module's note on re-entry.
    pub fn reenter(&mut self, t: f64) {
        self.demand_since = None;
        self.reentry_until = Some(t + REENTRY_S);
    }

    /// Checks one tick at controller time `t`: measured rates `qd`, the law's output `out`.
    pub fn check<const N: usize>(
        &mut self,
        t: f64,
        p: &SafetyParams,
        qd: &VecN<N>,
        out: &ControlOutput<N>,
    ) -> Option<FaultReason> {
        if out.flags & flags::NONFINITE != 0 {
            return Some(FaultReason::NonFinite);
        }
        let (joint, ratio) = (0..N)
            .map(|i| (i, qd[i].abs() / p.qd_max[i]))
            .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
        if let Some(for_s) = held(&mut self.rate_since, ratio > RATE_SLACK, t, p.guard_time) {
            return Some(FaultReason::Rate {
                joint,
                value: qd[joint],
                limit: p.qd_max[joint],
                for_s,
            });
        }
        if out.flags & flags::SAFETY_LEFT_NULL_SPACE != 0 {
            self.reenter(t);
        }
        let settling = self.reentry_until.is_some_and(|until| t < until);
        let clamped = out.flags & flags::SAFETY_ACTIVE != 0
            && out.flags & (flags::SAFETY_INFEASIBLE | flags::TRACK_LOST) == 0;
        let over = out.demand > 1.0 && !settling && !clamped;
        if let Some(for_s) = held(&mut self.demand_since, over, t, p.guard_time) {
            return Some(FaultReason::Demand {
                ratio: out.demand,
                for_s,
            });
        }
        self.check_growth(t, p, out.tracking_error)
    }

    fn check_growth(&mut self, t: f64, p: &SafetyParams, e: f64) -> Option<FaultReason> {
        let (t_ref, e_ref) = *self.growth_ref.get_or_insert((t, e));
        if t - t_ref < GROWTH_STEP {
            return None;
        }
        self.growth_ref = Some((t, e));
        let growing = e > p.guard_tracking_error && e > e_ref;
        held(&mut self.growth_since, growing, t, p.guard_growth_time).map(|for_s| {
            FaultReason::TrackingGrowth {
                error: e,
                limit: p.guard_tracking_error,
                for_s,
            }
        })
    }
}

/// Tracks how long `cond` has held; returns that time once it reaches `limit`.
fn held(since: &mut Option<f64>, cond: bool, t: f64, limit: f64) -> Option<f64> {
    if !cond {
        *since = None;
        return None;
    }
    let start = *since.get_or_insert(t);
    (t - start >= limit).then_some(t - start)
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::Config;

    fn output(tracking_error: f64, demand: f64, flags: u32) -> ControlOutput<3> {
        let cfg = Config::preset("demo").unwrap();
        let mut kin = control::Kinematics::default();
        let z = VecN::<3>::zeros();
        let mut o = control::law::evaluate(
            &cfg.law_params(),
            &cfg.model::<3>(),
            0.0,
            0.0,
            &VecN::<3>::new(0.0, 1.5, 1.5),
            &z,
            &z,
            &mut kin,
        );
        (o.tracking_error, o.demand, o.flags) = (tracking_error, demand, flags);
        o
    }

    #[test]
    fn trips_on_each_condition_after_its_time_and_not_before() {
        let p = Config::preset("demo").unwrap().law_params().core.safety;
        let calm = output(0.0, 0.5, 0);
        let slow = VecN::<3>::new(1.0, -2.0, 3.0);
        let fast = VecN::<3>::new(1.0, -25.0, 3.0);
        let mut g = Guard::default();
        assert_eq!(g.check(0.0, &p, &slow, &calm), None);
        assert_eq!(
            g.check(0.001, &p, &slow, &output(0.0, 0.5, flags::NONFINITE)),
            Some(FaultReason::NonFinite)
        );

        // A rate beyond the limit: not at 19 ms, at 20 ms.
        let mut g = Guard::default();
        for k in 0..20 {
            assert_eq!(g.check(k as f64 * 1e-3, &p, &fast, &calm), None, "tick {k}");
        }
        match g.check(0.020, &p, &fast, &calm) {
            Some(FaultReason::Rate {
                joint: 1, value, ..
            }) => assert_eq!(value, -25.0),
            other => panic!("{other:?}"),
        }
        // Interrupted excursions never add up.
        let mut g = Guard::default();
        for k in 0..100 {
            let qd = if k % 10 == 9 { slow } else { fast };
            assert_eq!(g.check(k as f64 * 1e-3, &p, &qd, &calm), None);
        }
        // The law's demand.
        let mut g = Guard::default();
        let greedy = output(0.0, 3.0, 0);
        let tripped =
            (0..50).find_map(|k| g.check(k as f64 * 1e-3, &p, &slow, &greedy).map(|r| (k, r)));
        assert!(
            matches!(tripped, Some((20, FaultReason::Demand { .. }))),
            "{tripped:?}"
        );
        // The same demand clamped by a feasible filter while the arm tracks: the plant never
        // gets it.
        let mut g = Guard::default();
        let clamped = output(0.0, 3.0, flags::SAFETY_ACTIVE);
        for k in 0..100 {
            assert_eq!(
                g.check(k as f64 * 1e-3, &p, &slow, &clamped),
                None,
                "tick {k}"
            );
        }
        // Clamped, but the arm has lost its path: the law is fighting something.
        let mut g = Guard::default();
        let fighting = output(0.0, 3.0, flags::SAFETY_ACTIVE | flags::TRACK_LOST);
        let tripped = (0..50).find_map(|k| {
            g.check(k as f64 * 1e-3, &p, &slow, &fighting)
                .map(|r| (k, r))
        });
        assert!(
            matches!(tripped, Some((20, FaultReason::Demand { .. }))),
            "{tripped:?}"
        );
        // An infeasible filter holds nothing: it counts again.
        let mut g = Guard::default();
        let unheld = output(0.0, 3.0, flags::SAFETY_ACTIVE | flags::SAFETY_INFEASIBLE);
        let tripped =
            (0..50).find_map(|k| g.check(k as f64 * 1e-3, &p, &slow, &unheld).map(|r| (k, r)));
        assert!(
            matches!(tripped, Some((20, FaultReason::Demand { .. }))),
            "{tripped:?}"
        );
    }

    #[test]
    fn the_filter_leaving_the_null_space_opens_the_same_window_as_a_reentry() {
        let p = Config::preset("demo").unwrap().law_params().core.safety;
        let slow = VecN::<3>::new(1.0, -2.0, 3.0);
        let braked = output(0.0, 3.0, flags::SAFETY_LEFT_NULL_SPACE);
        let catching_up = output(0.0, 3.0, 0);
        let mut g = Guard::default();
        for k in 0..100 {
            assert_eq!(g.check(k as f64 * 1e-3, &p, &slow, &braked), None);
        }
        // Released at 0.1 s: the demand to get back waits REENTRY_S, then counts.
        let ticks = (REENTRY_S * 1e3) as usize;
        let tripped = (100..100 + ticks + 50).find_map(|k| {
            g.check(k as f64 * 1e-3, &p, &slow, &catching_up)
                .map(|r| (k, r))
        });
        assert!(
            matches!(tripped, Some((k, FaultReason::Demand { .. })) if k >= 99 + ticks + 20),
            "{tripped:?}"
        );
    }

    #[test]
    fn after_a_reentry_only_the_demand_criterion_waits() {
        let p = Config::preset("demo").unwrap().law_params().core.safety;
        let slow = VecN::<3>::new(1.0, -2.0, 3.0);
        let fast = VecN::<3>::new(1.0, -25.0, 3.0);
        let greedy = output(0.0, 3.0, 0);
        let mut g = Guard::default();
        g.reenter(10.0);
        // Catching up for the whole window: no trip.
        let ticks = (REENTRY_S * 1e3) as usize;
        for k in 0..ticks {
            assert_eq!(g.check(10.0 + k as f64 * 1e-3, &p, &slow, &greedy), None);
        }
        // A demand that outlasts the window trips guard_time after it ends.
        let tripped = (ticks..ticks + 50).find_map(|k| {
            g.check(10.0 + k as f64 * 1e-3, &p, &slow, &greedy)
                .map(|r| (k, r))
        });
        assert!(
            matches!(tripped, Some((k, FaultReason::Demand { .. })) if (ticks + 20..=ticks + 21).contains(&k)),
            "{tripped:?}"
        );
        // The rate criterion does not wait.
        let mut g = Guard::default();
        g.reenter(0.0);
        let tripped =
            (0..50).find_map(|k| g.check(k as f64 * 1e-3, &p, &fast, &greedy).map(|r| (k, r)));
        assert!(
            matches!(tripped, Some((20, FaultReason::Rate { .. }))),
            "{tripped:?}"
        );
    }

    #[test]
    fn a_large_but_shrinking_tracking_error_is_a_start_up_not_a_runaway() {
        let p = Config::preset("demo").unwrap().law_params().core.safety;
        let qd = VecN::<3>::zeros();
        let mut g = Guard::default();
        // 1.8 m off the circle and converging (the paper's start), with 0.1 s of growth first.
        for k in 0..3000 {
            let t = k as f64 * 1e-3;
            let e = if t < 0.1 {
                1.8 + t
            } else {
                1.9 * (-(t - 0.1) * 3.0).exp()
            };
            assert_eq!(g.check(t, &p, &qd, &output(e, 0.5, 0)), None, "t = {t}");
        }
        // Growing without bound: a fault after guard_growth_time.
        let mut g = Guard::default();
        let tripped = (0..3000).find_map(|k| {
            let t = k as f64 * 1e-3;
            g.check(t, &p, &qd, &output(1.2 + t, 0.5, 0))
                .map(|r| (t, r))
        });
        match tripped {
            Some((t, FaultReason::TrackingGrowth { .. })) => {
                assert!((0.5..0.53).contains(&t), "{t}")
            }
            other => panic!("{other:?}"),
        }
    }
}
