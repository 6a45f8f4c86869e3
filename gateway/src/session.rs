//! Opening a Zenoh session: explicit endpoints only.
//!
//! Multicast scouting is off, so a gateway or client joins only the network it is pointed at
//! (with `--listen`/`--connect`), never whatever else answers on the LAN. Gateways run as Zenoh
//! routers, so a client connected to any one of them reaches every gateway that gateway is
//! connected to; a remote client runs in client mode against one endpoint.

use anyhow::{anyhow, bail, Result};
use zenoh::{Session, Wait};

/// Whether the session serves (a gateway: router) or asks (a remote client).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Gateway,
    Client,
}

/// Checks an endpoint's shape before Zenoh sees it: `tcp/HOST:PORT` (the only transport built).
pub fn validate_endpoint(e: &str) -> Result<()> {
    let Some(addr) = e.strip_prefix("tcp/") else {
        bail!("endpoint {e:?}: expected tcp/HOST:PORT, e.g. tcp/127.0.0.1:7447 (this build has the TCP transport only)");
    };
    match addr.rsplit_once(':') {
        Some((host, port)) if !host.is_empty() && port.parse::<u16>().is_ok() => Ok(()),
        _ => bail!("endpoint {e:?}: expected tcp/HOST:PORT with a port from 0 to 65535"),
    }
}

/// Opens a session listening on `listen` and connecting to `connect`; a client gives up after
/// `connect_timeout`.
pub fn open(
    role: Role,
    listen: &[String],
    connect: &[String],
    connect_timeout: std::time::Duration,
) -> Result<Session> {
    for e in listen.iter().chain(connect) {
        validate_endpoint(e)?;
    }
    let mut c = zenoh::Config::default();
    let set = |c: &mut zenoh::Config, k: &str, v: String| {
        c.insert_json5(k, &v)
            .map_err(|e| anyhow!("zenoh config {k} = {v}: {e}"))
    };
    let mode = match role {
        Role::Gateway => "router",
        Role::Client => "client",
    };
    set(&mut c, "mode", format!("{mode:?}"))?;
    set(&mut c, "scouting/multicast/enabled", "false".into())?;
    set(&mut c, "listen/endpoints", serde_json::to_string(listen)?)?;
    set(&mut c, "connect/endpoints", serde_json::to_string(connect)?)?;
    if role == Role::Client {
        // Fail fast when the gateway is not there, instead of retrying for ever.
        let ms = connect_timeout.as_millis().clamp(1, 3_600_000);
        set(&mut c, "connect/timeout_ms", ms.to_string())?;
        set(&mut c, "connect/exit_on_failure", "true".into())?;
    }
    zenoh::open(c).wait().map_err(|e| {
        anyhow!("cannot open a Zenoh session (listen {listen:?}, connect {connect:?}): {e}")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints_are_checked() {
        assert!(validate_endpoint("tcp/127.0.0.1:7447").is_ok());
        assert!(validate_endpoint("tcp/[::1]:7447").is_ok());
        assert!(validate_endpoint("tcp/robot.local:1").is_ok());
        for bad in [
            "127.0.0.1:7447",
            "udp/1.2.3.4:5",
            "tcp/1.2.3.4",
            "tcp/:80",
            "tcp/h:99999",
        ] {
            assert!(validate_endpoint(bad).is_err(), "{bad}");
        }
    }
}
