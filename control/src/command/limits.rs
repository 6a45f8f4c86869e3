//! The limits a command stream must respect: the description's, the maker's table, and the
//! set-up's tightening.
//!
//! A URDF gives position, velocity and effort limits; acceleration, jerk and torque rate are only
//! in the maker's documentation, so a table per robot carries them (the Panda's published joint
//! specification is built in). The set-up may only tighten a described limit: a typo must never
//! let the daemon send what the arm's maker forbids.

use crate::basics::invalid;
use crate::basics::ConfigError;
use crate::model::Chain;
use serde::{Deserialize, Serialize};

/// Franka's published acceleration limits (docs/science.md, "Commanding real arms"), used for the built-in Panda; URDF
/// has no acceleration limits.
pub const PANDA_QDD_MAX: [f64; 7] = [15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0];
/// The acceleration limit of a joint whose robot publishes none (rad/s² or m/s²).
pub const DEFAULT_QDD_MAX: f64 = 10.0;

/// The jerk limit of a joint whose maker publishes none: this many times its acceleration limit
/// per second (the Panda's ratio).
pub const DEFAULT_JERK_PER_QDD: f64 = 500.0;
/// The torque-rate limit of a joint whose maker publishes none (N·m/s).
pub const DEFAULT_TAU_RATE: f64 = 1000.0;
/// The acceleration limit of a joint whose maker publishes none (rad/s² or m/s²).
pub const DEFAULT_QDD: f64 = DEFAULT_QDD_MAX;

/// What a maker publishes beyond the URDF, per joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MakerTable {
    pub robot: &'static str,
    pub q_min: &'static [f64],
    pub q_max: &'static [f64],
    pub qd: &'static [f64],
    pub qdd: &'static [f64],
    pub jerk: &'static [f64],
    pub tau: &'static [f64],
    pub tau_rate: &'static [f64],
}

/// Franka's published joint specification for the Panda (docs/science.md, "Commanding real arms").
pub const PANDA: MakerTable = MakerTable {
    robot: "panda",
    q_min: &[
        -2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973,
    ],
    q_max: &[2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973],
    qd: &[2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61],
    qdd: &PANDA_QDD_MAX,
    jerk: &[7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0],
    tau: &[87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0],
    tau_rate: &[1000.0; 7],
};

impl MakerTable {
    /// The table of a built-in robot with `n` joints, if its maker publishes one.
    pub fn for_robot(description: &str, n: usize) -> Option<&'static MakerTable> {
        (description == PANDA.robot && n == PANDA.qd.len()).then_some(&PANDA)
    }
}

/// Per-joint limits, one array per kind.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits<const N: usize> {
    pub q_min: [f64; N],
    pub q_max: [f64; N],
    pub qd: [f64; N],
    pub qdd: [f64; N],
    pub jerk: [f64; N],
    pub tau: [f64; N],
    pub tau_rate: [f64; N],
    /// Whether `qdd`, `jerk` and `tau_rate` came from a maker's table (else they are chaosd's
    /// defaults, which the set-up may change either way).
    pub published: bool,
}

/// `[command.limits]`: per-joint values that replace the described ones, only downwards.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LimitOverrides {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub velocity: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub acceleration: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub jerk: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub torque: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub torque_rate: Option<Vec<f64>>,
}

/// One kind of override: its name, the file's values, the limit it replaces, and whether a
/// described value binds it.
type Override<'a, const N: usize> = (&'a str, &'a Option<Vec<f64>>, &'a mut [f64; N], bool);

/// A URDF value that means "no limit" (0 or missing) as +∞.
fn described(v: f64) -> f64 {
    if v.is_finite() && v > 0.0 {
        v
    } else {
        f64::INFINITY
    }
}

fn from_table(table: Option<&[f64]>, i: usize, default: f64) -> f64 {
    table.and_then(|t| t.get(i).copied()).unwrap_or(default)
}

impl<const N: usize> JointLimits<N> {
    /// No limit at all (the paper's planar arm, which has no maker).
    pub const NONE: Self = Self {
        q_min: [f64::NEG_INFINITY; N],
        q_max: [f64::INFINITY; N],
        qd: [f64::INFINITY; N],
        qdd: [f64::INFINITY; N],
        jerk: [f64::INFINITY; N],
        tau: [f64::INFINITY; N],
        tau_rate: [f64::INFINITY; N],
        published: false,
    };

    /// The description's limits: the URDF's position, velocity and effort, the tighter of them
    /// and the maker's table where there is one, and the table (or chaosd's defaults) for the
    /// rest. `N` must be the chain's joint count.
    pub fn described(chain: &Chain, table: Option<&MakerTable>) -> Self {
        let mut l = Self::NONE;
        l.published = table.is_some();
        for (i, j) in chain.joints.iter().enumerate().take(N) {
            let lim = &j.limits;
            l.q_min[i] = lim
                .lower
                .max(from_table(table.map(|t| t.q_min), i, f64::NEG_INFINITY));
            l.q_max[i] = lim
                .upper
                .min(from_table(table.map(|t| t.q_max), i, f64::INFINITY));
            l.qd[i] =
                described(lim.velocity).min(from_table(table.map(|t| t.qd), i, f64::INFINITY));
            l.tau[i] =
                described(lim.effort).min(from_table(table.map(|t| t.tau), i, f64::INFINITY));
            l.qdd[i] = from_table(table.map(|t| t.qdd), i, DEFAULT_QDD);
            l.jerk[i] = from_table(table.map(|t| t.jerk), i, DEFAULT_JERK_PER_QDD * l.qdd[i]);
            l.tau_rate[i] = from_table(table.map(|t| t.tau_rate), i, DEFAULT_TAU_RATE);
        }
        l
    }

    /// These limits with the set-up's overrides (`prefix` names the table in errors, e.g.
    /// `command.limits`). A value above a described limit is refused, naming the field and the
    /// joint; chaosd's own defaults (no maker table) may be set to any positive value.
    pub fn tightened(mut self, o: &LimitOverrides, prefix: &str) -> Result<Self, ConfigError> {
        let published = self.published;
        let kinds: [Override<'_, N>; 5] = [
            ("velocity", &o.velocity, &mut self.qd, true),
            ("acceleration", &o.acceleration, &mut self.qdd, published),
            ("jerk", &o.jerk, &mut self.jerk, published),
            ("torque", &o.torque, &mut self.tau, true),
            ("torque_rate", &o.torque_rate, &mut self.tau_rate, published),
        ];
        for (name, values, limit, binding) in kinds {
            let Some(values) = values else { continue };
            let field = format!("{prefix}.{name}");
            if values.len() != N {
                return Err(invalid(
                    &field,
                    values,
                    &format!("{N} numbers, one per joint"),
                ));
            }
            for (i, &v) in values.iter().enumerate() {
                if !(v.is_finite() && v > 0.0) {
                    return Err(invalid(&field, values, "finite numbers > 0"));
                }
                if binding && v > limit[i] {
                    return Err(invalid(
                        &field,
                        values,
                        &format!(
                            "at most the description's limit for joint {} ({}): the set-up may \
                             tighten a limit, never loosen it",
                            i + 1,
                            limit[i]
                        ),
                    ));
                }
                limit[i] = v;
            }
        }
        Ok(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::builtin;

    fn panda() -> JointLimits<7> {
        let chain = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap();
        JointLimits::described(&chain, MakerTable::for_robot("panda", 7))
    }

    #[test]
    fn the_panda_gets_franka_s_published_table() {
        let l = panda();
        assert_eq!(
            l.jerk,
            [7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0]
        );
        assert_eq!(l.tau, [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]);
        assert_eq!(l.qd[4], 2.61);
        assert_eq!((l.q_min[3], l.q_max[3]), (-3.0718, -0.0698));
        assert!(l.published);
    }

    #[test]
    fn overrides_only_tighten_and_name_the_field() {
        let mut o = LimitOverrides {
            jerk: Some(vec![1000.0; 7]),
            ..Default::default()
        };
        assert_eq!(
            panda().tightened(&o, "command.limits").unwrap().jerk,
            [1000.0; 7]
        );
        o.jerk = Some(vec![8000.0; 7]);
        let e = panda()
            .tightened(&o, "command.limits")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("command.limits.jerk") && e.contains("joint 1"),
            "{e}"
        );
        o.jerk = Some(vec![1.0; 6]);
        let e = panda()
            .tightened(&o, "command.limits")
            .unwrap_err()
            .to_string();
        assert!(e.contains("7 numbers"), "{e}");
        o.jerk = None;
        o.torque = Some(vec![f64::NAN; 7]);
        assert!(panda().tightened(&o, "command.limits").is_err());
    }
}
