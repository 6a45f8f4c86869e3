//! iceoryx2 service names, grouped under a per-system namespace: `chaosd/<namespace>/<channel>`.
//!
//! Several chaosd systems (or test runs) can share one machine as long as their namespaces
//! differ. The namespace is validated once, here, so that a bad value is refused at start-up with
//! one clear message rather than surfacing later as an iceoryx2 error.

use core::fmt;

/// The namespace used when none is configured.
pub const DEFAULT_NAMESPACE: &str = "default";
/// Longest accepted namespace, in bytes.
pub const MAX_NAMESPACE_LEN: usize = 64;
/// First component of every chaosd service name.
pub const SERVICE_ROOT: &str = "chaosd";

/// Why a namespace was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum NamespaceError {
    #[error("namespace is empty")]
    Empty,
    #[error("namespace is {len} bytes long; at most {MAX_NAMESPACE_LEN} are allowed")]
    TooLong { len: usize },
    #[error("namespace has {ch:?} at byte {index}; only A-Z, a-z, 0-9, '_' and '-' are allowed")]
    InvalidChar { ch: char, index: usize },
}

/// Validates a namespace: non-empty, at most [`MAX_NAMESPACE_LEN`] bytes, `[A-Za-z0-9_-]` only.
pub fn validate_namespace(namespace: &str) -> Result<(), NamespaceError> {
    if namespace.is_empty() {
        return Err(NamespaceError::Empty);
    }
    if let Some((index, ch)) = namespace
        .char_indices()
        .find(|&(_, c)| !(c.is_ascii_alphanumeric() || c == '_' || c == '-'))
    {
        return Err(NamespaceError::InvalidChar { ch, index });
    }
    if namespace.len() > MAX_NAMESPACE_LEN {
        return Err(NamespaceError::TooLong {
            len: namespace.len(),
        });
    }
    Ok(())
}

/// The names of all chaosd services in one namespace.
///
/// Built once at start-up; the strings are then only borrowed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServiceNames {
    namespace: String,
    state: String,
    command: String,
    control: String,
    telemetry: String,
    plant_info: String,
    daemon_info: String,
}

impl ServiceNames {
    /// Names for `namespace`, which must pass [`validate_namespace`].
    pub fn new(namespace: &str) -> Result<Self, NamespaceError> {
        validate_namespace(namespace)?;
        let name = |channel: &str| format!("{SERVICE_ROOT}/{namespace}/{channel}");
        Ok(Self {
            namespace: namespace.to_owned(),
            state: name("state"),
            command: name("command"),
            control: name("control"),
            telemetry: name("telemetry"),
            plant_info: name("plant/info"),
            daemon_info: name("daemon/info"),
        })
    }

    /// The namespace these names were built from.
    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    /// Publish-subscribe, plant → daemon: [`crate::StateSample`].
    pub fn state(&self) -> &str {
        &self.state
    }

    /// Publish-subscribe, daemon → plant: [`crate::CommandSample`].
    pub fn command(&self) -> &str {
        &self.command
    }

    /// Request-response, client → daemon: live control (`control::ControlRequest`).
    pub fn control(&self) -> &str {
        &self.control
    }

    /// Publish-subscribe, daemon → monitors and recorders (`control::TelemetrySample`).
    pub fn telemetry(&self) -> &str {
        &self.telemetry
    }

    /// Publish-subscribe with history, plant → daemon: the plant's `handshake::ArmInfo`.
    pub fn plant_info(&self) -> &str {
        &self.plant_info
    }

    /// Publish-subscribe with history, daemon → plant: the daemon's `handshake::ArmInfo`.
    pub fn daemon_info(&self) -> &str {
        &self.daemon_info
    }
}

impl Default for ServiceNames {
    fn default() -> Self {
        Self::new(DEFAULT_NAMESPACE).expect("the default namespace is valid")
    }
}

impl fmt::Display for ServiceNames {
    /// The common prefix, `chaosd/<namespace>/`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{SERVICE_ROOT}/{}/", self.namespace)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_grouped_under_the_namespace() {
        let names = ServiceNames::new("lab-2_arm").unwrap();
        assert_eq!(names.namespace(), "lab-2_arm");
        assert_eq!(names.state(), "chaosd/lab-2_arm/state");
        assert_eq!(names.command(), "chaosd/lab-2_arm/command");
        assert_eq!(names.control(), "chaosd/lab-2_arm/control");
        assert_eq!(names.telemetry(), "chaosd/lab-2_arm/telemetry");
        assert_eq!(names.plant_info(), "chaosd/lab-2_arm/plant/info");
        assert_eq!(names.daemon_info(), "chaosd/lab-2_arm/daemon/info");
        assert_eq!(names.to_string(), "chaosd/lab-2_arm/");
    }

    #[test]
    fn default_namespace() {
        let names = ServiceNames::default();
        assert_eq!(names.namespace(), DEFAULT_NAMESPACE);
        assert_eq!(names.state(), "chaosd/default/state");
    }

    #[test]
    fn longest_namespace_is_accepted() {
        let ns = "a".repeat(MAX_NAMESPACE_LEN);
        assert!(ServiceNames::new(&ns).is_ok());
        // Every name must also fit iceoryx2's service-name limit.
        let names = ServiceNames::new(&ns).unwrap();
        for name in [
            names.state(),
            names.command(),
            names.control(),
            names.telemetry(),
            names.plant_info(),
            names.daemon_info(),
        ] {
            assert!(iceoryx2::prelude::ServiceName::new(name).is_ok(), "{name}");
        }
    }

    #[test]
    fn bad_namespaces_are_refused() {
        assert_eq!(ServiceNames::new(""), Err(NamespaceError::Empty));
        assert_eq!(
            ServiceNames::new(&"a".repeat(MAX_NAMESPACE_LEN + 1)),
            Err(NamespaceError::TooLong {
                len: MAX_NAMESPACE_LEN + 1
            })
        );
        for (ns, ch, index) in [
            ("a/b", '/', 1),
            ("a b", ' ', 1),
            ("..", '.', 0),
            ("ns:1", ':', 2),
            ("arm\n", '\n', 3),
            ("bras-é", 'é', 5),
        ] {
            assert_eq!(
                ServiceNames::new(ns),
                Err(NamespaceError::InvalidChar { ch, index }),
                "{ns:?}"
            );
        }
    }

    #[test]
    fn error_messages_are_clear() {
        assert_eq!(
            ServiceNames::new("a/b").unwrap_err().to_string(),
            "namespace has '/' at byte 1; only A-Z, a-z, 0-9, '_' and '-' are allowed"
        );
        assert_eq!(
            ServiceNames::new(&"x".repeat(65)).unwrap_err().to_string(),
            "namespace is 65 bytes long; at most 64 are allowed"
        );
    }
}
