//! The iceoryx2 quality-of-service settings of every chaosd service, and the only functions that
//! open those services.
//!
//! iceoryx2 fixes a service's capacities when the first process *creates* it. A later process
//! that *opens* it only has to ask for no more than that: an opener asking for a smaller buffer
//! is accepted silently and gets the creator's values. So whichever of daemon and plant starts
//! first would decide the queue depths. The `open_*` functions here therefore apply one set of
//! constants and then check that the service they got matches them exactly
//! ([`ServiceError::QosMismatch`]). The payload type name (with [`crate::WIRE_VERSION`]), size
//! and alignment, and the overflow behaviour, are compared by iceoryx2 itself.
//!
//! ## Why these numbers (state and command)
//!
//! * `history_size = 1`: a subscriber that joins late (a monitor, a restarted daemon) gets the
//!   latest sample, never a backlog. iceoryx2 delivers it on the publisher's next send.
//! * `subscriber_max_buffer_size = 4`: the consumer drains its queue every tick and keeps only
//!   the newest sample. Four slots let it run up to three periods late and still see, and count,
//!   every sample; more would only keep staler data around.
//! * `subscriber_max_borrowed_samples = 2`: a subscriber may hold the sample it is using while it
//!   receives the next one.
//! * `safe_overflow = true`: when a queue is full the oldest entry is overwritten. The real-time
//!   publisher never waits for a slow, stopped or SIGKILLed subscriber (iceoryx2's default
//!   without overflow is to retry until the sample is delivered).
//! * `max_publishers = 1`: one writer per namespace, enforced by iceoryx2. A second plant or
//!   daemon started in the same namespace fails at start-up with `ExceedsMaxSupportedPublishers`
//!   instead of interleaving two streams. A process that restarts after a crash still gets the
//!   slot: by default `NodeBuilder::create` removes the resources of dead nodes first, which
//!   frees the old publisher. A graceful restart must wait for the old process to exit (or
//!   retry for a moment).
//! * `max_subscribers = 8`: the peer, a live monitor, a recorder, and room for spares. A dead
//!   subscriber keeps its slot until its node is cleaned up.
//! * `max_nodes = 16`: more than enough nodes for the processes above.

use core::fmt::{self, Debug};

use iceoryx2::node::Node;
use iceoryx2::prelude::{PortFactory as _, ServiceName, ZeroCopySend};
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError;
use iceoryx2::service::port_factory::publish_subscribe;

use crate::names::ServiceNames;
use crate::sample::{CommandSample, StateSample};

/// The opened state service (plant publishes, daemon subscribes).
pub type StateService<S> = publish_subscribe::PortFactory<S, StateSample, ()>;
/// The opened command service (daemon publishes, plant subscribes).
pub type CommandService<S> = publish_subscribe::PortFactory<S, CommandSample, ()>;

/// Settings of a publish-subscribe service.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PubSubQos {
    pub history_size: usize,
    pub subscriber_max_buffer_size: usize,
    pub subscriber_max_borrowed_samples: usize,
    pub max_publishers: usize,
    pub max_subscribers: usize,
    pub max_nodes: usize,
    pub safe_overflow: bool,
}

/// QoS of the state service. See the module docs for the reasoning.
pub const STATE_QOS: PubSubQos = PubSubQos {
    history_size: 1,
    subscriber_max_buffer_size: 4,
    subscriber_max_borrowed_samples: 2,
    max_publishers: 1,
    max_subscribers: 8,
    max_nodes: 16,
    safe_overflow: true,
};

/// QoS of the command service: the same trade-offs as the state service.
pub const COMMAND_QOS: PubSubQos = STATE_QOS;

/// Which chaosd service an error is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Channel {
    State,
    Command,
    Control,
    Telemetry,
    PlantInfo,
    DaemonInfo,
}

impl fmt::Display for Channel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Channel::State => "state",
            Channel::Command => "command",
            Channel::Control => "control",
            Channel::Telemetry => "telemetry",
            Channel::PlantInfo => "plant/info",
            Channel::DaemonInfo => "daemon/info",
        })
    }
}

/// Why a chaosd service could not be opened.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ServiceError {
    #[error("the {channel} service name is not a valid iceoryx2 service name")]
    InvalidName { channel: Channel },
    /// `IncompatibleTypes` here means the peer was built with another wire version.
    #[error("cannot open or create the {channel} service: {source}")]
    PubSub {
        channel: Channel,
        source: PublishSubscribeOpenOrCreateError,
    },
    #[error("cannot open the {channel} service: {source}")]
    RequestResponse {
        channel: Channel,
        source: iceoryx2::service::builder::request_response::RequestResponseOpenOrCreateError,
    },
    #[error(
        "cannot open ({open:?}) or create ({create:?}) the {channel} blackboard (the fast lane)"
    )]
    Board {
        channel: Channel,
        open: iceoryx2::service::builder::blackboard::BlackboardOpenError,
        create: iceoryx2::service::builder::blackboard::BlackboardCreateError,
    },
    #[error(
        "no chaosd is serving the {channel} service (is the daemon running in this namespace?)"
    )]
    NotRunning { channel: Channel },
    #[error("cannot open the {channel} service: {source:?} (a daemon of another chaosd build, or another user's?)")]
    RequestResponseOpen {
        channel: Channel,
        source: iceoryx2::service::builder::request_response::RequestResponseOpenError,
    },
    #[error(
        "the {channel} service already exists with {setting} = {found}, but this build uses \
         {expected}; it was created by another chaosd build, so stop that or use another namespace"
    )]
    QosMismatch {
        channel: Channel,
        setting: &'static str,
        found: usize,
        expected: usize,
    },
}

pub(crate) fn service_name(name: &str, channel: Channel) -> Result<ServiceName, ServiceError> {
    ServiceName::new(name).map_err(|_| ServiceError::InvalidName { channel })
}

fn expect(
    channel: Channel,
    setting: &'static str,
    found: usize,
    expected: usize,
) -> Result<(), ServiceError> {
    if found == expected {
        Ok(())
    } else {
        Err(ServiceError::QosMismatch {
            channel,
            setting,
            found,
            expected,
        })
    }
}

pub(crate) fn open_pubsub<S, T>(
    node: &Node<S>,
    name: &str,
    channel: Channel,
    qos: &PubSubQos,
) -> Result<publish_subscribe::PortFactory<S, T, ()>, ServiceError>
where
    S: iceoryx2::service::Service,
    T: Debug + ZeroCopySend,
{
    let service = node
        .service_builder(&service_name(name, channel)?)
        .publish_subscribe::<T>()
        .history_size(qos.history_size)
        .subscriber_max_buffer_size(qos.subscriber_max_buffer_size)
        .subscriber_max_borrowed_samples(qos.subscriber_max_borrowed_samples)
        .max_publishers(qos.max_publishers)
        .max_subscribers(qos.max_subscribers)
        .max_nodes(qos.max_nodes)
        .enable_safe_overflow(qos.safe_overflow)
        .open_or_create()
        .map_err(|source| ServiceError::PubSub { channel, source })?;

    let found = service.static_config();
    expect(
        channel,
        "history_size",
        found.history_size(),
        qos.history_size,
    )?;
    expect(
        channel,
        "subscriber_max_buffer_size",
        found.subscriber_max_buffer_size(),
        qos.subscriber_max_buffer_size,
    )?;
    expect(
        channel,
        "subscriber_max_borrowed_samples",
        found.subscriber_max_borrowed_samples(),
        qos.subscriber_max_borrowed_samples,
    )?;
    expect(
        channel,
        "max_publishers",
        found.max_publishers(),
        qos.max_publishers,
    )?;
    expect(
        channel,
        "max_subscribers",
        found.max_subscribers(),
        qos.max_subscribers,
    )?;
    expect(channel, "max_nodes", found.max_nodes(), qos.max_nodes)?;
    // iceoryx2 already refuses a different overflow behaviour; keep the check anyway.
    expect(
        channel,
        "safe_overflow",
        usize::from(found.has_safe_overflow()),
        usize::from(qos.safe_overflow),
    )?;
    Ok(service)
}

/// Opens (or creates) `chaosd/<ns>/state` with [`STATE_QOS`].
pub fn open_state_service<S: iceoryx2::service::Service>(
    node: &Node<S>,
    names: &ServiceNames,
) -> Result<StateService<S>, ServiceError> {
    open_pubsub(node, names.state(), Channel::State, &STATE_QOS)
}

/// Opens (or creates) `chaosd/<ns>/command` with [`COMMAND_QOS`].
pub fn open_command_service<S: iceoryx2::service::Service>(
    node: &Node<S>,
    names: &ServiceNames,
) -> Result<CommandService<S>, ServiceError> {
    open_pubsub(node, names.command(), Channel::Command, &COMMAND_QOS)
}
