//! A driver written against iceoryx2's own `ipc` service (what a third-party driver uses) and a
//! Sextant port on `msgs::ipc_service::Service` meet on the same shared-memory service: the
//! service type changes only how a process keeps its per-sample state, not the transport.

use iceoryx2::prelude::*;
use sextant_msgs::ipc::Bus;
use sextant_msgs::{Channel, ImuSample};
use std::time::Duration;

#[test]
fn a_plain_iceoryx2_publisher_reaches_a_sextant_subscriber_and_back() {
    let prefix = format!("sextant-test-interop-{}", std::process::id());
    let bus = Bus::new(&prefix, "interop-sextant").expect("bus");
    let sub = bus.subscriber::<ImuSample>().expect("sextant subscriber");
    let mut sextant_pub = bus.publisher::<ImuSample>().expect("sextant publisher");

    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .expect("plain node");
    let name: ServiceName = Channel::Imu
        .service_name(&prefix)
        .as_str()
        .try_into()
        .expect("name");
    let pubsub = node
        .service_builder(&name)
        .publish_subscribe::<ImuSample>()
        .open()
        .expect("the plain node opens Sextant's service");
    let event = node
        .service_builder(&name)
        .event()
        .open()
        .expect("and its event service");
    let publisher = pubsub
        .publisher_builder()
        .create()
        .expect("plain publisher");
    let notifier = event.notifier_builder().create().expect("plain notifier");

    for k in 0..100 {
        let mut s = ImuSample::default();
        s.header.seq = k;
        s.dt_s = 0.005;
        publisher.send_copy(s).expect("plain send");
        notifier.notify().expect("plain notify");
    }
    sub.wait_for_wake_up(Duration::from_secs(5)).expect("woken");
    let mut got = Vec::new();
    while let Some(s) = sub.receive().expect("receive") {
        got.push(s.header.seq);
    }
    assert_eq!(
        got,
        (0..100).collect::<Vec<u64>>(),
        "every sample, in order"
    );

    // And the other way: Sextant's publisher (pooled per-sample state) to a plain subscriber
    // (created now: the service keeps no history, so it sees only what follows).
    let plain_sub = pubsub
        .subscriber_builder()
        .create()
        .expect("plain subscriber");
    let s = ImuSample {
        dt_s: 0.01,
        ..Default::default()
    };
    for _ in 0..100 {
        sextant_pub.send(s).expect("sextant send");
    }
    let mut seqs = Vec::new();
    while let Some(sample) = plain_sub.receive().expect("plain receive") {
        seqs.push(sample.header.seq);
        assert_eq!(sample.dt_s, 0.01);
    }
    assert_eq!(seqs, (1..=100).collect::<Vec<u64>>());
}
