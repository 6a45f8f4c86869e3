//! What a live change changed, in the words of the config file: the answer to `set`, `dfc` and
//! `obstacle`.
//!
//! A client that sets one key wants to see that key's old and new value, and anything the
//! change moved besides (a capped gain, a switch-on time): not the whole law. Both set-ups are
//! written as their TOML and compared key by key, so every key a file can hold is covered
//! without a list to keep in step with the configs.

use control::System;
use std::collections::BTreeMap;

/// `key: old → new` for every key of the file that differs, one per line, then when the change
/// takes effect. `(none)` stands for a key one side does not have.
pub fn describe(old: &System, new: &System) -> String {
    let (a, b) = (flat(old), flat(new));
    let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
    keys.sort();
    keys.dedup();
    let none = "(none)".to_string();
    let mut lines: Vec<String> = keys
        .into_iter()
        .filter(|k| a.get(*k) != b.get(*k))
        .map(|k| {
            let (x, y) = (a.get(k).unwrap_or(&none), b.get(k).unwrap_or(&none));
            format!("{k}: {x} → {y}")
        })
        .collect();
    // With `mu = "auto"` the file holds no number: the gain the adaptation starts from is said
    // on its own line.
    let (mu_old, mu_new, auto) = (old.feedback().mu, new.feedback().mu, new.feedback().auto);
    if let Some(a) = auto.filter(|_| mu_old != mu_new) {
        let capped = if mu_new == a.max_mu {
            " (auto starts from the gain it had, at most max_mu)"
        } else {
            ""
        };
        lines.push(format!("the gain μ: {mu_old} → {mu_new}{capped}"));
    }
    if lines.is_empty() {
        return "nothing changed (every value was already so)".into();
    }
    lines.push("applied at the next tick".into());
    lines.join("\n")
}

/// Every leaf of the set-up's TOML as `section.key` → value; an array of tables (the
/// obstacles) by its entries, `obstacles[1].center` (numbered from 1, as `obstacle ls`).
fn flat(s: &System) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    if let Ok(t) = s.to_toml().parse::<toml::Table>() {
        for (k, v) in &t {
            if k != "daemon" && k != "plant" {
                leaves(k, v, &mut out);
            }
        }
    }
    out
}

fn leaves(prefix: &str, v: &toml::Value, out: &mut BTreeMap<String, String>) {
    match v {
        toml::Value::Table(t) => {
            for (k, v) in t {
                leaves(&format!("{prefix}.{k}"), v, out);
            }
        }
        // An empty list says no more than a missing one (no obstacles).
        toml::Value::Array(a) if a.is_empty() => {}
        toml::Value::Array(a) if a.iter().all(|x| x.is_table()) => {
            for (i, x) in a.iter().enumerate() {
                leaves(&format!("{prefix}[{}]", i + 1), x, out);
            }
        }
        other => {
            out.insert(prefix.to_string(), other.to_string());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_set_answers_with_the_keys_it_changed() {
        let old = System::preset("demo", &control::system::builtin_robot).unwrap();
        let mut new = old.clone();
        new.feedback_section_mut().mu = 0.5;
        new.add_obstacle(&[0.9, 1.1], 0.15, 0.1).unwrap();
        let text = describe(&old, &new);
        assert!(text.contains("feedback.mu: "), "{text}");
        assert!(text.contains(" → 0.5"), "{text}");
        assert!(
            text.contains("obstacles[1].radius: (none) → 0.15") && !text.contains("control."),
            "{text}"
        );
        assert!(!text.contains("feedback.tau"), "{text}");
        assert!(text.ends_with("applied at the next tick"), "{text}");
        assert_eq!(
            describe(&old, &old),
            "nothing changed (every value was already so)"
        );
    }
}
