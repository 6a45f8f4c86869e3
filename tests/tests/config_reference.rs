//! The configuration reference (docs/config.md) lists every key the code accepts, and only those.
//!
//! The code's side comes from the parsers themselves: every section is a `deny_unknown_fields`
//! struct, and serde's refusal of an unknown key names every field it expects. The book's side is
//! the first column of each section's table. A key added to the code without a line in the book,
//! or a line for a key that is gone, fails here with both names.

use serde::de::DeserializeOwned;
use std::collections::{BTreeMap, BTreeSet};

/// The keys a section's struct accepts, from serde's "expected one of" list.
fn accepted<T: DeserializeOwned + std::fmt::Debug>() -> BTreeSet<String> {
    let e = toml::from_str::<T>("no_such_key_here = 1")
        .unwrap_err()
        .to_string();
    let list = e
        .split("expected one of ")
        .nth(1)
        .or_else(|| e.split("expected ").nth(1))
        .unwrap_or_else(|| panic!("no field list in {e:?}"));
    // "`a`, `b`, `c`" or, for two fields, "`a` or `b`": every name between backticks.
    list.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

/// The book's sections: heading text between backticks (`[robot] (planar)`, `[plant.rigid_body]`) → the
/// keys in the first column of its table.
fn documented() -> BTreeMap<String, BTreeSet<String>> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let text = std::fs::read_to_string(root.join("docs/config.md")).unwrap();
    let mut out: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut section = None;
    for line in text.lines() {
        if let Some(h) = line.strip_prefix("## ") {
            section = h.split('`').nth(1).map(str::to_string);
            continue;
        }
        let (Some(s), Some(row)) = (&section, line.strip_prefix("| `")) else {
            continue;
        };
        let key = row.split('`').next().unwrap().to_string();
        let keys = out.entry(s.clone()).or_default();
        assert!(keys.insert(key.clone()), "{s} lists {key} twice");
    }
    out
}

#[test]
fn the_reference_lists_every_key_of_every_section_and_no_other() {
    use control::config::spatial as sp;
    let code: Vec<(&str, BTreeSet<String>)> = vec![
        // The planar arm's `[robot]` is its `ArmConfig` and the `description` that names it;
        // its `[law]` is every arm's `LawSection`, whose `obstacles` are the top-level list
        // (`control::config::planar_file`).
        ("[robot] (planar)", {
            let mut k = accepted::<control::config::ArmConfig>();
            k.insert("description".into());
            k
        }),
        ("[task]", accepted::<control::config::TaskConfig>()),
        ("[feedback]", accepted::<control::config::FeedbackSection>()),
        ("[sim]", accepted::<control::config::SimSection>()),
        ("[safety]", accepted::<control::safety::SafetySection>()),
        ("[robot]", accepted::<sp::RobotSection>()),
        ("[task] (spatial)", accepted::<sp::TaskSection>()),
        // `obstacles` is the older planar form's `[[control.obstacles]]`.
        ("[law]", {
            let mut k = accepted::<control::config::LawSection>();
            assert!(k.remove("obstacles"));
            k
        }),
        // One entry type for every arm: a disc's keys are a sphere's.
        ("[[obstacles]]", {
            let k = accepted::<control::config::ObstacleConfig>();
            assert_eq!(k, accepted::<sp::SphereEntry>());
            k
        }),
        (
            "[command]",
            accepted::<control::config::command::CommandSection>(),
        ),
        (
            "[command.limits]",
            accepted::<control::command::LimitOverrides>(),
        ),
        ("[daemon]", accepted::<daemon::config::DaemonConfig>()),
        ("[plant]", accepted::<plant::config::PlantConfig>()),
        (
            "[plant.rigid_body]",
            accepted::<control::rigid_body::RigidBodyConfig>(),
        ),
        ("[plant.mujoco]", accepted::<plant::config::MujocoConfig>()),
    ];
    let book = documented();
    let mut problems = Vec::new();
    for (section, keys) in &code {
        // A spatial section shares its heading's name: "[task] (spatial)" is `[task]` under
        // the spatial part of the book.
        let Some(listed) = book.get(*section) else {
            problems.push(format!("the book has no section `{section}`"));
            continue;
        };
        for k in keys.difference(listed) {
            problems.push(format!(
                "{section} {k}: accepted by the code, not in docs/config.md"
            ));
        }
        for k in listed.difference(keys) {
            problems.push(format!(
                "{section} {k}: in docs/config.md, not accepted by the code"
            ));
        }
    }
    for s in book.keys() {
        if !code.iter().any(|(c, _)| c == s) {
            problems.push(format!(
                "docs/config.md documents `{s}`, which no parser reads"
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    // The serde introspection saw the sections' keys (147 since `[safety]` and `[[obstacles]]`
    // are one section each).
    let total: usize = code.iter().map(|(_, k)| k.len()).sum();
    assert!(total >= 147, "{total} keys");
}
