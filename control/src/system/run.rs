//! What an offline run asks of either arm's set-up before it starts: where it starts, whether
//! it can run at all, and how to name it in a figure or a report.
//!
//! The client's commands (`simulate`, `sweep`, `basins`, `figures`, …) take any arm; they ask
//! here and never which arm it is, so a command written once serves the planar arm and every
//! URDF chain, and a new kind of arm answers these few questions in this one file.

use super::System;
use crate::analysis::{check_reachable, period_steps, AnalysisError};

impl System {
    /// The start's angles q(0), or with `rate` its rates q̇(0) (zeros where the file gives
    /// none), one per joint.
    ///
    /// ```
    /// let s = control::System::preset("panda", &control::system::builtin_robot).unwrap();
    /// assert_eq!(s.start_coords(false).len(), 7);
    /// assert_eq!(s.start_coords(true).len(), 7);
    /// ```
    pub fn start_coords(&self, rate: bool) -> Vec<f64> {
        match (self, rate) {
            (System::Planar(c), false) => c.q0(),
            (System::Planar(c), true) => c.qd0(),
            (System::Spatial(s), false) => s.config.sim.start().to_vec(),
            (System::Spatial(s), true) => {
                let zeros = || vec![0.0; s.chain.dof()];
                s.config.sim.qd0.clone().unwrap_or_else(zeros)
            }
        }
    }

    /// Checks what a run needs beyond a valid file: the set-up valid against its arm, the
    /// period a whole number of steps, and on the planar arm the circle within reach of joint 1
    /// where the start puts it (the floating base's reach moves with the base, so the file's
    /// own check, [`Self::validate`], covers only the fixed base; a URDF chain's task is
    /// checked when its set-up is built).
    ///
    /// ```
    /// let mut s = control::System::preset("paper", &control::system::builtin_robot).unwrap();
    /// assert!(s.check_run().is_ok());
    /// *s.task_circle_mut().0 = 5.0; // a radius beyond the arm's reach
    /// let e = s.check_run().unwrap_err();
    /// assert!(e.to_string().contains("reaches only"), "{e}");
    /// ```
    pub fn check_run(&self) -> Result<(), AnalysisError> {
        self.validate()?;
        period_steps(self.period(), self.sim_section().dt)?;
        if let System::Planar(c) = self {
            crate::with_dof!(c.n(), N => {
                check_reachable(&c.model::<N>(), &c.law_params(), &c.initial_state::<N>())?;
            });
        }
        Ok(())
    }

    /// The arm's name: `"planar"` (the paper's arm) or the robot's description as the file
    /// gives it (a built-in name or a URDF path).
    pub fn robot_name(&self) -> String {
        match self {
            System::Planar(_) => crate::config::planar_file::PLANAR_ROBOT.into(),
            System::Spatial(s) => s.own().robot.description.clone(),
        }
    }

    /// The task's rows and path, `position circle` or `pose circle` (the planar arm's task is
    /// always a position).
    pub fn task_name(&self) -> String {
        match self {
            System::Planar(c) => format!("position {}", c.planar_part().task.path),
            System::Spatial(s) => format!("{} {}", s.own().task.kind, s.own().task.path),
        }
    }

    /// One line for a figure's title: the arm, its task and its secondary task.
    pub fn title(&self) -> String {
        match self {
            System::Planar(c) => format!(
                "planar {}-link arm, {:?} secondary task",
                c.n(),
                c.law.secondary
            ),
            System::Spatial(s) => s.config.describe(),
        }
    }

    /// The whole set-up as text, every number exact (Debug prints the shortest round-trip form):
    /// equal text, equal set-up. A sharded study's grid carries it so that shards of different
    /// set-ups are never merged; the form is kept as it was, so older shards still match.
    pub fn fingerprint_text(&self) -> String {
        match self {
            System::Planar(c) => crate::config::file::older_debug(c),
            System::Spatial(s) => format!(
                "{} {:?}",
                crate::config::file::robot_debug(&s.config),
                s.chain
            ),
        }
    }
}
