//! The live view: the bus channels of a running system served to Foxglove over the Foxglove
//! WebSocket protocol (the `foxglove` crate's server; subprotocol `foxglove.sdk.v1`, the
//! current name of `foxglove.websocket.v1`), so that Foxglove connected to `ws://ADDR` shows
//! live what it shows from a recording.
//!
//! It runs as its own process (`sextant-foxglove`, started by `sextant run --foxglove`), a
//! subscriber on the bus like any other: tokio and the WebSocket never run in the fusion
//! daemon. The bus's services overwrite the oldest sample of a subscriber that falls behind
//! (`msgs::ipc`: safe overflow), so neither this process nor a slow or vanishing client can
//! make a publisher wait; each client has its own bounded queue in the server, whose oldest
//! messages are dropped when it is slow.
//!
//! Channels, topics, schemas and JSON are those of the recording (`sextant_daemons::recorder`,
//! `sextant_daemons::foxglove`):
//! - one channel per bus channel (`imu`, `star_tracker`, `gnss`, `odometer`, `baro`, `truth`,
//!   `nav`, `status`), schema [`msgs::channel_schema`], the message as the recording holds it;
//! - the solution also as `nav/location_fix`, `nav/pose` and `tf`, the status as
//!   `status/plot`. The local NED frame of `nav/pose` and `tf` has its origin at the first
//!   solution this process received (the recording's at the first solution it recorded: the
//!   same point when both start with the run).
//!
//! Message times (the protocol's `logTime`, and the Foxglove `timestamp` fields) follow the
//! recording's convention: Unix ns of the message's time of validity, converted from its
//! header's GPS time through the leap-second table
//! ([`sextant_daemons::recorder::log_time_of`]). A message whose header has no time yet (the
//! status before the filter's first epoch) is stamped with the latest time of validity seen
//! or, before any, with the wall clock: a live view cannot hold messages back as the recorder
//! does. A message is encoded only when a client is subscribed to its channel, so unwatched
//! channels (the 200 Hz IMU) cost a receive and nothing more.

use foxglove::{Context, PartialMetadata, RawChannel, Schema, WebSocketServer};
use msgs::Record;
use msgs::ipc::Bus;
use sextant_daemons::foxglove as views;
use sextant_daemons::recorder::log_time_of;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// Errors of the live server.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// A Foxglove channel could not be created.
    #[error("foxglove channel {topic}: {source}")]
    Channel {
        /// Its topic.
        topic: String,
        /// Why.
        source: foxglove::FoxgloveError,
    },
    /// The WebSocket server could not listen on the address.
    #[error("cannot serve on {addr}: {source}")]
    Listen {
        /// The address.
        addr: SocketAddr,
        /// Why (address in use, not local, …).
        source: foxglove::FoxgloveError,
    },
    /// The server's tokio runtime could not be created.
    #[error("tokio runtime of the WebSocket server: {0}")]
    Runtime(std::io::Error),
    /// The bus could not be joined (node, subscriber or WaitSet), or the wait failed.
    #[error("bus {prefix:?}: {detail}")]
    Bus {
        /// The service-name prefix.
        prefix: String,
        /// What failed.
        detail: String,
    },
}

/// What the live server saw, for its exit log.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LiveCounters {
    /// Messages received from the bus.
    pub received: u64,
    /// Messages sent to the server (encoded for at least one subscribed client), views
    /// counted one each.
    pub logged: u64,
    /// Messages not sent because a float in them is not finite (JSON has no NaN; the
    /// recording diverts such a record to `fusion/non_finite_input`).
    pub non_finite: u64,
    /// Bus receive errors.
    pub receive_errors: u64,
}

/// The Foxglove channels of the live view and the state of their encoding.
pub struct LiveChannels {
    /// One channel per bus channel, in `msgs::Channel::ALL` order.
    bus: Vec<Arc<RawChannel>>,
    location_fix: Arc<RawChannel>,
    pose: Arc<RawChannel>,
    tf: Arc<RawChannel>,
    status_plot: Arc<RawChannel>,
    ned_origin: Option<views::NedOrigin>,
    /// The sensors' mounts of the frame tree.
    mounts: views::SensorMounts,
    /// Log time of the latest timed message, Unix ns.
    last_log_time: Option<u64>,
    buf: Vec<u8>,
    counters: LiveCounters,
}

fn json_channel(
    ctx: &Arc<Context>,
    topic: &str,
    schema_name: &str,
    schema: String,
) -> Result<Arc<RawChannel>, LiveError> {
    ctx.channel_builder(topic)
        .message_encoding("json")
        .schema(Schema::new(schema_name, "jsonschema", schema.into_bytes()))
        .build_raw()
        .map_err(|source| LiveError::Channel {
            topic: topic.into(),
            source,
        })
}

/// Unix time now, ns (the stamp of an untimed message before any time of validity).
pub fn unix_now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

impl LiveChannels {
    /// Create the channels in `ctx` (a server on `ctx` advertises them to every client); the
    /// frame tree draws the sensors at `mounts`.
    pub fn new(ctx: &Arc<Context>, mounts: views::SensorMounts) -> Result<Self, LiveError> {
        let bus = msgs::Channel::ALL
            .into_iter()
            .map(|ch| {
                let (name, schema) = msgs::channel_schema(ch);
                json_channel(ctx, ch.name(), name, schema)
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            bus,
            location_fix: json_channel(
                ctx,
                views::LOCATION_FIX_TOPIC,
                views::LOCATION_FIX_SCHEMA,
                views::location_fix_schema(),
            )?,
            pose: json_channel(
                ctx,
                views::POSE_TOPIC,
                views::POSE_SCHEMA,
                views::pose_in_frame_schema(),
            )?,
            tf: json_channel(
                ctx,
                views::TF_TOPIC,
                views::TF_SCHEMA,
                views::frame_transforms_schema(),
            )?,
            status_plot: json_channel(
                ctx,
                views::STATUS_PLOT_TOPIC,
                views::STATUS_PLOT_SCHEMA,
                views::status_plot_schema(),
            )?,
            ned_origin: None,
            mounts,
            last_log_time: None,
            buf: Vec::with_capacity(16 * 1024),
            counters: LiveCounters::default(),
        })
    }

    /// The counters so far.
    pub fn counters(&self) -> LiveCounters {
        self.counters
    }

    /// The log time of a message whose header holds GPS time `gps_ns` (see the module
    /// comment); `now_unix_ns` stamps an untimed message before any timed one.
    pub fn log_time(&mut self, gps_ns: i64, now_unix_ns: u64) -> u64 {
        match log_time_of(gps_ns) {
            Some(t) => {
                self.last_log_time = Some(t);
                t
            }
            None => self.last_log_time.unwrap_or(now_unix_ns),
        }
    }

    /// Log the JSON in `self.buf` on `channel` at `log_time`, unless it holds a non-finite
    /// float (serialized as `null`; our messages hold only numbers).
    fn log_buf(&mut self, channel: &RawChannel, log_time: u64) {
        if self.buf.windows(4).any(|w| w == b"null") {
            self.counters.non_finite += 1;
            return;
        }
        channel.log_with_meta(&self.buf, PartialMetadata::with_log_time(log_time));
        self.counters.logged += 1;
    }

    fn log_view<T: serde::Serialize>(&mut self, channel: &RawChannel, view: &T, log_time: u64) {
        self.buf.clear();
        if serde_json::to_writer(&mut self.buf, view).is_ok() {
            self.log_buf(channel, log_time);
        }
    }

    /// Publish one message from the bus on its channel and its views, encoding only for the
    /// channels a client is subscribed to.
    pub fn publish(&mut self, record: &Record, now_unix_ns: u64) {
        self.counters.received += 1;
        let t = self.log_time(record.time_ns(), now_unix_ns);
        let Some(ch) = record.channel() else {
            return;
        };
        let Some(idx) = msgs::Channel::ALL.iter().position(|c| *c == ch) else {
            return;
        };
        let channel = self.bus[idx].clone();
        if channel.has_sinks() && record.write_json(&mut self.buf).is_ok() {
            self.log_buf(&channel, t);
        }
        match record {
            Record::Nav(nav) => {
                let origin = *self
                    .ned_origin
                    .get_or_insert_with(|| views::NedOrigin::at(nav));
                let mounts = self.mounts;
                let (fix, pose, tf) = (
                    self.location_fix.clone(),
                    self.pose.clone(),
                    self.tf.clone(),
                );
                if fix.has_sinks() {
                    self.log_view(&fix, &views::location_fix(nav, t), t);
                }
                if pose.has_sinks() {
                    self.log_view(&pose, &views::pose_in_frame(nav, &origin, t), t);
                }
                if tf.has_sinks() {
                    self.log_view(&tf, &views::frame_transforms(nav, &origin, &mounts, t), t);
                }
            }
            Record::Status(st) => {
                let plot = self.status_plot.clone();
                if plot.has_sinks() {
                    self.log_view(&plot, &views::status_plot(st, t), t);
                }
            }
            _ => {}
        }
    }
}

/// Where and what to serve.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// Service-name prefix of the run whose channels are served.
    pub prefix: String,
    /// Address of the WebSocket server (port 0: any free port).
    pub listen: SocketAddr,
    /// Name of the iceoryx2 node.
    pub node_name: String,
    /// The sensors' mounts of the frame tree (the filter configuration's).
    pub mounts: views::SensorMounts,
}

/// Subscribers of every bus channel.
struct Subs {
    star: msgs::ipc::Sub<msgs::StarTrackerSample>,
    gnss: msgs::ipc::Sub<msgs::GnssSample>,
    odo: msgs::ipc::Sub<msgs::OdometerSample>,
    baro: msgs::ipc::Sub<msgs::BaroSample>,
    imu: msgs::ipc::Sub<msgs::ImuSample>,
    truth: msgs::ipc::Sub<msgs::TruthSample>,
    nav: msgs::ipc::Sub<msgs::NavSolution>,
    status: msgs::ipc::Sub<msgs::Status>,
}

fn drain<T: msgs::Message + Into<Record>>(
    sub: &msgs::ipc::Sub<T>,
    live: &mut LiveChannels,
    receive_errors: &mut u64,
) {
    sub.clear_events();
    loop {
        match sub.receive() {
            Ok(Some(m)) => live.publish(&m.into(), unix_now_ns()),
            Ok(None) => break,
            Err(e) => {
                *receive_errors += 1;
                tracing::warn!("{e}");
                break;
            }
        }
    }
}

/// Serve the channels of `opts.prefix` on `opts.listen` until `stop` is set; calls `ready`
/// with the address bound (the actual port when 0 was asked). Returns the counters. `ready` is
/// a trait object so that the server is compiled once, in this library, not again in each caller.
pub fn serve(
    opts: &ServeOptions,
    stop: &AtomicBool,
    ready: &mut dyn FnMut(SocketAddr),
) -> Result<LiveCounters, LiveError> {
    use iceoryx2::prelude::*;
    let bus_err = |detail: String| LiveError::Bus {
        prefix: opts.prefix.clone(),
        detail,
    };
    let ctx = Context::new();
    let mut live = LiveChannels::new(&ctx, opts.mounts)?;
    // One worker thread: the server only moves queued frames to sockets.
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("foxglove-ws")
        .enable_all()
        .build()
        .map_err(LiveError::Runtime)?;
    let server = rt
        .block_on(
            WebSocketServer::new()
                .name("sextant")
                .bind(opts.listen.ip().to_string(), opts.listen.port())
                .context(&ctx)
                .start(),
        )
        .map_err(|source| LiveError::Listen {
            addr: opts.listen,
            source,
        })?;
    ready(SocketAddr::new(opts.listen.ip(), server.port()));

    let bus = Bus::new(&opts.prefix, &opts.node_name).map_err(|e| bus_err(e.to_string()))?;
    let sub_err = |e: msgs::ipc::SubscriberError| bus_err(e.to_string());
    let subs = Subs {
        star: bus.subscriber().map_err(sub_err)?,
        gnss: bus.subscriber().map_err(sub_err)?,
        odo: bus.subscriber().map_err(sub_err)?,
        baro: bus.subscriber().map_err(sub_err)?,
        imu: bus.subscriber().map_err(sub_err)?,
        truth: bus.subscriber().map_err(sub_err)?,
        nav: bus.subscriber().map_err(sub_err)?,
        status: bus.subscriber().map_err(sub_err)?,
    };
    let ws = msgs::ipc::waitset().map_err(|e| bus_err(e.to_string()))?;
    let listeners = [
        subs.star.listener(),
        subs.gnss.listener(),
        subs.odo.listener(),
        subs.baro.listener(),
        subs.imu.listener(),
        subs.truth.listener(),
        subs.nav.listener(),
        subs.status.listener(),
    ];
    let mut guards = Vec::with_capacity(listeners.len());
    for l in listeners {
        guards.push(
            ws.attach_notification(l)
                .map_err(|e| bus_err(format!("{e:?}")))?,
        );
    }
    let mut receive_errors = 0;
    // Readiness and watchdog pings to `sextant run` (or systemd); the loop wakes at least every
    // 500 ms, so an idle bus does not look like a hung server.
    let mut service = msgs::sd_notify::Service::from_env();
    while !stop.load(Ordering::SeqCst) {
        service.ping();
        ws.wait_and_process_once_with_timeout(
            |_| CallbackProgression::Continue,
            Duration::from_millis(500),
        )
        .map_err(|e| bus_err(format!("wait: {e:?}")))?;
        // In `msgs::Channel` order, as the fusion daemon drains them.
        drain(&subs.star, &mut live, &mut receive_errors);
        drain(&subs.gnss, &mut live, &mut receive_errors);
        drain(&subs.odo, &mut live, &mut receive_errors);
        drain(&subs.baro, &mut live, &mut receive_errors);
        drain(&subs.imu, &mut live, &mut receive_errors);
        drain(&subs.truth, &mut live, &mut receive_errors);
        drain(&subs.nav, &mut live, &mut receive_errors);
        drain(&subs.status, &mut live, &mut receive_errors);
    }
    drop(guards);
    rt.block_on(server.stop().wait());
    let mut counters = live.counters();
    counters.receive_errors = receive_errors;
    Ok(counters)
}

#[cfg(test)]
mod tests {
    use super::*;
    use msgs::{NavSolution, Status};

    /// With nobody subscribed nothing is encoded; the log time of a timed message is its GPS
    /// time of validity in Unix ns, and an untimed one takes the latest.
    #[test]
    fn log_times_follow_the_recording_convention() {
        let ctx = Context::new();
        let mut live = LiveChannels::new(&ctx, views::SensorMounts::default()).unwrap();
        let untimed = Record::Status(Box::default());
        // Before any timed message: the wall clock given.
        assert_eq!(live.log_time(untimed.time_ns(), 42), 42);
        let mut nav = NavSolution::default();
        // 2025-03-20T21:00:00 UTC in GPS ns: Unix 1 742 504 400 s + 18 leap s − GPS epoch
        // 315 964 800 s (written out, independent of the conversion under test).
        nav.header.time_ns = (1_742_504_400 + 18 - 315_964_800) * 1_000_000_000;
        live.publish(&Record::Nav(nav), 7);
        let t = 1_742_504_400_000_000_000;
        assert_eq!(live.last_log_time, Some(t));
        assert_eq!(live.log_time(0, 7), t);
        let c = live.counters();
        assert_eq!((c.received, c.logged), (1, 0));
    }

    /// The channels carry the recording's schemas, and what they send validates against them.
    #[test]
    fn channels_carry_the_recording_schemas() {
        let ctx = Context::new();
        let live = LiveChannels::new(&ctx, views::SensorMounts::default()).unwrap();
        for (ch, raw) in msgs::Channel::ALL.iter().zip(&live.bus) {
            let (name, schema) = msgs::channel_schema(*ch);
            assert_eq!(raw.topic(), ch.name());
            assert_eq!(raw.message_encoding(), "json");
            let s = raw.schema().unwrap();
            assert_eq!((s.name.as_str(), s.encoding.as_str()), (name, "jsonschema"));
            assert_eq!(s.data.as_ref(), schema.as_bytes());
        }
        let nav = NavSolution {
            q_ned_body: [1.0, 0.0, 0.0, 0.0],
            ..Default::default()
        };
        let origin = views::NedOrigin::at(&nav);
        for (raw, msg) in [
            (
                &live.location_fix,
                serde_json::to_value(views::location_fix(&nav, 5)).unwrap(),
            ),
            (
                &live.pose,
                serde_json::to_value(views::pose_in_frame(&nav, &origin, 5)).unwrap(),
            ),
            (
                &live.tf,
                serde_json::to_value(views::frame_transforms(
                    &nav,
                    &origin,
                    &views::SensorMounts::default(),
                    5,
                ))
                .unwrap(),
            ),
            (
                &live.status_plot,
                serde_json::to_value(views::status_plot(&Status::default(), 5)).unwrap(),
            ),
        ] {
            let schema: serde_json::Value =
                serde_json::from_slice(&raw.schema().unwrap().data).unwrap();
            let v = jsonschema::validator_for(&schema).unwrap();
            assert!(v.is_valid(&msg), "{}: {msg}", raw.topic());
        }
    }
}
