//! What robotics tools can read of a running chaosd: the channels of an MCAP recording (and of
//! a live viewer), their schemas and their encoding.
//!
//! The formats are the field's own (ROS 2 messages in CDR, Foxglove's JSON schemas), so that
//! Foxglove, rosbag2 and Python's `mcap` readers open chaosd's files without a plugin. All of
//! it runs on the reporter thread: the loop's record is `Copy`, and nothing here is on its path.

pub mod cdr;
pub mod channels;
pub mod scene;
pub mod schemas;

pub use channels::{Encoder, Level, Sink, TickContext, Topic, VIEW_HZ};
pub use scene::Scene;
