//! Why a cycle or a detour does not fit the loop's fixed-size tables, by its numbers.

/// A cycle or a detour the loop cannot hold.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SteerError {
    #[error("a cycle of 1 to {max_phases} phases of 1 to {max_joints} joints (this one has {phases} phases of {joints})")]
    CycleShape {
        max_phases: usize,
        max_joints: usize,
        phases: usize,
        joints: usize,
    },
    #[error("a cycle of 1 to {max_phases} phases (this one has {phases})")]
    Phases { max_phases: usize, phases: usize },
    #[error("a detour of 2 to {max_points} finite postures, ending after it starts")]
    Detour { max_points: usize },
}
