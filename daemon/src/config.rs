//! The `[daemon]` table, and loading a whole file for the daemon.
//!
//! The daemon refuses a bad file at start-up with one message naming the field, before it touches
//! shared memory or the scheduler (ripgrep's validate-then-run). The `[plant]` table belongs to the
//! plant process and is checked there; the daemon never needs it.

use control::basics::ConfigError;
use control::{Config, System};
use rt::{Trigger, WaitStrategy};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DaemonConfig {
    /// Service-name namespace: several systems can share a machine under different namespaces.
    pub namespace: String,
    /// Control rate (Hz), 100 to 10 000.
    pub rate_hz: f64,
    /// How to wait for each deadline: sleep, hybrid or spin.
    pub wait: WaitStrategy,
    /// Hybrid wait: spin this long before the deadline (µs).
    pub spin_us: f64,
    /// Core to pin the control thread to (none: unpinned).
    pub core: Option<usize>,
    /// SCHED_FIFO priority 1..=99, or 0 for the normal scheduler.
    pub priority: u8,
    /// mlockall the process.
    pub lock_memory: bool,
    /// Periods without a fresh state before the daemon enters HOLD.
    pub hold_after: u32,
    /// A state older than this (ms) is stale and not used; unset: [`Self::stale_ms`]'s default.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stale_ms: Option<f64>,
    /// Where histograms, the summary and recordings go.
    pub output_dir: PathBuf,
    /// Seconds between live status lines (0: none).
    pub report_every_s: f64,
    /// Seconds between sweeps for dead iceoryx2 nodes.
    pub cleanup_every_s: f64,
    /// Capacity of the loop → reporter telemetry queue (ticks).
    pub telemetry_queue: usize,
    /// Rate of the telemetry stream (Hz), 10 to 50.
    pub telemetry_hz: f64,
    /// How the plant holds a command between ticks: "first-order" (q̈ and its rate, the
    /// default) or "zero-order" (constant q̈). See `control::hold` for why it matters.
    pub hold: Hold,
    /// What starts a tick: "clock" (fixed-rate deadlines, the default) or "state" (a tick runs
    /// the moment a new state arrives and its command goes out at once; `wait` then says how
    /// to wait for it: spin = busy-poll, hybrid = sleep until `spin_us` before the state is
    /// due, then poll, sleep = poll every 20 µs). Must match `plant.trigger`.
    pub trigger: Trigger,
    /// State trigger: also take states from, and write commands to, an iceoryx2 blackboard
    /// (`protocol::board`), the latest-value fast lane; pub-sub still carries every sample. Off,
    /// or if the lane cannot be opened, pub-sub alone carries them. Ignored with the clock trigger.
    pub fast_lane: bool,
    /// Clock trigger: lock the tick's phase to the plant's state stamps, `phase_offset_us`
    /// after each state (µs, below one period), so the state age is small and fixed instead of
    /// wherever the two start phases fell. None (the default): free-running.
    pub phase_offset_us: Option<f64>,
    /// A recording moves on to a new file (`rec.1.csv`, `rec.2.csv`, …) before a row would
    /// take its file past this many bytes, 4096 to 2^40 (default 1 GiB, about 70 min at 1 kHz).
    pub record_max_bytes: u64,
    /// How many full recording files to keep besides the one being written, 0 to 1000
    /// (default 4); older ones are deleted.
    pub record_keep: usize,
    /// Run the chaos monitor on the reporter thread (default true; off, status says `unknown`
    /// and the loop is unchanged: the monitor never runs on it).
    pub monitor: bool,
    /// The chaos monitor's window: once-per-period returns kept for the 0–1 test, 32 to 4096
    /// (default 256).
    pub monitor_window: usize,
    /// Mean period residual (rad/s) below which the monitor calls the motion periodic, in
    /// (0, 1] (default 2e-2: a live orbit's residual stops at a few 1e-3, chaos gives 1–10).
    pub monitor_periodic_residual: f64,
    /// Serve the live view (the Foxglove WebSocket protocol) on this address, e.g.
    /// "127.0.0.1:8765". None (the default): no server.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub foxglove: Option<String>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Hold {
    #[default]
    FirstOrder,
    ZeroOrder,
}

impl Default for DaemonConfig {
    fn default() -> Self {
        Self {
            namespace: protocol::DEFAULT_NAMESPACE.to_string(),
            rate_hz: 1000.0,
            wait: WaitStrategy::Hybrid,
            spin_us: 50.0,
            core: Some(1),
            priority: 50,
            lock_memory: true,
            hold_after: 20,
            stale_ms: None,
            output_dir: PathBuf::from("out/chaosd"),
            report_every_s: 2.0,
            cleanup_every_s: 1.0,
            telemetry_queue: 16_384,
            telemetry_hz: 20.0,
            hold: Hold::FirstOrder,
            trigger: Trigger::Clock,
            fast_lane: true,
            phase_offset_us: None,
            record_max_bytes: 1 << 30,
            record_keep: 4,
            monitor: true,
            monitor_window: 256,
            monitor_periodic_residual: control::monitor::PERIODIC_RESIDUAL,
            foxglove: None,
        }
    }
}

fn invalid(field: &str, value: impl std::fmt::Debug, expected: &str) -> ConfigError {
    ConfigError::Invalid {
        field: format!("daemon.{field}"),
        value: format!("{value:?}"),
        expected: expected.into(),
    }
}

impl DaemonConfig {
    /// How old (ms) a state may be and still be used: the file's `stale_ms`, else 5 ms or five
    /// periods, whichever is longer, so that a slower loop (`--rate 100`) does not refuse every
    /// state as stale before it reads it.
    pub fn stale_ms(&self) -> f64 {
        self.stale_ms
            .unwrap_or_else(|| (5e3 / self.rate_hz).max(5.0))
    }

    pub fn validate(&self) -> Result<(), ConfigError> {
        protocol::validate_namespace(&self.namespace)
            .map_err(|e| invalid("namespace", &self.namespace, &e.to_string()))?;
        if let Some(a) = &self.foxglove {
            a.parse::<std::net::SocketAddr>().map_err(|_| {
                invalid(
                    "foxglove",
                    a,
                    "an address and port such as \"127.0.0.1:8765\"",
                )
            })?;
        }
        rt::setup::check_loop(
            self.rate_hz,
            (100.0, 10_000.0),
            self.spin_us,
            self.priority,
            self.core,
        )
        .map_err(|e| ConfigError::Invalid {
            field: format!("daemon.{}", e.field),
            value: e.value,
            expected: e.expected,
        })?;
        if !(1..=100_000).contains(&self.hold_after) {
            return Err(invalid(
                "hold_after",
                self.hold_after,
                "must be between 1 and 100000 periods",
            ));
        }
        let stale_ms = self.stale_ms();
        if !(stale_ms.is_finite() && stale_ms > 0.0 && stale_ms <= 10_000.0) {
            return Err(invalid("stale_ms", stale_ms, "must be > 0 and ≤ 10000 ms"));
        }
        if self.output_dir.as_os_str().is_empty() {
            return Err(invalid("output_dir", &self.output_dir, "must not be empty"));
        }
        if !(self.report_every_s.is_finite()
            && self.report_every_s >= 0.0
            && self.report_every_s <= 3600.0)
        {
            return Err(invalid(
                "report_every_s",
                self.report_every_s,
                "must be between 0 and 3600 s",
            ));
        }
        if !(self.cleanup_every_s.is_finite()
            && self.cleanup_every_s >= 0.1
            && self.cleanup_every_s <= 3600.0)
        {
            return Err(invalid(
                "cleanup_every_s",
                self.cleanup_every_s,
                "must be between 0.1 and 3600 s",
            ));
        }
        if !(self.telemetry_hz.is_finite() && (10.0..=50.0).contains(&self.telemetry_hz)) {
            return Err(invalid(
                "telemetry_hz",
                self.telemetry_hz,
                "must be between 10 and 50 Hz",
            ));
        }
        let period_us = 1e6 / self.rate_hz;
        if let Some(o) = self.phase_offset_us {
            if !(o.is_finite() && o >= 0.0 && o < period_us) {
                return Err(invalid(
                    "phase_offset_us",
                    o,
                    &format!("must be between 0 and the period ({period_us} µs)"),
                ));
            }
            if self.trigger == Trigger::State {
                return Err(invalid(
                    "phase_offset_us",
                    o,
                    "applies to trigger = \"clock\" only (a state-triggered tick has no phase of its own)",
                ));
            }
        }
        // A record is about 600 bytes: 65 536 of them are 40 MB, over a minute at 1 kHz.
        if !(64..=1 << 16).contains(&self.telemetry_queue) {
            return Err(invalid(
                "telemetry_queue",
                self.telemetry_queue,
                "must be between 64 and 65536",
            ));
        }
        // A file must hold the header and a row (a 7-link row is about 530 bytes).
        if !(4096..=1 << 40).contains(&self.record_max_bytes) {
            return Err(invalid(
                "record_max_bytes",
                self.record_max_bytes,
                "must be between 4096 and 1099511627776 (1 TiB)",
            ));
        }
        if self.record_keep > 1000 {
            return Err(invalid(
                "record_keep",
                self.record_keep,
                "must be between 0 and 1000 files",
            ));
        }
        if !(32..=4096).contains(&self.monitor_window) {
            let e = "must be between 32 and 4096 periods";
            return Err(invalid("monitor_window", self.monitor_window, e));
        }
        let r = self.monitor_periodic_residual;
        if !(r > 0.0 && r <= 1.0) {
            let e = "must be a number in (0, 1] rad/s";
            return Err(invalid("monitor_periodic_residual", r, e));
        }
        Ok(())
    }

    /// The chaos monitor's settings.
    pub fn monitor(&self) -> control::monitor::MonitorSettings {
        control::monitor::MonitorSettings {
            window: self.monitor_window,
            periodic_residual: self.monitor_periodic_residual,
        }
    }

    /// How a recording rotates (`rotate`).
    pub fn record_limit(&self) -> crate::rotate::Limit {
        crate::rotate::Limit {
            max_bytes: Some(self.record_max_bytes),
            keep: self.record_keep,
        }
    }

    pub fn period_ns(&self) -> u64 {
        (1e9 / self.rate_hz).round() as u64
    }
}

/// Everything the daemon runs from.
#[derive(Clone, Debug)]
pub struct DaemonSetup {
    /// The arm and its law: the planar arm or a URDF chain.
    pub system: System,
    pub daemon: DaemonConfig,
    /// The live state a restarted daemon resumes (`persist`), if any.
    pub live: Option<crate::persist::LiveState>,
    /// A replay recording to write from the first tick (`chaosd run --record NAME`).
    pub record: Option<String>,
    /// `persist::fingerprint` of the file's settings, before any saved live state replaced them.
    pub file_fingerprint: String,
}

impl DaemonSetup {
    /// A planar file's set-up (see [`DaemonSetup::from_system`]).
    pub fn from_config(system: Config) -> Result<Self, ConfigError> {
        Self::from_system(System::Planar(system))
    }

    /// Splits a parsed file into the system and `[daemon]` parts and validates both.
    pub fn from_system(system: System) -> Result<Self, ConfigError> {
        system.validate()?;
        let daemon: DaemonConfig = match system.tables().0 {
            Some(t) => t
                .clone()
                .try_into()
                .map_err(|e: toml::de::Error| ConfigError::Parse(format!("in [daemon]: {e}")))?,
            None => DaemonConfig::default(),
        };
        let s = Self {
            file_fingerprint: crate::persist::fingerprint(&system),
            system,
            daemon,
            live: None,
            record: None,
        };
        s.validate()?;
        Ok(s)
    }

    /// Re-validates after command-line overrides.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.system.validate()?;
        self.daemon.validate()?;
        // With the plant's table in the same file, check the two loops fit together: the daemon
        // must see a state at least every `hold_after` ticks, or it holds after every state.
        let plant_table = self.system.tables().1;
        if let Some(plant) = plant_table {
            let rate = plant
                .get("rate_hz")
                .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)))
                .unwrap_or(1000.0);
            let hold_window = self.daemon.hold_after as f64 / self.daemon.rate_hz;
            if rate > 0.0 && hold_window < 2.0 / rate {
                return Err(ConfigError::Invalid {
                    field: "daemon.hold_after".into(),
                    value: self.daemon.hold_after.to_string(),
                    expected: format!(
                        "must span at least two plant periods: {} ticks at {} Hz is {:.3} ms, the plant publishes every {:.3} ms (plant.rate_hz = {rate})",
                        self.daemon.hold_after, self.daemon.rate_hz, hold_window * 1e3, 1e3 / rate
                    ),
                });
            }
        }
        if let Some(plant) = plant_table {
            let plant_trigger = plant
                .get("trigger")
                .and_then(|v| v.as_str())
                .unwrap_or("clock");
            if plant_trigger != self.daemon.trigger.name() {
                return Err(ConfigError::Invalid {
                    field: "daemon.trigger".into(),
                    value: format!("{:?}", self.daemon.trigger.name()),
                    expected: format!(
                        "must equal plant.trigger = {plant_trigger:?} (both ends must agree on who answers when)"
                    ),
                });
            }
            // State-triggered, the plant's states set the pace: a daemon expecting them at
            // another rate sleeps through most of them (at a tenth of the rate, 99 % go late).
            let plant_rate = plant
                .get("rate_hz")
                .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)))
                .unwrap_or(1000.0);
            // The newest state may be a whole plant period old when a tick reads it: older than
            // `stale_ms`, every state would be refused and the daemon would never leave HOLD.
            if plant_rate > 0.0 && self.daemon.stale_ms() <= 1e3 / plant_rate {
                return Err(ConfigError::Invalid {
                    field: "daemon.stale_ms".into(),
                    value: self.daemon.stale_ms().to_string(),
                    expected: format!(
                        "must exceed one plant period ({:.3} ms at plant.rate_hz = {plant_rate}), or states are refused as stale before they are used",
                        1e3 / plant_rate
                    ),
                });
            }
            if self.daemon.trigger == rt::Trigger::State && plant_rate != self.daemon.rate_hz {
                return Err(ConfigError::Invalid {
                    field: "daemon.rate_hz".into(),
                    value: self.daemon.rate_hz.to_string(),
                    expected: format!(
                        "must equal plant.rate_hz = {plant_rate} with trigger = \"state\": each state is answered in its own cycle, so both ends run at the plant's rate"
                    ),
                });
            }
        }
        // The sampled-loop rules at the daemon's own step; τ must span at least one tick.
        self.system.check_step(
            1.0 / self.daemon.rate_hz,
            &format!("daemon.rate_hz = {}", self.daemon.rate_hz),
        )?;
        self.system.check_motion_effort()
    }

    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let size = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
        if size > control::basics::MAX_CONFIG_BYTES as u64 {
            anyhow::bail!(
                "{}: the config is {size} bytes; at most {} are accepted",
                path.display(),
                control::basics::MAX_CONFIG_BYTES
            );
        }
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow::anyhow!("cannot read config file {}: {e}", path.display()))?;
        let system =
            rt::robot::parse(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        Self::from_system(system).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
    }

    /// Adopts a saved live state: its system settings, with this file's `[daemon]` and `[plant]`.
    pub fn resume_from(&mut self, live: crate::persist::LiveState) -> Result<(), ConfigError> {
        let mut system = live.system.to_system()?;
        if let Some(g) = &live.gain {
            g.restore(&mut system);
        }
        let (daemon, plant) = self.system.tables();
        let (d, p) = system.tables_mut();
        (*d, *p) = (daemon.clone(), plant.clone());
        let before = std::mem::replace(&mut self.system, system);
        if let Err(e) = self.validate() {
            self.system = before;
            return Err(e);
        }
        self.live = Some(live);
        Ok(())
    }

    /// What the controller runs with, for a daemon start with id `daemon_id`.
    pub fn controller_settings(&self, daemon_id: u64) -> crate::controller::ControllerSettings {
        let d = &self.daemon;
        crate::controller::ControllerSettings {
            rate_hz: d.rate_hz,
            first_order_hold: d.hold == Hold::FirstOrder,
            hold_after: d.hold_after,
            stale_ns: (d.stale_ms() * 1e6) as u64,
            future_slack_ns: d.period_ns(),
            daemon_id,
            t_start: self.live.as_ref().map_or(0.0, |l| l.t),
        }
    }

    /// The whole file, with the effective `[daemon]` table, for the plant and for the record.
    pub fn to_toml(&self) -> String {
        let mut c = self.system.clone();
        *c.tables_mut().0 = toml::Table::try_from(&self.daemon).ok();
        c.to_toml()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_errors_name_the_field() {
        let s = DaemonSetup::from_config(Config::default()).unwrap();
        assert_eq!(s.daemon.period_ns(), 1_000_000);
        let bad = |t: &str| {
            DaemonSetup::from_config(Config::parse(t).unwrap())
                .unwrap_err()
                .to_string()
        };
        assert!(bad("[daemon]\nrate_hz = 50\n").contains("daemon.rate_hz"));
        assert!(bad("[daemon]\nwait = \"nap\"\n").contains("nap"));
        assert!(bad("[daemon]\nnamespace = \"a b\"\n").contains("daemon.namespace"));
        assert!(bad("[daemon]\npriority = 120\n").contains("daemon.priority"));
        assert!(bad("[daemon]\nbogus = 1\n").contains("bogus"));
        assert!(bad("[daemon]\nrate_hz = 10000\n[plant]\nrate_hz = 100\n")
            .contains("daemon.hold_after"));
        assert!(bad("[daemon]\nrate_hz = 100\n[feedback]\ntau = 0.005\n").contains("feedback.tau"));
        assert!(bad("[daemon]\ntrigger = \"bell\"\n").contains("bell"));
        assert!(
            bad("[daemon]\ntrigger = \"state\"\n[plant]\nrate_hz = 1000\n")
                .contains("daemon.trigger")
        );
        assert!(bad("[daemon]\nphase_offset_us = 1000\n").contains("daemon.phase_offset_us"));
        assert!(
            bad("[daemon]\nphase_offset_us = 100\ntrigger = \"state\"\n")
                .contains("daemon.phase_offset_us")
        );
        assert!(
            bad("[daemon]\nrate_hz = 100\nstale_ms = 5\n[plant]\nrate_hz = 100\n")
                .contains("daemon.stale_ms = 5: must exceed one plant period (10.000 ms")
        );
        assert!(bad(
            "[daemon]\ntrigger = \"state\"\nrate_hz = 100\n[plant]\ntrigger = \"state\"\n"
        )
        .contains("must equal plant.rate_hz = 1000"));
        let ok = "[daemon]\ntrigger = \"state\"\n[plant]\ntrigger = \"state\"\n";
        assert!(DaemonSetup::from_config(Config::parse(ok).unwrap()).is_ok());
    }

    #[test]
    fn a_slower_loop_takes_a_longer_staleness_unless_the_file_sets_one() {
        let at = |t: &str| DaemonSetup::from_config(Config::parse(t).unwrap());
        let slow = at("[daemon]\nrate_hz = 100\n[plant]\nrate_hz = 100\n").unwrap();
        assert_eq!(slow.daemon.stale_ms(), 50.0);
        assert_eq!(at("").unwrap().daemon.stale_ms(), 5.0);
        assert_eq!(
            at("[daemon]\nrate_hz = 2000\n").unwrap().daemon.stale_ms(),
            5.0
        );
        let set = at("[daemon]\nrate_hz = 100\nstale_ms = 30\n[plant]\nrate_hz = 100\n");
        assert_eq!(set.unwrap().daemon.stale_ms(), 30.0);
        // Not written back into the file the plant and the record get.
        assert!(!slow.to_toml().contains("stale_ms"));
    }

    #[test]
    fn recording_limits_are_validated() {
        let setup = |t: &str| DaemonSetup::from_config(Config::parse(t).unwrap());
        for t in [
            "[daemon]\nrecord_max_bytes = 4095\n",
            "[daemon]\nrecord_max_bytes = 1099511627777\n",
        ] {
            let e = setup(t).unwrap_err().to_string();
            assert!(
                e.contains("daemon.record_max_bytes") && e.contains("4096"),
                "{e}"
            );
        }
        let e = setup("[daemon]\nrecord_keep = 1001\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("daemon.record_keep"), "{e}");
        assert!(setup("[daemon]\nrecord_keep = -1\n").is_err());
        let s = setup("[daemon]\nrecord_max_bytes = 4096\nrecord_keep = 0\n").unwrap();
        assert_eq!(
            s.daemon.record_limit(),
            crate::rotate::Limit {
                max_bytes: Some(4096),
                keep: 0
            }
        );
    }

    #[test]
    fn monitor_settings_are_checked() {
        let setup = |t: &str| DaemonSetup::from_config(Config::parse(t).unwrap());
        for (t, key) in [
            ("monitor_window = 31", "daemon.monitor_window"),
            ("monitor_window = 5000", "daemon.monitor_window"),
            (
                "monitor_periodic_residual = 0",
                "daemon.monitor_periodic_residual",
            ),
            (
                "monitor_periodic_residual = nan",
                "daemon.monitor_periodic_residual",
            ),
        ] {
            let e = setup(&format!("[daemon]\n{t}\n")).unwrap_err().to_string();
            assert!(e.contains(key), "{t}: {e}");
        }
        let s = setup("[daemon]\nmonitor = false\nmonitor_window = 64\n").unwrap();
        assert!(!s.daemon.monitor);
        assert_eq!(s.daemon.monitor().window, 64);
    }

    #[test]
    fn round_trips() {
        let s = DaemonSetup::from_config(Config::default()).unwrap();
        let back = DaemonSetup::from_config(Config::parse(&s.to_toml()).unwrap()).unwrap();
        assert_eq!(back.daemon, s.daemon);
    }
}
