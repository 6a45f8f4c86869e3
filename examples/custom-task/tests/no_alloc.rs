//! A custom task runs on every tick of the real-time loop: the Panda's law step with the posture
//! task allocates nothing (a counting global allocator, armed per thread; its own test binary,
//! since a `#[global_allocator]` applies to the whole binary).

use control::sim::Simulation;
use control::Config;
use rt::alloc_count::{allocations, Counting};

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn the_counter_sees_allocations() {
    let n = allocations(|| {
        let v: Vec<u8> = Vec::with_capacity(std::hint::black_box(64));
        std::hint::black_box(v);
    });
    assert_eq!(n, 1);
}

#[test]
fn the_panda_step_with_the_posture_task_allocates_nothing() {
    control::secondary::custom::register(&[(custom_task::NAME, &custom_task::PANDA_READY)])
        .unwrap();
    let mut cfg = Config::from_robot_toml(include_str!("../panda-posture.toml")).unwrap();
    cfg.feedback.t_on = 0.5;
    let chain = rt::robot::load("panda", None, None).unwrap();
    let s = cfg.setup::<7>(&chain).unwrap();
    let mut sim = Simulation::spatial(s.arm, s.params, s.dt, s.q0, s.qd0, 2.0);
    let n = allocations(|| {
        for _ in 0..1500 {
            std::hint::black_box(sim.step());
        }
    });
    assert_eq!(n, 0, "the step with a custom task allocated {n} times");
}
