//! chaosctl's library side: the control-request and telemetry code that `chaosctl` and
//! `chaosd-gateway` share, so a request through the Zenoh gateway meets exactly the checks and
//! the messages of a local one.

pub mod online;
