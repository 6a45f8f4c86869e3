//! How a number that moves on its own reads in a report, a log line or `chaosctl status`
//! ([`control::basics::number`], shared with the gain search's explanations).

pub use control::basics::number::short;
