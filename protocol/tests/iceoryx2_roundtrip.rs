//! The QoS helpers against real iceoryx2 services, inside one process.
//!
//! Every test uses its own namespace (`chaosd-test-<pid>-<nanos>-<n>`), so tests running in
//! parallel, or leftovers from an earlier run, never share a service.

use std::sync::atomic::{AtomicUsize, Ordering};

use iceoryx2::port::publisher::PublisherCreateError;
use iceoryx2::prelude::*;
use protocol::{
    open_command_service, open_state_service, Channel, CommandSample, Mode, ServiceError,
    ServiceNames, StateSample, COMMAND_QOS, STATE_QOS,
};

type Error = Box<dyn std::error::Error>;

fn unique_names() -> ServiceNames {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .expect("clock after 1970")
        .as_nanos();
    let ns = format!(
        "chaosd-test-{}-{}-{}",
        std::process::id(),
        nanos,
        COUNTER.fetch_add(1, Ordering::Relaxed)
    );
    ServiceNames::new(&ns).expect("test namespace is valid")
}

fn node(name: &str) -> Result<Node<ipc::Service>, Error> {
    // Hide iceoryx2's "no config file found" warning; errors still show.
    set_log_level(LogLevel::Error);
    Ok(NodeBuilder::new()
        .name(&NodeName::new(name)?)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()?)
}

fn state(seq: u64) -> StateSample {
    let mut s = StateSample {
        seq,
        stamp_ns: protocol::monotonic_ns(),
        plant_id: 11,
        n: 3,
        flags: protocol::flags::SIMULATED,
        ..StateSample::default()
    };
    s.q[..3].copy_from_slice(&[0.1, 0.2, seq as f64]);
    s.qd[..3].copy_from_slice(&[-0.1, 0.0, 0.1]);
    s
}

#[test]
fn state_round_trip_keeps_only_the_newest() -> Result<(), Error> {
    let names = unique_names();
    let plant = node("test-plant")?;
    let daemon = node("test-daemon")?;
    let plant_side = open_state_service(&plant, &names)?;
    let daemon_side = open_state_service(&daemon, &names)?;

    let publisher = plant_side.publisher_builder().create()?;
    let subscriber = daemon_side.subscriber_builder().create()?;

    // Nothing queued yet: an empty drain returns None, not an error.
    assert!(subscriber.receive()?.is_none());

    // Six samples queue up while the daemon is "late"; its buffer holds four and safe overflow
    // drops the oldest.
    for seq in 0..6 {
        let sample = publisher.loan_uninit()?;
        let sample = sample.write_payload(state(seq));
        sample.send()?;
    }

    // The daemon's drain: keep a copy of the newest sample and count the rest. (`receive` does
    // not allocate; in iceoryx2 0.10 each `loan_uninit` allocates one small `Rc`.)
    let mut newest: Option<StateSample> = None;
    let mut seen = [u64::MAX; STATE_QOS.subscriber_max_buffer_size];
    let mut count = 0;
    while let Some(sample) = subscriber.receive()? {
        seen[count] = sample.seq;
        count += 1;
        newest = Some(*sample);
    }
    assert_eq!(count, STATE_QOS.subscriber_max_buffer_size);
    assert_eq!(seen, [2, 3, 4, 5]);
    let newest = newest.expect("a sample arrived");
    assert_eq!(newest.seq, 5);
    assert_eq!((newest.q, newest.qd), (state(5).q, state(5).qd));
    newest.validate(3)?;
    assert!(subscriber.receive()?.is_none());
    Ok(())
}

#[test]
fn command_round_trip() -> Result<(), Error> {
    let names = unique_names();
    let daemon = node("test-daemon")?;
    let plant = node("test-plant")?;
    let publisher = open_command_service(&daemon, &names)?
        .publisher_builder()
        .create()?;
    let subscriber = open_command_service(&plant, &names)?
        .subscriber_builder()
        .create()?;

    let mut command = CommandSample {
        seq: 1,
        state_seq: 5,
        state_stamp_ns: 100,
        stamp_ns: 200,
        daemon_id: 99,
        mode: Mode::Run.into(),
        n: 2,
        ..CommandSample::default()
    };
    command.qdd[..2].copy_from_slice(&[1.0, -1.0]);
    publisher.loan_uninit()?.write_payload(command).send()?;

    let received = *subscriber.receive()?.expect("command arrives");
    assert_eq!(received, command);
    received.validate(2)?;
    assert_eq!(received.mode(), Ok(Mode::Run));
    Ok(())
}

#[test]
fn a_second_writer_is_refused() -> Result<(), Error> {
    let names = unique_names();
    let first = node("test-plant-1")?;
    let second = node("test-plant-2")?;
    let _publisher = open_state_service(&first, &names)?
        .publisher_builder()
        .create()?;
    let service = open_state_service(&second, &names)?;
    assert_eq!(STATE_QOS.max_publishers, 1);
    assert_eq!(
        service.publisher_builder().create().err(),
        Some(PublisherCreateError::ExceedsMaxSupportedPublishers)
    );
    assert_eq!(COMMAND_QOS.max_publishers, 1);
    Ok(())
}

#[test]
fn a_service_created_with_other_qos_is_refused() -> Result<(), Error> {
    let names = unique_names();
    let node = node("test-other-build")?;

    // An "other build" created the service with a deeper queue. iceoryx2 would let us open it
    // (we ask for less than it offers); our exact check refuses it.
    let _deeper = node
        .service_builder(&ServiceName::new(names.state())?)
        .publish_subscribe::<StateSample>()
        .history_size(1)
        .subscriber_max_buffer_size(8)
        .enable_safe_overflow(true)
        .create()?;
    let err = open_state_service(&node, &names).expect_err("queue depth differs");
    assert_eq!(
        err,
        ServiceError::QosMismatch {
            channel: Channel::State,
            setting: "subscriber_max_buffer_size",
            found: 8,
            expected: STATE_QOS.subscriber_max_buffer_size,
        }
    );

    // A shallower queue is already refused by iceoryx2.
    let _shallow = node
        .service_builder(&ServiceName::new(names.command())?)
        .publish_subscribe::<CommandSample>()
        .subscriber_max_buffer_size(1)
        .history_size(1)
        .enable_safe_overflow(true)
        .create()?;
    let err = open_command_service(&node, &names).expect_err("queue too small");
    assert!(
        matches!(
            err,
            ServiceError::PubSub {
                channel: Channel::Command,
                ..
            }
        ),
        "{err}"
    );
    Ok(())
}

#[test]
fn a_different_payload_type_is_refused() -> Result<(), Error> {
    /// Same size as a CommandSample would not matter: the type name differs.
    #[derive(Debug, Clone, Copy, ZeroCopySend)]
    #[type_name("chaosd::StateSample.v0")]
    #[repr(C)]
    struct OldState {
        seq: u64,
    }

    let names = unique_names();
    let node = node("test-old-build")?;
    let _old = node
        .service_builder(&ServiceName::new(names.state())?)
        .publish_subscribe::<OldState>()
        .open_or_create()?;
    let err = open_state_service(&node, &names).expect_err("payload type differs");
    assert!(err.to_string().contains("IncompatibleTypes"), "{err}");
    Ok(())
}

#[test]
fn resources_are_released_when_dropped() -> Result<(), Error> {
    let names = unique_names();
    let node = node("test-drop")?;
    let config = node.config().clone();
    let name = ServiceName::new(names.state())?;
    {
        let service = open_state_service(&node, &names)?;
        let publisher = service.publisher_builder().create()?;
        let subscriber = service.subscriber_builder().create()?;
        publisher.send_copy(state(0))?;
        assert!(subscriber.receive()?.is_some());
        assert!(ipc::Service::does_exist(
            &name,
            &config,
            MessagingPattern::PublishSubscribe
        )?);
    }
    // The last port factory is gone, so the service's shared memory and files are removed.
    assert!(!ipc::Service::does_exist(
        &name,
        &config,
        MessagingPattern::PublishSubscribe
    )?);
    drop(node);
    assert!(!ipc::Service::does_exist(
        &name,
        &config,
        MessagingPattern::PublishSubscribe
    )?);
    Ok(())
}

#[test]
fn the_helpers_also_work_with_the_process_local_service() -> Result<(), Error> {
    // `local::Service` never leaves the process: handy for in-process simulations.
    set_log_level(LogLevel::Error);
    let names = unique_names();
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<local::Service>()?;
    let service = open_state_service(&node, &names)?;
    let publisher = service.publisher_builder().create()?;
    let subscriber = service.subscriber_builder().create()?;
    publisher.send_copy(state(1))?;
    assert_eq!(subscriber.receive()?.map(|s| s.seq), Some(1));
    assert!(!ipc::Service::does_exist(
        &ServiceName::new(names.state())?,
        node.config(),
        MessagingPattern::PublishSubscribe
    )?);
    Ok(())
}
