//! chaosd, the controller service.
//!
//! The daemon owns no math: it feeds measured states to `control`'s law on a fixed-rate loop and
//! publishes the answers. What lives here is what makes that loop trustworthy as a service: start-up
//! validation ([`config`]), the per-tick decisions with their fault handling ([`controller`]), the runaway guard
//! ([`guard`]), the
//! real-time loop on iceoryx2 ([`service`]) and the reporting that keeps work out of the tick
//! ([`telemetry`] the shared types, [`reporter`], [`control_service`], [`recording`]).

pub mod change;
pub mod chaos;
pub mod cli;
pub mod config;
pub mod control_service;
pub mod controller;
pub mod deadlock;
pub mod demo_report;
pub mod foxglove;
pub mod gains;
pub mod guard;
pub mod handshake;
pub mod ipc;
pub mod limits;
pub mod mcap_read;
pub mod mcap_recording;
pub mod number;
pub mod persist;
pub mod planner;
pub mod record;
pub mod recording;
pub mod recording_files;
pub mod replay;
mod replay_steer;
pub mod reporter;
pub mod requests;
pub mod residual;
pub mod ros2_bag;

pub mod rotate;
pub mod saturations;
pub mod service;
pub mod targeting;
pub mod telemetry;
pub mod tick;
pub mod tracking;
pub mod trigger;
pub mod view;
pub mod watchdog;
pub mod window;
pub mod worker;

const _: () = assert!(
    control::MAX_JOINTS == protocol::MAX_JOINTS,
    "control and protocol disagree on MAX_JOINTS"
);
