//! The command alone (`TickLaw::acceleration`, what an RK4 step's inner stages and the
//! first-order hold's second point call) is the full evaluation's q̈ and φ̇ bit for bit, on every
//! kind of arm, with and without obstacles, with the safety filter binding or not: the
//! diagnostics it skips never feed the command.

use control::sim::{ArmState, ClosedLoopLaw, Simulation};

use control::system::builtin_robot;
use control::tick_law::LawScratch;
use control::System;

/// Runs `system`'s own law for `steps`, and at every state compares the two evaluations (at the
/// state, and at a perturbed one off the trajectory). Returns how many evaluations the filter
/// changed, so a caller can tell that the binding path was taken.
fn compare<const N: usize>(system: &System, steps: usize) -> usize {
    let law = system.tick_law::<N>();
    let mut sim = Simulation::of(law, 1e-3, system.initial_state::<N>(), 4.0);
    let (mut scratch, mut lean) = (LawScratch::<N>::default(), LawScratch::<N>::default());
    let mut filtered = 0;
    for k in 0..steps {
        sim.step();
        let x = *sim.state();
        let delayed = sim.delay().sample(sim.step_index() as f64 - 2000.0);
        let shaken = ArmState {
            qd: x.qd.map(|v| 1.7 * v + 0.3),
            ..x
        };
        for (s, state) in [(0.0, x), (0.5e-3, shaken)] {
            let t = k as f64 * 1e-3 + s;
            let full = sim.law.evaluate(t, &state, &delayed, &mut scratch);
            let (qdd, base_rate) = sim.law.acceleration(t, &state, &delayed, &mut lean);
            assert_eq!(full.qdd, qdd, "q̈ differs at step {k}");
            assert_eq!(full.base_rate.to_bits(), base_rate.to_bits());
            filtered += (full.flags & control::basics::flags::SAFETY_ACTIVE != 0) as usize;
        }
    }
    filtered
}

#[test]
fn the_command_alone_is_the_full_evaluations_on_every_arm() {
    for name in ["paper", "paper-obstacle", "paper-floating"] {
        let s = System::preset(name, &builtin_robot).unwrap();
        compare::<3>(&s, 3000);
    }
    let mut panda = System::preset("panda", &builtin_robot).unwrap();
    for c in [
        [0.55, 0.3, 0.3],
        [0.55, -0.3, 0.3],
        [0.0, 0.45, 0.6],
        [0.0, -0.45, 0.6],
    ] {
        panda.add_obstacle(&c, 0.08, 0.1).unwrap();
    }
    let filtered = compare::<7>(&panda, 3000);
    assert!(
        filtered > 0,
        "the filter never bound: the binding path went untested"
    );
}
