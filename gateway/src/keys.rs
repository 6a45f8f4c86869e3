//! The Zenoh key space and the messages on it: the gateway's wire contract.
//!
//! ```text
//! chaosd/<host>/<namespace>/telemetry   publication: one JSON object per daemon telemetry sample
//!                                       (the fields of `chaosctl watch --json`, plus host and
//!                                       namespace), as often as the daemon publishes (20 Hz)
//! chaosd/<host>/<namespace>/status      publication: the daemon's status JSON once a second,
//!                                       with a "gateway" object (host, namespace, access)
//! chaosd/<host>/<namespace>/control     queryable: a `Request` in, a `Reply` out
//! ```
//!
//! `<host>` is the gateway's `--host` (default: the machine's host name), `<namespace>` the
//! daemon's iceoryx2 namespace. Both are single key chunks: `[A-Za-z0-9_.-]`, no `/` or wildcard.

use serde::{Deserialize, Serialize};

/// The first chunk of every key.
pub const ROOT: &str = "chaosd";

/// A host name usable as one key chunk.
pub fn validate_host(host: &str) -> Result<(), String> {
    if host.is_empty() || host.len() > 64 {
        return Err(format!("--host {host:?}: must be 1 to 64 characters"));
    }
    if let Some(c) = host
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.')))
    {
        return Err(format!(
            "--host {host:?}: {c:?} is not allowed (only A-Z, a-z, 0-9, '_', '-', '.')"
        ));
    }
    Ok(())
}

/// `chaosd/<host>/<namespace>/<leaf>`; `None` for host or namespace is the wildcard `*`.
pub fn key(host: Option<&str>, namespace: Option<&str>, leaf: &str) -> String {
    format!(
        "{ROOT}/{}/{}/{leaf}",
        host.unwrap_or("*"),
        namespace.unwrap_or("*")
    )
}

/// (host, namespace) from a key of this key space.
pub fn parse(key: &str) -> Option<(&str, &str)> {
    let mut it = key.split('/');
    match (it.next(), it.next(), it.next(), it.next(), it.next()) {
        (Some(ROOT), Some(h), Some(ns), Some(_), None) => Some((h, ns)),
        _ => None,
    }
}

/// A control request: `op` is `protocol::Op` as a number, `args` its text.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct Request {
    pub op: u32,
    #[serde(default)]
    pub args: String,
}

/// How a request ended; the exit codes of `chaosctl`.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Outcome {
    /// Done (exit 0).
    Ok,
    /// The daemon or the gateway refused; nothing changed (exit 1).
    Refused,
    /// Malformed request (exit 2).
    Usage,
    /// The gateway could not reach its daemon (exit 3).
    Unreachable,
}

impl Outcome {
    pub fn code(self) -> u8 {
        match self {
            Outcome::Ok => 0,
            Outcome::Refused => 1,
            Outcome::Usage => 2,
            Outcome::Unreachable => 3,
        }
    }
}

/// The gateway's answer to a `Request`.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct Reply {
    pub outcome: Outcome,
    pub body: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_build_and_parse() {
        let k = key(Some("robot-1"), Some("arm"), "control");
        assert_eq!(k, "chaosd/robot-1/arm/control");
        assert_eq!(parse(&k), Some(("robot-1", "arm")));
        assert_eq!(key(None, Some("arm"), "status"), "chaosd/*/arm/status");
        assert_eq!(parse("chaosd/a/b"), None);
        assert_eq!(parse("other/a/b/c"), None);
    }

    #[test]
    fn hosts_are_single_chunks() {
        assert!(validate_host("lab-pc.local").is_ok());
        for bad in ["", "a/b", "*", "a b", "$x", &"h".repeat(65)] {
            assert!(validate_host(bad).is_err(), "{bad}");
        }
    }
}
