//! The paper's planar arm written in the schema every arm shares: a `[robot]` table
//! (`description = "planar"` and the arm's links and masses), `[task]`, `[law]`, `[feedback]`,
//! `[safety]`, `[[obstacles]]`, `[sim]`, `[daemon]`, `[plant]`, as a URDF robot's file is.
//!
//! Why a file layer and not a second config type: the sections are the planar arm's own
//! ([`ArmConfig`], [`TaskConfig`], [`LawSection`], …), only where they sit in the file
//! changes. [`Config`] keeps its fields; this module moves `[arm]` into `[robot]`, `[control]`
//! into `[law]` and `[[control.obstacles]]` to the top level on the way in, and back on the way
//! out. The older form (`[arm]`, `[control]`) still loads unchanged, so recordings and files
//! written before keep their meaning; `chaosctl config` prints this one.
//!
//! The field names in a refusal follow the form the text was written in
//! ([`to_legacy_key`]): `law.kp` in this form, `control.kp` in the older one.

use super::{
    ArmConfig, Config, FeedbackSection, LawSection, ObstacleConfig, SafetySection, SimSection,
    TaskConfig,
};
use crate::basics::{excerpt, invalid, ConfigError};
use serde::{Deserialize, Serialize};

/// The `robot.description` that names the paper's planar arm (closed-form kinematics and
/// dynamics; `planar3`, a URDF of the same arm in 3-D, is a chain like any other).
pub const PLANAR_ROBOT: &str = "planar";

/// The file as read: `[robot]` is taken apart by hand (its `description` first, the rest is
/// [`ArmConfig`]), every other section is the planar arm's own type.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileIn {
    robot: toml::Table,
    #[serde(default)]
    task: TaskConfig,
    #[serde(default)]
    law: LawSection,
    #[serde(default)]
    feedback: FeedbackSection,
    #[serde(default)]
    safety: SafetySection,
    #[serde(default)]
    obstacles: Vec<ObstacleConfig>,
    #[serde(default)]
    sim: SimSection,
    daemon: Option<toml::Table>,
    plant: Option<toml::Table>,
}

/// The file as printed, in the order a reader wants it.
#[derive(Serialize)]
struct FileOut<'a> {
    robot: RobotOut<'a>,
    task: &'a TaskConfig,
    law: LawSection,
    feedback: &'a FeedbackSection,
    safety: &'a SafetySection,
    #[serde(skip_serializing_if = "<[_]>::is_empty")]
    obstacles: &'a [ObstacleConfig],
    sim: &'a SimSection,
    #[serde(skip_serializing_if = "Option::is_none")]
    daemon: &'a Option<toml::Table>,
    #[serde(skip_serializing_if = "Option::is_none")]
    plant: &'a Option<toml::Table>,
}

#[derive(Serialize)]
struct RobotOut<'a> {
    description: &'static str,
    #[serde(flatten)]
    arm: &'a ArmConfig,
}

/// Whether a parsed file's `[robot]` names the planar arm.
pub fn names_planar(file: &toml::Table) -> bool {
    file.get("robot")
        .and_then(|r| r.get("description"))
        .and_then(|d| d.as_str())
        == Some(PLANAR_ROBOT)
}

/// Reads the shared form (the caller has seen `robot.description = "planar"`).
pub(crate) fn read(text: &str) -> Result<Config, ConfigError> {
    if text
        .parse::<toml::Table>()
        .is_ok_and(|t| t.contains_key("command"))
    {
        return Err(invalid(
            "command",
            "a [command] table",
            "the planar arm is commanded in acceleration only (it has no URDF limits or dynamics for the other interfaces): remove [command]",
        ));
    }
    let f: FileIn = toml::from_str(text).map_err(|e| super::parse_error(text, &e))?;
    let mut robot = f.robot;
    robot.remove("description");
    let arm: ArmConfig = toml::Value::Table(robot)
        .try_into()
        .map_err(|e: toml::de::Error| ConfigError::Parse(excerpt(&format!("robot: {e}"))))?;
    if !f.law.obstacles.is_empty() {
        return Err(invalid(
            "law.obstacles",
            format!("{} entries", f.law.obstacles.len()),
            "the obstacles are a top-level [[obstacles]] list, as for every robot",
        ));
    }
    Ok(Config {
        robot: super::Robot::Planar(super::PlanarRobot {
            arm,
            task: f.task,
            obstacles: f.obstacles,
        }),
        law: f.law,
        feedback: f.feedback,
        sim: f.sim,
        safety: f.safety,
        daemon: f.daemon,
        plant: f.plant,
    })
}

/// Prints `c` in the shared form.
pub(crate) fn write(c: &Config) -> String {
    let p = c.planar_part();
    let law = LawSection {
        obstacles: Vec::new(),
        ..c.law.clone()
    };
    let file = FileOut {
        robot: RobotOut {
            description: PLANAR_ROBOT,
            arm: &p.arm,
        },
        task: &p.task,
        law,
        feedback: &c.feedback,
        safety: &c.safety,
        obstacles: &p.obstacles,
        sim: &c.sim,
        daemon: &c.daemon,
        plant: &c.plant,
    };
    toml::to_string(&file).unwrap_or_default()
}

/// The key a refusal names, as the older form spells it: `robot.links` → `arm.links`,
/// `law.kp` → `control.kp`, `obstacles[0].radius` → `control.obstacles[0].radius`.
///
/// ```
/// use control::config::planar_file::to_legacy_key;
/// assert_eq!(to_legacy_key("law.kp"), "control.kp");
/// assert_eq!(to_legacy_key("obstacles[1].radius"), "control.obstacles[1].radius");
/// assert_eq!(to_legacy_key("robot.links[0]"), "arm.links[0]");
/// assert_eq!(to_legacy_key("feedback.mu"), "feedback.mu");
/// ```
pub fn to_legacy_key(key: &str) -> String {
    for (new, old) in [
        ("robot.", "arm."),
        ("law.", "control."),
        ("obstacles", "control.obstacles"),
    ] {
        if let Some(rest) = key.strip_prefix(new) {
            return format!("{old}{rest}");
        }
    }
    key.to_string()
}

/// `e` with its field named as the older form spells it (see [`to_legacy_key`]).
pub fn in_legacy_terms(e: ConfigError) -> ConfigError {
    match e {
        ConfigError::Invalid {
            field,
            value,
            expected,
        } => ConfigError::Invalid {
            field: to_legacy_key(&field),
            value,
            expected: expected
                .replace("[[obstacles]]", "[[control.obstacles]]")
                .replace("robot.links", "arm.links"),
        },
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::PRESETS;

    #[test]
    fn every_planar_preset_prints_as_a_robot_and_reads_back_the_same() {
        for name in PRESETS {
            let c = Config::preset(name).unwrap();
            let text = c.to_toml();
            assert!(
                text.starts_with("[robot]\ndescription = \"planar\"\n"),
                "{name}:\n{text}"
            );
            for older in ["[arm]", "[control]", "control.obstacles"] {
                assert!(!text.contains(older), "{name} prints {older}:\n{text}");
            }
            assert!(!crate::config::spatial::is_spatial(&text), "{name}");
            assert_eq!(Config::parse(&text).unwrap(), c, "{name}:\n{text}");
        }
        let text = Config::preset("paper-obstacle").unwrap().to_toml();
        assert!(
            text.contains("[[obstacles]]\ncenter = [0.0, 1.6]"),
            "{text}"
        );
    }

    #[test]
    fn the_older_form_still_reads_and_means_the_same() {
        for name in PRESETS {
            let c = Config::preset(name).unwrap();
            let older = crate::config::file::older_text(&c);
            assert!(older.contains("[arm]") && !older.contains("[robot]"));
            assert_eq!(Config::parse(&older).unwrap(), c, "{name}");
        }
        let hand = "[arm]\nlinks = [1.0, 1.2, 0.8]\n[control]\nkp = 30.0\n\
                    [[control.obstacles]]\ncenter = [0.0, 1.6]\nradius = 0.2\n";
        let shared = "[robot]\ndescription = \"planar\"\nlinks = [1.0, 1.2, 0.8]\n\
                      [law]\nkp = 30.0\n[[obstacles]]\ncenter = [0.0, 1.6]\nradius = 0.2\n";
        assert_eq!(Config::parse(hand).unwrap(), Config::parse(shared).unwrap());
    }

    #[test]
    fn a_refusal_names_the_key_as_the_file_spells_it() {
        let err = |t: &str| Config::parse(t).unwrap_err().to_string();
        let shared = "[robot]\ndescription = \"planar\"\n";
        let e = err(&format!("{shared}[law]\nkp = -3\n"));
        assert!(e.contains("law.kp") && !e.contains("control"), "{e}");
        assert!(err("[control]\nkp = -3\n").contains("control.kp"));
        let e = err(&format!("{shared}links = [1.0]\n"));
        assert!(e.contains("robot.links"), "{e}");
        assert!(err("[arm]\nlinks = [1.0]\n").contains("arm.links"));
        let e = err(&format!("{shared}[law]\nsecondary = \"obstacles\"\n"));
        assert!(e.contains("[[obstacles]]") && !e.contains("control"), "{e}");
        let e = err("[control]\nsecondary = \"obstacles\"\n");
        assert!(e.contains("[[control.obstacles]]"), "{e}");
    }

    #[test]
    fn misplaced_or_unknown_keys_are_refused_by_name() {
        let err = |t: &str| Config::parse(t).unwrap_err().to_string();
        let shared = "[robot]\ndescription = \"planar\"\n";
        let e = err(&format!("{shared}lnks = [1.0, 1.0]\n"));
        assert!(e.contains("robot") && e.contains("lnks"), "{e}");
        let e = err(&format!(
            "{shared}[[law.obstacles]]\ncenter = [0.0, 1.6]\nradius = 0.2\n"
        ));
        assert!(
            e.contains("law.obstacles") && e.contains("[[obstacles]]"),
            "{e}"
        );
        let e = err(&format!("{shared}[control]\nkp = 1.0\n"));
        assert!(e.contains("control") && e.contains("line 3"), "{e}");
        let e = err(&format!("{shared}[command]\nmode = \"torque\"\n"));
        assert!(
            e.contains("command") && e.contains("acceleration only"),
            "{e}"
        );
        let e = err("[robot]\ndescription = \"panda\"\n");
        assert!(e.contains("spatial"), "{e}");
    }
}
