//! The bridge: a running system's bus channels to other computers over Zenoh, and remote
//! channels into the local bus.
//!
//! A navigation computer serves other computers (autopilot, mission computer, ground station):
//! the bridge process (`sextant-bridge`, started by `sextant run` when `[bridge]` is
//! configured) is a subscriber on the bus like the recorder, and
//! - **exports** the configured channels (by default the solution and the status): every
//!   message is put on Zenoh under `<key_prefix>/v1/<channel>` in its protobuf form
//!   ([`wire`] documents the format and its version);
//! - **imports** channels of a remote system (`<import_from>/v1/<channel>`, e.g. a sensor on
//!   another computer, or the solution on a ground station) and publishes each message,
//!   unchanged, on the local bus, where the fusion daemon, the recorder and the live view see
//!   it as any local publisher's.
//!
//! Zenoh runs in peer mode over TCP only, between the endpoints configured (`listen`,
//! `connect`): scouting is off, so a vehicle's bridge never links to whatever else answers on
//! its network. A lost link is retried every second at most (`connect/retry`), for ever.
//!
//! **The link's state**: each bridge declares a liveliness token ([`wire::alive_key`]). An
//! importing bridge follows the tokens of the system it imports from: the link is *up* while
//! one is seen, *down* when the last one vanishes — at once when the remote bridge stops or
//! its connection closes, within the lease (`lease_ms`) when the network silently drops
//! (cable, radio). A repaired link is used again within a lease and a retry period (a
//! connection attempt that started while the link was silent gives up after a lease). Each change is logged (`link to … up/down`), counted, and sent to the
//! service manager as the bridge's `STATUS=` (what `systemctl status` and `sextant run` show).
//! Consumers on the local bus also see the imported messages stop, as they do for any source.
//!
//! A channel cannot be both exported and imported: what the bridge publishes locally it would
//! receive and send back. Messages that fail to decode are counted and dropped, never
//! published. The bridge's queues are bounded: an import arriving faster than the local bus
//! takes it drops the newest messages (counted), and the export drops on a congested link
//! (Zenoh's `CongestionControl::Drop`), so neither a slow network nor a slow reader ever
//! blocks the fusion daemon, which only ever writes to shared memory.

pub mod wire;

use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::*;
use msgs::ipc::{Bus, Pub, Sub};
use msgs::{
    BaroSample, Channel, GnssSample, ImuSample, Message, NavSolution, OdometerSample, Record,
    RecordKind, StarTrackerSample, Status, TruthSample,
};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// Default lease of a link, ms: a silently dropped link is declared down after at most this.
pub const DEFAULT_LEASE_MS: u64 = 3000;

/// Capacity of the queue between Zenoh's receiving threads and the local publishers, messages:
/// one second of the fastest IMU this system supports.
const IMPORT_QUEUE: usize = 2048;

/// How often the bridge looks at its stop flag, peers and link, at most.
const TICK: Duration = Duration::from_millis(250);

/// What the bridge does.
#[derive(Debug, Clone, PartialEq)]
pub struct BridgeOptions {
    /// Service-name prefix of the local bus.
    pub prefix: String,
    /// This bridge's name: its iceoryx2 node and its liveliness token.
    pub name: String,
    /// Key prefix under which the exported channels are published.
    pub key_prefix: String,
    /// Zenoh endpoints to listen on (`tcp/IP:PORT`).
    pub listen: Vec<String>,
    /// Zenoh endpoints to connect to (`tcp/HOST:PORT`).
    pub connect: Vec<String>,
    /// Local channels published on Zenoh.
    pub export: Vec<Channel>,
    /// Remote channels published on the local bus.
    pub import: Vec<Channel>,
    /// Key prefix of the remote system whose channels are imported.
    pub import_from: String,
    /// Lease of the links, ms: a silent link is declared down after it.
    pub lease_ms: u64,
}

/// Failure of the bridge ([`run`], [`BridgeOptions::check`]).
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// A key prefix cannot name a system's channels.
    #[error("key prefix {prefix:?}: {error}")]
    KeyPrefix {
        /// The prefix.
        prefix: String,
        /// Why.
        error: wire::KeyPrefixError,
    },
    /// An endpoint is not `tcp/HOST:PORT` (the only transport built in).
    #[error("Zenoh endpoint {endpoint:?}: {detail}")]
    Endpoint {
        /// The endpoint.
        endpoint: String,
        /// Why.
        detail: String,
    },
    /// A channel is both exported and imported.
    #[error("channel {} is both exported and imported (it would loop back)", .0.name())]
    Loop(Channel),
    /// Channels are imported but nothing names the remote system.
    #[error("channels are imported but no remote key prefix (import_from) is given")]
    NoImportFrom,
    /// The lease is outside 100 ms – 1 h.
    #[error("lease {0} ms is outside 100 ms – 3 600 000 ms")]
    Lease(u64),
    /// The Zenoh configuration refused a setting.
    #[error("Zenoh configuration {key}: {detail}")]
    Config {
        /// The configuration key.
        key: &'static str,
        /// Zenoh's message.
        detail: String,
    },
    /// The Zenoh session could not be opened (e.g. a listen endpoint is in use).
    #[error("cannot open the Zenoh session: {0}")]
    Open(String),
    /// A publisher, subscriber, queryable or token could not be declared.
    #[error("Zenoh {what} on {key}: {detail}")]
    Declare {
        /// What was declared.
        what: &'static str,
        /// Its key expression.
        key: String,
        /// Zenoh's message.
        detail: String,
    },
    /// The local bus could not be joined or waited on.
    #[error("bus {prefix:?}: {detail}")]
    Bus {
        /// The service-name prefix.
        prefix: String,
        /// What failed.
        detail: String,
    },
    /// The import thread failed.
    #[error("import: {0}")]
    Import(Box<BridgeError>),
}

/// What the bridge did, for its exit log.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BridgeCounters {
    /// Messages put on Zenoh.
    pub exported: u64,
    /// Exported messages Zenoh refused.
    pub export_errors: u64,
    /// Messages received from Zenoh and published on the local bus.
    pub imported: u64,
    /// Received messages dropped because the import queue was full.
    pub import_dropped: u64,
    /// Received messages that did not decode (not published).
    pub decode_errors: u64,
    /// Times the link to the imported system went down.
    pub link_losses: u64,
    /// Local bus receive or send errors.
    pub bus_errors: u64,
}

impl BridgeOptions {
    /// Check the options before anything is opened; every error names the value.
    pub fn check(&self) -> Result<(), BridgeError> {
        let key = |prefix: &str| {
            wire::check_key_prefix(prefix).map_err(|error| BridgeError::KeyPrefix {
                prefix: prefix.to_string(),
                error,
            })
        };
        key(&self.key_prefix)?;
        if !self.import.is_empty() {
            if self.import_from.is_empty() {
                return Err(BridgeError::NoImportFrom);
            }
            key(&self.import_from)?;
        }
        for e in self.listen.iter().chain(&self.connect) {
            check_endpoint(e)?;
        }
        if let Some(&c) = self.export.iter().find(|c| self.import.contains(c)) {
            return Err(BridgeError::Loop(c));
        }
        if !(100..=3_600_000).contains(&self.lease_ms) {
            return Err(BridgeError::Lease(self.lease_ms));
        }
        Ok(())
    }
}

/// Check that `endpoint` is `tcp/HOST:PORT` (with an optional Zenoh `?`/`#` tail).
pub fn check_endpoint(endpoint: &str) -> Result<(), BridgeError> {
    let bad = |detail: &str| BridgeError::Endpoint {
        endpoint: endpoint.to_string(),
        detail: detail.to_string(),
    };
    let Some(addr) = endpoint.strip_prefix("tcp/") else {
        return Err(bad("only tcp/HOST:PORT is supported"));
    };
    let addr = addr.split(['?', '#']).next().unwrap_or_default();
    let Some((host, port)) = addr.rsplit_once(':') else {
        return Err(bad("no :PORT"));
    };
    if host.is_empty() || port.parse::<u16>().is_err() {
        return Err(bad("expected tcp/HOST:PORT with PORT in 0–65535"));
    }
    endpoint
        .parse::<zenoh::config::EndPoint>()
        .map_err(|e| bad(&e.to_string()))?;
    Ok(())
}

/// The Zenoh configuration of a bridge: peer mode, the endpoints given, no scouting, the lease,
/// deeper transmit queues, and reconnection every 250 ms – 1 s.
pub fn session_config(o: &BridgeOptions) -> Result<zenoh::Config, BridgeError> {
    let mut c = zenoh::Config::default();
    let json = |v: &[String]| serde_json::to_string(v).unwrap_or_default();
    let settings: [(&'static str, String); 11] = [
        ("mode", "\"peer\"".into()),
        ("listen/endpoints", json(&o.listen)),
        ("connect/endpoints", json(&o.connect)),
        ("scouting/multicast/enabled", "false".into()),
        ("scouting/gossip/enabled", "false".into()),
        ("transport/link/tx/lease", o.lease_ms.to_string()),
        // A connection attempt over a link that went silent hangs in its handshake until this
        // timeout (Zenoh's default 10 s) before the next retry: bounded by the lease, a repaired
        // link is used again within a lease and a retry period.
        ("transport/unicast/open_timeout", o.lease_ms.to_string()),
        ("transport/unicast/accept_timeout", o.lease_ms.to_string()),
        // Zenoh's default holds 2 batches per priority and drops a message that waits 1 ms
        // for one: on a loaded computer a healthy link lost solutions. 16 batches (allocated
        // only when used) and 20 ms: a link that stalls for less loses nothing, a congested
        // one still drops instead of blocking the export.
        ("transport/link/tx/queue/size/data", "16".into()),
        (
            "transport/link/tx/queue/congestion_control/drop/wait_before_drop",
            "20000".into(),
        ),
        (
            "connect/retry",
            "{ period_init_ms: 250, period_max_ms: 1000, period_increase_factor: 2 }".into(),
        ),
    ];
    for (key, value) in settings {
        c.insert_json5(key, &value)
            .map_err(|e| BridgeError::Config {
                key,
                detail: e.to_string(),
            })?;
    }
    Ok(c)
}

/// One local channel's subscriber, whatever its message type.
trait Export {
    fn listener(&self) -> &Listener<msgs::ipc::IpcService>;
    /// Take every pending message, as a record, until none is left or receiving fails.
    fn drain(&self, out: &mut dyn FnMut(Record)) -> Result<(), msgs::ipc::ReceiveError>;
}

impl<T: Message + Into<Record>> Export for Sub<T> {
    fn listener(&self) -> &Listener<msgs::ipc::IpcService> {
        Sub::listener(self)
    }
    fn drain(&self, out: &mut dyn FnMut(Record)) -> Result<(), msgs::ipc::ReceiveError> {
        self.clear_events();
        while let Some(m) = self.receive()? {
            out(m.into());
        }
        Ok(())
    }
}

fn export_sub(bus: &Bus, ch: Channel) -> Result<Box<dyn Export>, msgs::ipc::SubscriberError> {
    Ok(match ch {
        Channel::Imu => Box::new(bus.subscriber::<ImuSample>()?),
        Channel::StarTracker => Box::new(bus.subscriber::<StarTrackerSample>()?),
        Channel::Gnss => Box::new(bus.subscriber::<GnssSample>()?),
        Channel::Odometer => Box::new(bus.subscriber::<OdometerSample>()?),
        Channel::Baro => Box::new(bus.subscriber::<BaroSample>()?),
        Channel::Truth => Box::new(bus.subscriber::<TruthSample>()?),
        Channel::Nav => Box::new(bus.subscriber::<NavSolution>()?),
        Channel::Status => Box::new(bus.subscriber::<Status>()?),
    })
}

/// The local publishers of the imported channels.
#[derive(Default)]
struct ImportPubs {
    imu: Option<Pub<ImuSample>>,
    star: Option<Pub<StarTrackerSample>>,
    gnss: Option<Pub<GnssSample>>,
    odo: Option<Pub<OdometerSample>>,
    baro: Option<Pub<BaroSample>>,
    truth: Option<Pub<TruthSample>>,
    nav: Option<Pub<NavSolution>>,
    status: Option<Pub<Status>>,
}

impl ImportPubs {
    fn new(bus: &Bus, channels: &[Channel]) -> Result<Self, msgs::ipc::PublisherError> {
        let mut p = Self::default();
        for &ch in channels {
            match ch {
                Channel::Imu => p.imu = Some(bus.publisher()?),
                Channel::StarTracker => p.star = Some(bus.publisher()?),
                Channel::Gnss => p.gnss = Some(bus.publisher()?),
                Channel::Odometer => p.odo = Some(bus.publisher()?),
                Channel::Baro => p.baro = Some(bus.publisher()?),
                Channel::Truth => p.truth = Some(bus.publisher()?),
                Channel::Nav => p.nav = Some(bus.publisher()?),
                Channel::Status => p.status = Some(bus.publisher()?),
            }
        }
        Ok(p)
    }

    /// Publish `r` unchanged (header as the remote publisher stamped it). A record of a channel
    /// not imported is ignored (cannot happen: the subscribers are per imported channel).
    fn publish(&mut self, r: Record) -> Result<(), msgs::ipc::SendError> {
        fn send<T: Message>(p: &mut Option<Pub<T>>, m: T) -> Result<(), msgs::ipc::SendError> {
            p.as_mut().map_or(Ok(()), |p| p.send_raw(m))
        }
        match r {
            Record::Imu(m) => send(&mut self.imu, m),
            Record::StarTracker(m) => send(&mut self.star, m),
            Record::Gnss(m) => send(&mut self.gnss, *m),
            Record::Odometer(m) => send(&mut self.odo, m),
            Record::Baro(m) => send(&mut self.baro, m),
            Record::Truth(m) => send(&mut self.truth, m),
            Record::Nav(m) => send(&mut self.nav, m),
            Record::Status(m) => send(&mut self.status, *m),
            Record::SensorAlive(_) => Ok(()),
        }
    }
}

/// What Zenoh's threads hand to the import thread.
enum Inbound {
    /// A message of an imported channel, in its wire form.
    Message(Channel, Vec<u8>),
    /// A remote bridge's liveliness token appeared (`true`) or vanished (`false`).
    Alive(String, bool),
}

/// Counters and link state shared between the threads.
#[derive(Default)]
struct Shared {
    imported: AtomicU64,
    import_dropped: AtomicU64,
    decode_errors: AtomicU64,
    link_losses: AtomicU64,
    bus_errors: AtomicU64,
    /// Remote bridges alive (liveliness tokens seen) of the imported system.
    remotes_alive: AtomicU64,
}

fn declare_err<'k>(what: &'static str, key: &'k str) -> impl Fn(zenoh::Error) -> BridgeError + 'k {
    move |e| BridgeError::Declare {
        what,
        key: key.to_string(),
        detail: e.to_string(),
    }
}

/// The import thread: decode what Zenoh delivered, publish it on the local bus, follow the
/// remote bridges' liveliness. Ends when `stop` is set or the queue's senders are gone.
fn import_loop(
    opts: &BridgeOptions,
    rx: &Receiver<Inbound>,
    shared: &Shared,
    stop: &AtomicBool,
) -> Result<(), BridgeError> {
    let bus_err = |detail: String| BridgeError::Bus {
        prefix: opts.prefix.clone(),
        detail,
    };
    let bus = Bus::new(&opts.prefix, &format!("{}-import", opts.name))
        .map_err(|e| bus_err(e.to_string()))?;
    let mut pubs = ImportPubs::new(&bus, &opts.import).map_err(|e| bus_err(e.to_string()))?;
    // Remote bridges' liveliness tokens seen, per key, with their count.
    let mut alive: Vec<(String, u32)> = Vec::new();
    while !stop.load(Ordering::SeqCst) {
        let inbound = match rx.recv_timeout(TICK) {
            Ok(i) => i,
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => break,
        };
        match inbound {
            Inbound::Message(ch, bytes) => {
                match Record::from_protobuf(RecordKind::Channel(ch), &bytes) {
                    Ok(r) => match pubs.publish(r) {
                        Ok(()) => {
                            shared.imported.fetch_add(1, Ordering::Relaxed);
                        }
                        Err(e) => {
                            if shared.bus_errors.fetch_add(1, Ordering::Relaxed) == 0 {
                                tracing::warn!("{e} (further bus errors only counted)");
                            }
                        }
                    },
                    Err(e) => {
                        if shared.decode_errors.fetch_add(1, Ordering::Relaxed) == 0 {
                            tracing::warn!(
                                "a message on {} does not decode ({e}); dropped (further ones only counted)",
                                wire::data_key(&opts.import_from, ch)
                            );
                        }
                    }
                }
            }
            // Tokens are counted per key: a restarted remote bridge declares the same key
            // again, possibly before its old token's lease has run out.
            Inbound::Alive(key, true) => {
                match alive.iter_mut().find(|(k, _)| *k == key) {
                    Some((_, n)) => *n += 1,
                    None => alive.push((key.clone(), 1)),
                }
                if alive.len() == 1 && alive[0].1 == 1 {
                    tracing::info!("link to {} up (bridge {key})", opts.import_from);
                }
            }
            Inbound::Alive(key, false) => {
                let before = alive.len();
                if let Some((_, n)) = alive.iter_mut().find(|(k, _)| *k == key) {
                    *n = n.saturating_sub(1);
                }
                alive.retain(|(_, n)| *n > 0);
                if before > 0 && alive.is_empty() {
                    shared.link_losses.fetch_add(1, Ordering::Relaxed);
                    tracing::warn!(
                        "link to {} down (bridge {key} gone: stopped, or silent for the {} ms lease)",
                        opts.import_from,
                        opts.lease_ms
                    );
                }
            }
        }
        shared
            .remotes_alive
            .store(alive.len() as u64, Ordering::Relaxed);
    }
    Ok(())
}

/// Run the bridge until `stop` is set; calls `ready` once the session is open and every port
/// declared. Returns the counters.
pub fn run(
    opts: &BridgeOptions,
    stop: &'static AtomicBool,
    ready: &mut dyn FnMut(),
) -> Result<BridgeCounters, BridgeError> {
    opts.check()?;
    let bus_err = |detail: String| BridgeError::Bus {
        prefix: opts.prefix.clone(),
        detail,
    };
    let session = zenoh::open(session_config(opts)?)
        .wait()
        .map_err(|e| BridgeError::Open(e.to_string()))?;

    let own_alive = wire::alive_key(&opts.key_prefix, &opts.name);
    let _token = session
        .liveliness()
        .declare_token(own_alive.as_str())
        .wait()
        .map_err(declare_err("liveliness token", &own_alive))?;

    // Export: one publisher and one schema queryable per channel.
    let mut publishers = Vec::with_capacity(opts.export.len());
    let mut queryables = Vec::with_capacity(opts.export.len());
    for &ch in &opts.export {
        let key = wire::data_key(&opts.key_prefix, ch);
        publishers.push(
            session
                .declare_publisher(key.clone())
                .encoding(wire::encoding(ch))
                .congestion_control(zenoh::qos::CongestionControl::Drop)
                .wait()
                .map_err(declare_err("publisher", &key))?,
        );
        let schema_key = wire::schema_key(&opts.key_prefix, ch);
        let (_, descriptors) = RecordKind::Channel(ch).protobuf_schema();
        queryables.push(
            session
                .declare_queryable(schema_key.clone())
                .callback(move |query| {
                    let reply = query
                        .reply(query.key_expr().clone(), descriptors.clone())
                        .encoding(
                            zenoh::bytes::Encoding::APPLICATION_PROTOBUF
                                .with_schema("google.protobuf.FileDescriptorSet"),
                        )
                        .wait();
                    if let Err(e) = reply {
                        tracing::warn!("schema query: {e}");
                    }
                })
                .wait()
                .map_err(declare_err("queryable", &schema_key))?,
        );
    }

    // Import: Zenoh's callbacks queue what arrives for the import thread, which owns the local
    // publishers (iceoryx2 ports stay on the thread that made them).
    let shared = Arc::new(Shared::default());
    let (tx, rx) = std::sync::mpsc::sync_channel::<Inbound>(IMPORT_QUEUE);
    let queue = |tx: SyncSender<Inbound>, shared: Arc<Shared>| {
        move |i: Inbound| match tx.try_send(i) {
            Ok(()) | Err(TrySendError::Disconnected(_)) => {}
            Err(TrySendError::Full(_)) => {
                shared.import_dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    };
    let mut subscribers = Vec::with_capacity(opts.import.len());
    let mut liveliness = None;
    let mut import_thread = None;
    if !opts.import.is_empty() {
        for &ch in &opts.import {
            let key = wire::data_key(&opts.import_from, ch);
            let push = queue(tx.clone(), shared.clone());
            subscribers.push(
                session
                    .declare_subscriber(key.clone())
                    .callback(move |sample| {
                        push(Inbound::Message(
                            ch,
                            sample.payload().to_bytes().into_owned(),
                        ));
                    })
                    .wait()
                    .map_err(declare_err("subscriber", &key))?,
            );
        }
        let key = wire::alive_keys(&opts.import_from);
        let push = queue(tx.clone(), shared.clone());
        liveliness = Some(
            session
                .liveliness()
                .declare_subscriber(key.clone())
                .history(true)
                .callback(move |sample| {
                    let put = sample.kind() == zenoh::sample::SampleKind::Put;
                    push(Inbound::Alive(sample.key_expr().to_string(), put));
                })
                .wait()
                .map_err(declare_err("liveliness subscriber", &key))?,
        );
        let (o, s) = (opts.clone(), shared.clone());
        import_thread = Some(
            std::thread::Builder::new()
                .name("import".into())
                .spawn(move || import_loop(&o, &rx, &s, stop))
                .map_err(|e| bus_err(format!("cannot start the import thread: {e}")))?,
        );
    }
    drop(tx);

    // Export loop: wait on the local channels' listeners.
    let bus = Bus::new(&opts.prefix, &opts.name).map_err(|e| bus_err(e.to_string()))?;
    let subs = opts
        .export
        .iter()
        .map(|&ch| export_sub(&bus, ch))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| bus_err(e.to_string()))?;
    let ws = msgs::ipc::waitset().map_err(|e| bus_err(e.to_string()))?;
    // The tick wakes the loop when nothing is exported (or the bus is silent), for the stop
    // flag, the link's state and the watchdog.
    let tick = ws
        .attach_interval(TICK)
        .map_err(|e| bus_err(format!("attach: {e:?}")))?;
    let mut guards = Vec::with_capacity(subs.len());
    for s in &subs {
        guards.push(
            ws.attach_notification(s.listener())
                .map_err(|e| bus_err(format!("attach: {e:?}")))?,
        );
    }
    ready();

    let mut counters = BridgeCounters::default();
    let mut service = msgs::sd_notify::Service::from_env();
    let mut buf = Vec::with_capacity(4096);
    let mut last_status = String::new();
    let mut last_look = Instant::now() - TICK;
    let mut peers = 0;
    while !stop.load(Ordering::SeqCst) {
        ws.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, TICK)
            .map_err(|e| bus_err(format!("wait: {e:?}")))?;
        for (s, publisher) in subs.iter().zip(&publishers) {
            let drained = s.drain(&mut |r| {
                r.write_protobuf(&mut buf);
                match publisher.put(buf.as_slice()).wait() {
                    Ok(()) => counters.exported += 1,
                    Err(e) => {
                        if counters.export_errors == 0 {
                            tracing::warn!("put on {}: {e}", publisher.key_expr());
                        }
                        counters.export_errors += 1;
                    }
                }
            });
            if let Err(e) = drained {
                if counters.bus_errors == 0 {
                    tracing::warn!("{e}");
                }
                counters.bus_errors += 1;
            }
        }
        if last_look.elapsed() >= TICK {
            last_look = Instant::now();
            let now_peers = session.info().peers_zid().wait().count();
            if now_peers != peers {
                tracing::info!("connected to {now_peers} Zenoh peer(s)");
                peers = now_peers;
            }
            let status = status_line(opts, peers, &shared);
            if status != last_status {
                service.status(&status);
                last_status = status;
            }
            service.ping();
            if let Some(t) = &import_thread
                && t.is_finished()
            {
                break;
            }
        }
    }
    service.stopping();
    drop(guards);
    drop(tick);
    drop(subscribers);
    drop(liveliness);
    if let Some(t) = import_thread {
        stop.store(true, Ordering::SeqCst);
        match t.join() {
            Ok(r) => r.map_err(|e| BridgeError::Import(Box::new(e)))?,
            Err(_) => return Err(BridgeError::Import(Box::new(bus_err("panicked".into())))),
        }
    }
    drop(queryables);
    drop(publishers);
    if let Err(e) = session.close().wait() {
        tracing::warn!("closing the Zenoh session: {e}");
    }
    counters.imported = shared.imported.load(Ordering::Relaxed);
    counters.import_dropped = shared.import_dropped.load(Ordering::Relaxed);
    counters.decode_errors = shared.decode_errors.load(Ordering::Relaxed);
    counters.link_losses = shared.link_losses.load(Ordering::Relaxed);
    counters.bus_errors += shared.bus_errors.load(Ordering::Relaxed);
    Ok(counters)
}

/// The bridge's one-line state for the service manager: peers, and the link to the imported
/// system when there is one.
fn status_line(opts: &BridgeOptions, peers: usize, shared: &Shared) -> String {
    let mut s = format!("{peers} Zenoh peer(s)");
    if !opts.import.is_empty() {
        let up = shared.remotes_alive.load(Ordering::Relaxed) > 0;
        s += &format!(
            "; link to {} {}; {} link loss(es)",
            opts.import_from,
            if up { "up" } else { "down" },
            shared.link_losses.load(Ordering::Relaxed)
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts() -> BridgeOptions {
        BridgeOptions {
            prefix: "sextant".into(),
            name: "a".into(),
            key_prefix: "car1".into(),
            listen: vec!["tcp/127.0.0.1:7447".into()],
            connect: vec![],
            export: vec![Channel::Nav, Channel::Status],
            import: vec![],
            import_from: String::new(),
            lease_ms: DEFAULT_LEASE_MS,
        }
    }

    #[test]
    fn options_are_checked_by_name() {
        assert!(opts().check().is_ok());
        let mut o = opts();
        o.import = vec![Channel::Nav];
        o.import_from = "car2".into();
        assert!(matches!(o.check(), Err(BridgeError::Loop(Channel::Nav))));
        o.import = vec![Channel::Gnss];
        assert!(o.check().is_ok());
        o.import_from = String::new();
        assert!(matches!(o.check(), Err(BridgeError::NoImportFrom)));
        let mut o = opts();
        o.key_prefix = "car/*".into();
        let e = o.check().unwrap_err().to_string();
        assert!(e.contains("car/*"), "{e}");
        let mut o = opts();
        o.lease_ms = 10;
        assert!(matches!(o.check(), Err(BridgeError::Lease(10))));
    }

    #[test]
    fn endpoints_are_tcp_host_port() {
        for good in [
            "tcp/127.0.0.1:7447",
            "tcp/[::]:7447",
            "tcp/nav-computer:7447",
            "tcp/10.0.0.2:7447#iface=eth0",
        ] {
            assert!(check_endpoint(good).is_ok(), "{good}");
        }
        for bad in [
            "udp/127.0.0.1:7447",
            "127.0.0.1:7447",
            "tcp/host",
            "tcp/:7447",
            "tcp/h:99999",
        ] {
            let e = check_endpoint(bad).unwrap_err().to_string();
            assert!(e.contains(bad), "{e}");
        }
    }

    #[test]
    fn the_session_configuration_is_accepted() {
        let mut o = opts();
        o.connect = vec!["tcp/127.0.0.1:7448".into()];
        o.lease_ms = 1000;
        let c = session_config(&o).unwrap();
        let text = format!("{c}");
        assert!(text.contains("7448"), "{text}");
    }
}
