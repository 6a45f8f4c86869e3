//! This process's iceoryx2 node, in a file of its own: the loop (`service`) and the reporter
//! thread (`reporter`) each open one, and neither should import the other for it.

use anyhow::Result;
use iceoryx2::prelude::ipc;

/// Creates this process's iceoryx2 node (see `protocol::node`).
pub fn node(name: &str) -> Result<iceoryx2::node::Node<ipc::Service>> {
    Ok(protocol::node(name)?)
}
