//! Real-time plumbing shared by the daemon, the plant and the benchmarks.
//!
//! Each of these runs a fixed-rate loop on absolute deadlines, asks the kernel for real-time
//! scheduling, stops on SIGINT/SIGTERM and writes latency histograms. Keeping that in one crate
//! means the daemon and the plant wait, measure and report in exactly the same way, and the
//! benchmarks measure the code the daemon really runs.

pub mod alloc_count;
pub mod clock;
pub mod files;
pub mod gaps;
pub mod hist;
pub mod log;
pub mod news;
pub mod notify;
pub mod robot;
pub mod setup;
pub mod signal;
pub mod throttle;
pub mod trigger;
pub mod word;

pub use clock::{wait_until, wait_until_warm, WaitStrategy};
pub use protocol::monotonic_ns;
pub use trigger::Trigger;
