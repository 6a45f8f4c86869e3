//! How every chaosd process joins iceoryx2.
//!
//! Three defaults of iceoryx2 are wrong for us, so they are set once here: its signal handler
//! (it would take SIGINT/SIGTERM/SIGTSTP away from the processes' own shutdown handling), its
//! config-file search relative to the working directory (a stray `./config/iceoryx2.toml` must
//! not change a daemon), and its info-level logging (`IOX2_LOG_LEVEL` still overrides).

use iceoryx2::node::Node;
use iceoryx2::prelude::{ipc, LogLevel, NodeBuilder, NodeName, SignalHandlingMode};

/// Why a node could not be created.
#[derive(Debug, thiserror::Error)]
#[error("cannot join iceoryx2 as {name:?}: {reason}")]
pub struct NodeError {
    pub name: String,
    pub reason: String,
}

/// An inter-process node named `name` (shown by iceoryx2's node listing).
pub fn node(name: &str) -> Result<Node<ipc::Service>, NodeError> {
    iceoryx2::prelude::set_log_level_from_env_or(LogLevel::Error);
    let err = |reason: String| NodeError {
        name: name.to_string(),
        reason,
    };
    NodeBuilder::new()
        .name(&NodeName::new(name).map_err(|e| err(format!("{e:?}")))?)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .config(&iceoryx2::config::Config::default())
        .create::<ipc::Service>()
        .map_err(|e| err(format!("{e:?}")))
}
