//! The robots chaosd ships, by name: their URDFs are compiled in, so a name works anywhere.

use super::ModelError;

/// Built-in robot names and their descriptions (`robots/*.urdf`).
pub const BUILTIN: [(&str, &str); 2] = [
    ("panda", include_str!("../../../robots/panda.urdf")),
    ("planar3", include_str!("../../../robots/planar3.urdf")),
];

/// The URDF text of a built-in robot.
///
/// ```
/// assert!(control::model::builtin("panda").unwrap().contains("panda_joint7"));
/// assert!(control::model::builtin("pr2").is_err());
/// ```
pub fn builtin(name: &str) -> Result<&'static str, ModelError> {
    BUILTIN
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, text)| *text)
        .ok_or_else(|| ModelError::UnknownRobot {
            name: name.to_string(),
            known: BUILTIN.map(|(n, _)| n).join(", "),
        })
}
