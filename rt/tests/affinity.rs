//! `avoid_core` never widens what the process was allowed (a unit's `CPUAffinity=`, a
//! `taskset`). Its own test binary: the allowed set is read once per process.

fn pin_to(cpu: usize) {
    // SAFETY: a zeroed cpu_set_t is the empty set; CPU_SET writes inside it; pid 0 is this thread.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        assert_eq!(
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set),
            0
        );
    }
}

fn allowed() -> Vec<usize> {
    // SAFETY: sched_getaffinity fills the set for this thread; CPU_ISSET only reads it.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set);
        (0..libc::CPU_SETSIZE as usize)
            .filter(|&c| libc::CPU_ISSET(c, &set))
            .collect()
    }
}

#[test]
fn a_process_confined_to_the_loops_core_keeps_its_helpers_there() {
    // As under `CPUAffinity=0` with the loop on core 0: there is nowhere else to go.
    pin_to(0);
    rt::setup::apply(rt::setup::RtRequest {
        core: Some(0),
        priority: 0,
        lock_memory: false,
    });
    let helper = std::thread::spawn(|| (rt::setup::avoid_core(Some(0)), allowed()))
        .join()
        .unwrap();
    assert_eq!(helper, (false, vec![0]), "the helper left the allowed set");
}
