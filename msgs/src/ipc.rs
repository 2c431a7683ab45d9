//! iceoryx2 plumbing shared by every process: one place that fixes how each channel's services
//! are configured, so that publishers and subscribers in different binaries always agree.
//!
//! Each channel is a publish-subscribe service paired with an event service of the same name:
//! a publisher notifies after every send, so that a subscriber can block on a WaitSet (with a
//! deadline for silent sensors) instead of polling (iceoryx2 0.10 subscribers cannot block).

use crate::{Channel, Message};
use iceoryx2::node::NodeState;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

/// Errors of the shared-memory transport.
#[derive(Debug, thiserror::Error)]
pub enum IpcError {
    /// An iceoryx2 call failed.
    #[error("iceoryx2: {context} failed: {detail}")]
    Iceoryx {
        /// What was attempted (names the service).
        context: String,
        /// The iceoryx2 error.
        detail: String,
    },
}

fn ice<E: core::fmt::Debug>(context: impl Into<String>) -> impl FnOnce(E) -> IpcError {
    let context = context.into();
    move |e| IpcError::Iceoryx {
        context,
        detail: format!("{e:?}"),
    }
}

/// Depth of each subscriber's queue, per channel: enough for one second of the fastest rate we
/// support plus margin, so that a briefly descheduled fusion loses nothing.
fn buffer_size(channel: Channel) -> usize {
    match channel {
        Channel::Imu | Channel::Truth | Channel::Nav => 2048,
        _ => 256,
    }
}

/// A node on the bus with the service-name prefix of this run.
pub struct Bus {
    node: Node<ipc::Service>,
    prefix: String,
}

impl Bus {
    /// Create a node named `name` for the run with service prefix `prefix`. Signal handling by
    /// iceoryx2 is disabled: every Sextant process handles SIGINT/SIGTERM itself.
    pub fn new(prefix: &str, name: &str) -> Result<Self, IpcError> {
        let node_name: NodeName = name.try_into().map_err(ice(format!("node name {name}")))?;
        let node = NodeBuilder::new()
            .name(&node_name)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(ice(format!("create node {name}")))?;
        Ok(Self {
            node,
            prefix: prefix.to_string(),
        })
    }

    /// The service-name prefix.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    fn service_name(&self, channel: Channel) -> Result<ServiceName, IpcError> {
        let s = channel.service_name(&self.prefix);
        s.as_str()
            .try_into()
            .map_err(ice(format!("service name {s}")))
    }

    /// Open (or create) the publish-subscribe service and event service of `T`'s channel and
    /// return a publisher that notifies after every send.
    pub fn publisher<T: Message>(&self) -> Result<Pub<T>, IpcError> {
        let name = self.service_name(T::CHANNEL)?;
        let svc = self
            .node
            .service_builder(&name)
            .publish_subscribe::<T>()
            .subscriber_max_buffer_size(buffer_size(T::CHANNEL))
            .history_size(0)
            .max_publishers(4)
            .max_subscribers(8)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(ice(format!("open pub-sub service {name}")))?;
        let publisher = svc
            .publisher_builder()
            .create()
            .map_err(ice(format!("create publisher {name}")))?;
        let ev = self
            .node
            .service_builder(&name)
            .event()
            .max_notifiers(8)
            .max_listeners(8)
            .open_or_create()
            .map_err(ice(format!("open event service {name}")))?;
        let notifier = ev
            .notifier_builder()
            .create()
            .map_err(ice(format!("create notifier {name}")))?;
        Ok(Pub {
            publisher,
            notifier,
            seq: 0,
        })
    }

    /// Open (or create) the services of `T`'s channel and return a subscriber with its listener.
    pub fn subscriber<T: Message>(&self) -> Result<Sub<T>, IpcError> {
        let name = self.service_name(T::CHANNEL)?;
        let svc = self
            .node
            .service_builder(&name)
            .publish_subscribe::<T>()
            .subscriber_max_buffer_size(buffer_size(T::CHANNEL))
            .history_size(0)
            .max_publishers(4)
            .max_subscribers(8)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(ice(format!("open pub-sub service {name}")))?;
        let subscriber = svc
            .subscriber_builder()
            .buffer_size(buffer_size(T::CHANNEL))
            .create()
            .map_err(ice(format!("create subscriber {name}")))?;
        let ev = self
            .node
            .service_builder(&name)
            .event()
            .max_notifiers(8)
            .max_listeners(8)
            .open_or_create()
            .map_err(ice(format!("open event service {name}")))?;
        let listener = ev
            .listener_builder()
            .create()
            .map_err(ice(format!("create listener {name}")))?;
        Ok(Sub {
            subscriber,
            listener,
        })
    }
}

/// Publisher of one channel, with its notifier; stamps sequence number and send time.
pub struct Pub<T: Message> {
    publisher: Publisher<ipc::Service, T, ()>,
    notifier: Notifier<ipc::Service>,
    seq: u64,
}

impl<T: Message> Pub<T> {
    /// Stamp `msg`'s header (sequence number, monotonic send time), send it by copy into shared
    /// memory and wake the listeners. Returns the stamped message.
    pub fn send(&mut self, mut msg: T) -> Result<T, IpcError> {
        self.seq += 1;
        let h = msg.header_mut();
        h.seq = self.seq;
        h.send_mono_ns = crate::monotonic_ns();
        self.send_raw(msg)?;
        Ok(msg)
    }

    /// Send `msg` as it is (header untouched), e.g. when republishing a recording.
    pub fn send_raw(&mut self, msg: T) -> Result<(), IpcError> {
        // The error context is formatted only on failure: this runs once per published
        // message, which must not allocate (the daemon's hot path).
        self.publisher
            .send_copy(msg)
            .map_err(|e| ice(format!("send on {}", T::CHANNEL.name()))(e))?;
        self.notifier
            .notify()
            .map_err(|e| ice(format!("notify on {}", T::CHANNEL.name()))(e))?;
        Ok(())
    }
}

/// Subscriber of one channel, with the listener to attach to a WaitSet.
pub struct Sub<T: Message> {
    subscriber: Subscriber<ipc::Service, T, ()>,
    listener: Listener<ipc::Service>,
}

impl<T: Message> Sub<T> {
    /// The event listener, to attach to a WaitSet.
    pub fn listener(&self) -> &Listener<ipc::Service> {
        &self.listener
    }

    /// Consume pending wake-ups (call before draining samples).
    pub fn clear_events(&self) {
        let _ = self.listener.try_wait(|_| {});
    }

    /// Take the next sample, copied out of shared memory.
    pub fn receive(&self) -> Result<Option<T>, IpcError> {
        match self.subscriber.receive() {
            Ok(Some(sample)) => Ok(Some(*sample)),
            Ok(None) => Ok(None),
            Err(e) => Err(ice(format!("receive on {}", T::CHANNEL.name()))(e)),
        }
    }
}

/// Remove the shared-memory resources of nodes whose process died (a crashed run), so that a new
/// run starts clean. Returns the number of dead nodes cleaned.
pub fn cleanup_dead_nodes() -> Result<usize, IpcError> {
    let mut cleaned = 0;
    Node::<ipc::Service>::list(Config::global_config(), |state| {
        if let NodeState::<ipc::Service>::Dead(view) = state
            && view.try_remove_stale_resources().is_ok()
        {
            cleaned += 1;
        }
        CallbackProgression::Continue
    })
    .map_err(ice("list nodes"))?;
    Ok(cleaned)
}

/// Number of nodes currently alive (all prefixes).
pub fn alive_node_count() -> Result<usize, IpcError> {
    let mut n = 0;
    Node::<ipc::Service>::list(Config::global_config(), |state| {
        if let NodeState::<ipc::Service>::Alive(_) = state {
            n += 1;
        }
        CallbackProgression::Continue
    })
    .map_err(ice("list nodes"))?;
    Ok(n)
}
