//! Proves the plant side's per-cycle calls allocate nothing, with a counting global allocator
//! armed per thread (its own test binary): the simulator's `write`/`read`, the command intake,
//! the UDP wire format, and the UDP bridge's `read`/`write` over a real loopback socket.

use control::Config;
use plant::intake::{Intake, Published, PublishedRing};
use plant::udp::bridge::{BridgeConfig, UdpBridge};
use plant::udp::wire::{DeviceCommand, DeviceMode, DeviceState, COMMAND_LEN, STATE_LEN};
use plant::{Actuation, Plant, SimPlant};
use protocol::{CommandSample, Mode, StateSample};
use rt::alloc_count::{allocations, Counting};
use std::net::UdpSocket;
use std::time::Duration;

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn the_counter_sees_allocations() {
    let n = allocations(|| {
        std::hint::black_box(Vec::<u8>::with_capacity(16));
    });
    assert_eq!(n, 1);
}

#[test]
fn the_simulator_and_the_intake_allocate_nothing() {
    let cfg = Config::preset("paper").unwrap();
    let mut sim = SimPlant::<3>::new(cfg.model::<3>(), cfg.initial_state(), 1e-3, 4, 20.0);
    let mut intake = Intake::new(3, 0);
    let mut ring = PublishedRing::default();
    let mut out = StateSample::default();
    let n = allocations(|| {
        for k in 0..1000u64 {
            let cmd = CommandSample {
                seq: k,
                state_seq: k,
                state_stamp_ns: 1,
                daemon_id: 3,
                mode: Mode::Run as u32,
                n: 3,
                ..CommandSample::default()
            };
            assert!(intake.accept(&cmd));
            sim.write(Actuation::Accelerate {
                qdd: &cmd.qdd[..3],
                qddd: &cmd.qddd[..3],
                since: ring.since(k, 0.0),
                answers: k,
            })
            .unwrap();
            sim.read(if k % 10 == 0 { 3e-3 } else { 1e-3 }, &mut out)
                .unwrap();
            ring.push(Published {
                seq: k,
                plant_time: k as f64,
                at_ns: k,
            });
        }
        sim.write(Actuation::Hold).unwrap();
        sim.read(1e-3, &mut out).unwrap();
    });
    assert_eq!(n, 0, "the simulator or the intake allocated {n} times");
}

#[test]
fn the_udp_bridge_and_the_wire_format_allocate_nothing() {
    let device = UdpSocket::bind("127.0.0.1:0").unwrap();
    device
        .set_read_timeout(Some(Duration::from_secs(2)))
        .unwrap();
    let bind = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let cfg = BridgeConfig {
        bind,
        device: device.local_addr().unwrap(),
        timeout: Duration::from_millis(100),
        // Lost at the first timeout, so that the news path below runs.
        lost_after: Duration::from_millis(1),
        period: Duration::from_millis(1),
        wait: rt::WaitStrategy::Hybrid,
        spin: Duration::from_micros(50),
        loop_core: None,
        interface: protocol::interface::ACCELERATION,
    };
    let mut bridge = UdpBridge::new(3, cfg);
    bridge.activate().unwrap();
    let mut out = StateSample::default();
    let (mut sbuf, mut cbuf) = ([0u8; STATE_LEN], [0u8; COMMAND_LEN + 1]);
    let mut allocs = 0;
    for k in 0..500u64 {
        let st = DeviceState {
            n: 3,
            seq: k,
            session: 77,
            flags: plant::udp::wire::takes(&[protocol::interface::ACCELERATION]),
            ..DeviceState::default()
        };
        // The device's side of the exchange is counted too: encode, send, receive, decode.
        allocs += allocations(|| {
            st.encode(&mut sbuf);
            device.send_to(&sbuf, bind).unwrap();
            out.seq = k;
            bridge.read(1e-3, &mut out).unwrap();
            bridge
                .write(Actuation::Accelerate {
                    qdd: &[1.0, 2.0, 3.0],
                    qddd: &[0.0; 3],
                    since: 0.0,
                    answers: k,
                })
                .unwrap();
            let len = device.recv(&mut cbuf).unwrap();
            let c = DeviceCommand::decode(&cbuf[..len]).unwrap();
            assert_eq!((c.seq, c.session, c.mode), (k, 77, DeviceMode::Run));
        });
    }
    assert_eq!(allocs, 0, "the bridge path allocated {allocs} times");
    assert_eq!(bridge.counters.states, 500);
    assert_eq!(bridge.counters.commands_sent, 500);

    // The news paths (device lost, back, restarted) post from the loop: counted too.
    let news = allocations(|| {
        assert!(bridge.read(1e-3, &mut out).is_err(), "nothing was sent");
        let restarted = DeviceState {
            n: 3,
            seq: 0,
            session: 78,
            flags: plant::udp::wire::takes(&[protocol::interface::ACCELERATION]),
            ..DeviceState::default()
        };
        restarted.encode(&mut sbuf);
        device.send_to(&sbuf, bind).unwrap();
        bridge.read(1e-3, &mut out).unwrap();
    });
    assert_eq!(
        news, 0,
        "reporting the device lost and back allocated {news} times"
    );
    assert_eq!(
        (bridge.counters.device_lost, bridge.counters.device_restarts),
        (1, 1)
    );
    bridge.deactivate();
}

/// MuJoCo's plant (built with the `mujoco` feature; CI runs it): `write` in every interface and
/// `read` (MuJoCo's steps, the torques, the contact judge, the check for a moved scene) allocate
/// nothing on the loop's thread. The scene thread asks for the daemon's list on its own thread
/// (no daemon answers here).
#[cfg(feature = "mujoco")]
#[test]
fn the_mujoco_plant_allocates_nothing_in_any_interface() {
    let system = rt::robot::preset("panda").unwrap();
    let cfg = plant::PlantConfig {
        dynamics: plant::config::Dynamics::Mujoco,
        namespace: format!("noalloc-mujoco-{}", std::process::id()),
        ..plant::PlantConfig::default()
    };
    let mut p = plant::mujoco::MujocoPlant::from_launch(&system, &cfg).unwrap();
    p.activate().unwrap();
    let mut out = StateSample::default();
    p.read(0.0, &mut out).unwrap();
    let q: Vec<f64> = out.q[..7].to_vec();
    let zero = [0.0; 7];
    let n = allocations(|| {
        for k in 0..400u64 {
            let a = match k / 80 {
                0 => Actuation::Torque {
                    tau: &zero,
                    since: 0.0,
                    answers: k,
                },
                1 => Actuation::Accelerate {
                    qdd: &zero,
                    qddd: &zero,
                    since: 0.0,
                    answers: k,
                },
                2 => Actuation::Position {
                    q: &q,
                    qd: &zero,
                    since: 0.0,
                    answers: k,
                },
                3 => Actuation::Velocity {
                    qd: &zero,
                    since: 0.0,
                    answers: k,
                },
                _ => Actuation::Hold,
            };
            p.write(a).unwrap();
            p.read(if k % 10 == 0 { 3e-3 } else { 1e-3 }, &mut out)
                .unwrap();
        }
    });
    p.deactivate();
    assert_eq!(n, 0, "the MuJoCo plant allocated {n} times in 400 cycles");
    assert!(out.q[..7].iter().all(|x| x.is_finite()));
}
