//! iceoryx2 plumbing shared by every process: one place that fixes how each channel's services
//! are configured, so that publishers and subscribers in different binaries always agree.
//!
//! Each channel is a publish-subscribe service paired with an event service of the same name:
//! a publisher notifies after every send, so that a subscriber can block on the listener
//! ([`Sub::wait_for_wake_up`]) or a WaitSet instead of polling (iceoryx2 0.10 subscribers
//! cannot block).

use crate::{Channel, Message};
use iceoryx2::node::{NodeCreationFailure, NodeListFailure, NodeState};
use iceoryx2::port::listener::{Listener, ListenerCreateError, ListenerWaitError};
use iceoryx2::port::notifier::{Notifier, NotifierCreateError, NotifierNotifyError};
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::port::{ReceiveError as IceReceiveError, SendError as IceSendError};
use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::EventOpenOrCreateError;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use iceoryx2::service::service_name::ServiceNameError;
use iceoryx2::waitset::{WaitSetAttachmentError, WaitSetCreateError, WaitSetRunError};
use std::time::Duration;

/// The iceoryx2 service type of every Sextant port (`crate::ipc_service`).
pub use crate::ipc_service::Service as IpcService;

/// Failure to join the bus ([`Bus::new`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum NodeError {
    /// The node name is not a valid iceoryx2 node name.
    #[error("invalid node name: {0}")]
    InvalidName(SemanticStringError),
    /// iceoryx2 could not create the node.
    #[error("cannot create the node: {0}")]
    Create(NodeCreationFailure),
}

/// Failure to open (or create) the publish-subscribe and event services of a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ServiceError {
    /// Prefix and channel name do not form a valid service name.
    #[error("invalid service name for {}: {error}", channel.name())]
    InvalidName {
        /// The channel.
        channel: Channel,
        /// Why the name is invalid.
        error: ServiceNameError,
    },
    /// The publish-subscribe service could not be opened nor created (e.g. another process
    /// created it with other settings or another message type).
    #[error("publish-subscribe service of {}: {error}", channel.name())]
    PublishSubscribe {
        /// The channel.
        channel: Channel,
        /// The iceoryx2 error.
        error: PublishSubscribeOpenOrCreateError,
    },
    /// The event service could not be opened nor created.
    #[error("event service of {}: {error}", channel.name())]
    Event {
        /// The channel.
        channel: Channel,
        /// The iceoryx2 error.
        error: EventOpenOrCreateError,
    },
}

/// Failure to create a channel's publisher ([`Bus::publisher`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PublisherError {
    /// The channel's services.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// The publisher port.
    #[error("publisher on {}: {error}", channel.name())]
    Publisher {
        /// The channel.
        channel: Channel,
        /// The iceoryx2 error.
        error: PublisherCreateError,
    },
    /// The notifier port paired with the publisher.
    #[error("notifier on {}: {error}", channel.name())]
    Notifier {
        /// The channel.
        channel: Channel,
        /// The iceoryx2 error.
        error: NotifierCreateError,
    },
}

/// Failure to create a channel's subscriber ([`Bus::subscriber`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SubscriberError {
    /// The channel's services.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// The subscriber port.
    #[error("subscriber on {}: {error}", channel.name())]
    Subscriber {
        /// The channel.
        channel: Channel,
        /// The iceoryx2 error.
        error: SubscriberCreateError,
    },
    /// The listener port paired with the subscriber.
    #[error("listener on {}: {error}", channel.name())]
    Listener {
        /// The channel.
        channel: Channel,
        /// The iceoryx2 error.
        error: ListenerCreateError,
    },
}

/// Failure to send a message ([`Pub::send`], [`Pub::send_raw`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SendError {
    /// The sample could not be delivered.
    #[error("send on {}: {error}", channel.name())]
    Send {
        /// The channel.
        channel: Channel,
        /// The iceoryx2 error.
        error: IceSendError,
    },
    /// The sample was delivered but the listeners could not be woken.
    #[error("notify on {}: {error}", channel.name())]
    Notify {
        /// The channel.
        channel: Channel,
        /// The iceoryx2 error.
        error: NotifierNotifyError,
    },
}

/// Failure to receive a message ([`Sub::receive`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("receive on {}: {error}", channel.name())]
pub struct ReceiveError {
    /// The channel.
    pub channel: Channel,
    /// The iceoryx2 error.
    pub error: IceReceiveError,
}

/// Failure of the wait on a channel's wake-ups ([`Sub::wait_for_wake_up`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("wait for {} wake-ups: {error}", channel.name())]
pub struct WaitError {
    /// The channel.
    pub channel: Channel,
    /// The iceoryx2 error.
    pub error: ListenerWaitError,
}

/// Failure of a WaitSet ([`waitset`] and the attachments and waits of the caller).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum WaitSetError {
    /// The WaitSet could not be created.
    #[error("cannot create the waitset: {0}")]
    Create(#[from] WaitSetCreateError),
    /// A listener, deadline or interval could not be attached.
    #[error("cannot attach to the waitset: {0}")]
    Attach(#[from] WaitSetAttachmentError),
    /// Waiting failed.
    #[error("waitset wait failed: {0}")]
    Wait(#[from] WaitSetRunError),
}

/// Failure to list the nodes of the machine ([`cleanup_dead_nodes`], [`alive_node_count`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("cannot list the iceoryx2 nodes: {0}")]
pub struct NodeListError(pub NodeListFailure);

/// Depth of each subscriber's queue, per channel: enough for one second of the fastest rate we
/// support plus margin, so that a briefly descheduled fusion loses nothing.
fn buffer_size(channel: Channel) -> usize {
    match channel {
        Channel::Imu | Channel::Truth | Channel::Nav => 2048,
        _ => 256,
    }
}

/// The publish-subscribe service of a channel and its paired event service.
struct Services<T: Message> {
    pubsub: publish_subscribe::PortFactory<IpcService, T, ()>,
    event: event::PortFactory<IpcService>,
}

/// A node on the bus with the service-name prefix of this run.
pub struct Bus {
    node: Node<IpcService>,
    prefix: String,
}

impl Bus {
    /// Create a node named `name` for the run with service prefix `prefix`. Signal handling by
    /// iceoryx2 is disabled: every Sextant process handles SIGINT/SIGTERM itself.
    pub fn new(prefix: &str, name: &str) -> Result<Self, NodeError> {
        let node_name: NodeName = name.try_into().map_err(NodeError::InvalidName)?;
        let node = NodeBuilder::new()
            .name(&node_name)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<IpcService>()
            .map_err(NodeError::Create)?;
        Ok(Self {
            node,
            prefix: prefix.to_string(),
        })
    }

    /// The service-name prefix.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// Open (or create) the services of `T`'s channel. Every process opens them with these
    /// settings, so that publishers and subscribers in different binaries always agree.
    fn services<T: Message>(&self) -> Result<Services<T>, ServiceError> {
        let channel = T::CHANNEL;
        let s = channel.service_name(&self.prefix);
        let name: ServiceName = s
            .as_str()
            .try_into()
            .map_err(|error| ServiceError::InvalidName { channel, error })?;
        let pubsub = self
            .node
            .service_builder(&name)
            .publish_subscribe::<T>()
            .subscriber_max_buffer_size(buffer_size(channel))
            .history_size(0)
            .max_publishers(4)
            .max_subscribers(8)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|error| ServiceError::PublishSubscribe { channel, error })?;
        let event = self
            .node
            .service_builder(&name)
            .event()
            .max_notifiers(8)
            .max_listeners(8)
            .open_or_create()
            .map_err(|error| ServiceError::Event { channel, error })?;
        Ok(Services { pubsub, event })
    }

    /// Open (or create) the publish-subscribe service and event service of `T`'s channel and
    /// return a publisher that notifies after every send.
    pub fn publisher<T: Message>(&self) -> Result<Pub<T>, PublisherError> {
        T::open_publisher(self)
    }

    /// Open (or create) the services of `T`'s channel and return a subscriber with its listener.
    pub fn subscriber<T: Message>(&self) -> Result<Sub<T>, SubscriberError> {
        T::open_subscriber(self)
    }
}

/// [`Bus::publisher`], instantiated once per message type by [`Message::open_publisher`].
pub(crate) fn publisher_of<T: Message>(bus: &Bus) -> Result<Pub<T>, PublisherError> {
    let channel = T::CHANNEL;
    let svc = bus.services::<T>()?;
    let publisher = svc
        .pubsub
        .publisher_builder()
        .create()
        .map_err(|error| PublisherError::Publisher { channel, error })?;
    let notifier = svc
        .event
        .notifier_builder()
        .create()
        .map_err(|error| PublisherError::Notifier { channel, error })?;
    Ok(Pub {
        publisher,
        notifier,
        seq: 0,
    })
}

/// [`Bus::subscriber`], instantiated once per message type by [`Message::open_subscriber`].
pub(crate) fn subscriber_of<T: Message>(bus: &Bus) -> Result<Sub<T>, SubscriberError> {
    let channel = T::CHANNEL;
    let svc = bus.services::<T>()?;
    let subscriber = svc
        .pubsub
        .subscriber_builder()
        .buffer_size(buffer_size(channel))
        .create()
        .map_err(|error| SubscriberError::Subscriber { channel, error })?;
    let listener = svc
        .event
        .listener_builder()
        .create()
        .map_err(|error| SubscriberError::Listener { channel, error })?;
    Ok(Sub {
        subscriber,
        listener,
    })
}

/// [`Pub::send_raw`], instantiated once per message type by [`Message::send_on`].
pub(crate) fn send_raw_of<T: Message>(p: &mut Pub<T>, msg: T) -> Result<(), SendError> {
    let channel = T::CHANNEL;
    p.publisher
        .send_copy(msg)
        .map_err(|error| SendError::Send { channel, error })?;
    p.notifier
        .notify()
        .map_err(|error| SendError::Notify { channel, error })?;
    Ok(())
}

/// [`Sub::receive`], instantiated once per message type by [`Message::receive_on`].
pub(crate) fn receive_of<T: Message>(s: &Sub<T>) -> Result<Option<T>, ReceiveError> {
    match s.subscriber.receive() {
        Ok(Some(sample)) => Ok(Some(*sample)),
        Ok(None) => Ok(None),
        Err(error) => Err(ReceiveError {
            channel: T::CHANNEL,
            error,
        }),
    }
}

/// A WaitSet with iceoryx2's signal handling disabled (every Sextant process handles
/// SIGINT/SIGTERM itself), to attach [`Sub::listener`]s, deadlines and intervals to.
pub fn waitset() -> Result<WaitSet<IpcService>, WaitSetError> {
    Ok(WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<IpcService>()?)
}

/// Publisher of one channel, with its notifier; stamps sequence number and send time.
pub struct Pub<T: Message> {
    publisher: Publisher<IpcService, T, ()>,
    notifier: Notifier<IpcService>,
    seq: u64,
}

impl<T: Message> Pub<T> {
    /// Stamp `msg`'s header (sequence number, monotonic send time), send it by copy into shared
    /// memory and wake the listeners. Returns the stamped message.
    pub fn send(&mut self, mut msg: T) -> Result<T, SendError> {
        self.seq += 1;
        let h = msg.header_mut();
        h.seq = self.seq;
        h.send_mono_ns = crate::monotonic_ns();
        self.send_raw(msg)?;
        Ok(msg)
    }

    /// Account for a sample the source produced but will never deliver (a driver that fell
    /// behind its sensor's clock drops the overdue samples, as a real sensor's FIFO does): its
    /// sequence number is consumed, so every subscriber counts the loss as a sequence gap.
    pub fn skip(&mut self) {
        self.seq += 1;
    }

    /// Send `msg` as it is (header untouched), e.g. when republishing a recording.
    pub fn send_raw(&mut self, msg: T) -> Result<(), SendError> {
        T::send_on(self, msg)
    }
}

/// Subscriber of one channel, with the listener to attach to a WaitSet.
pub struct Sub<T: Message> {
    subscriber: Subscriber<IpcService, T, ()>,
    listener: Listener<IpcService>,
}

impl<T: Message> Sub<T> {
    /// The event listener, to attach to a WaitSet.
    pub fn listener(&self) -> &Listener<IpcService> {
        &self.listener
    }

    /// Block until this channel's publisher wakes the listener or `timeout` passes, and
    /// consume the wake-ups. The listener's own wait (a receive with a timeout on its socket),
    /// not a WaitSet's: no allocation, where every WaitSet wait allocates twice in iceoryx2
    /// 0.10. A signal ends the wait early, as a timeout does.
    pub fn wait_for_wake_up(&self, timeout: Duration) -> Result<(), WaitError> {
        match self.listener.timed_wait(|_| {}, timeout) {
            Ok(_) | Err(ListenerWaitError::InterruptSignal) => Ok(()),
            Err(error) => Err(WaitError {
                channel: T::CHANNEL,
                error,
            }),
        }
    }

    /// Consume pending wake-ups (call before draining samples).
    pub fn clear_events(&self) {
        let _ = self.listener.try_wait(|_| {});
    }

    /// Take the next sample, copied out of shared memory.
    pub fn receive(&self) -> Result<Option<T>, ReceiveError> {
        T::receive_on(self)
    }

    /// Whether a wake-up is pending on the listener, without consuming it (a `poll` of its file
    /// descriptor with no timeout: one system call, no allocation, no sleep). For polling
    /// before a WaitSet wait, which then returns at once and still sees the wake-up.
    pub fn wake_up_pending(&self) -> bool {
        // SAFETY: the descriptor belongs to the listener, alive for the borrow of `self`.
        let fd = unsafe { self.listener.file_descriptor().native_handle() };
        let mut pfd = [PollFd {
            fd,
            events: POLLIN,
            revents: 0,
        }];
        // SAFETY: one pollfd we own, timeout 0 (never blocks).
        let n = unsafe { poll(pfd.as_mut_ptr(), 1, 0) };
        n > 0 && pfd[0].revents & POLLIN != 0
    }
}

/// Remove the shared-memory resources of nodes whose process died (a crashed run), so that a new
/// run starts clean. Returns the number of dead nodes cleaned.
pub fn cleanup_dead_nodes() -> Result<usize, NodeListError> {
    let mut cleaned = 0;
    Node::<IpcService>::list(Config::global_config(), |state| {
        if let NodeState::<IpcService>::Dead(view) = state
            && view.try_remove_stale_resources().is_ok()
        {
            cleaned += 1;
        }
        CallbackProgression::Continue
    })
    .map_err(NodeListError)?;
    Ok(cleaned)
}

/// Number of nodes currently alive (all prefixes).
pub fn alive_node_count() -> Result<usize, NodeListError> {
    let mut n = 0;
    Node::<IpcService>::list(Config::global_config(), |state| {
        if let NodeState::<IpcService>::Alive(_) = state {
            n += 1;
        }
        CallbackProgression::Continue
    })
    .map_err(NodeListError)?;
    Ok(n)
}

/// `struct pollfd` of poll(2).
#[repr(C)]
struct PollFd {
    fd: i32,
    events: i16,
    revents: i16,
}

/// `POLLIN` of poll(2): data to read.
const POLLIN: i16 = 0x001;

unsafe extern "C" {
    fn poll(fds: *mut PollFd, nfds: core::ffi::c_ulong, timeout_ms: i32) -> i32;
}
