//! A whole parameter block of either arm's law, as a live change hands it over.
//!
//! The daemon swaps a validated block in at a tick boundary, and an offline run watched by the
//! monitor swaps one in mid-run the same way ([`crate::sim::ClosedLoopLaw::take_block`]). It
//! lives with the law, below the simulation and the tick's law, so that both can take one.

use super::spatial::SpatialParams;
use super::{LawCore, LawParams};
use crate::safety::SafetyParams;

/// A new parameter block for a running law (the daemon's live changes, a watched run's edits).
// Not boxed: it crosses to the loop by value, and the loop frees nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ParamBlock {
    Planar(LawParams),
    Spatial(SpatialParams),
}

impl ParamBlock {
    /// The gains, feedback and limits of the block's law.
    pub fn core(&self) -> &LawCore {
        match self {
            ParamBlock::Planar(p) => &p.core,
            ParamBlock::Spatial(p) => &p.core,
        }
    }

    /// The limits the block's law obeys.
    pub fn safety(&self) -> &SafetyParams {
        &self.core().safety
    }
}
