//! Criterion bench of the navigator on the default run's own inputs: the vehicle scenario's
//! simulated IMU (200 Hz), star tracker, GNSS, odometer and baro, the shipped filter
//! configuration (every aiding, the car's latencies: late samples rewind the filter), fed
//! through the same input path as the daemon and `replay --offline`. Each iteration starts
//! from the navigator as it is right after the alignment and runs 60 s of the drive; the
//! throughput is printed in IMU samples per second ("elements"). Two ways of taking the
//! solutions: one formed for every IMU sample, as the fusion daemon publishes them
//! (`every_aiding_60s_imu_samples`), and only those `replay --offline` keeps, at the shipped
//! recorder's solution rate (`every_aiding_60s_recorded_solutions`: the offline filter core).

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use drivers_sim::offline::{OfflineSim, feed};
use drivers_sim::scenario::Scenario;
use fusion::navigator::{Input, Navigator};
use msgs::{Channel, Record};
use sextant_lab::recorder::{RateGate, log_time_of};
use std::hint::black_box;
use std::path::Path;

/// Navigation time fed per iteration after the alignment, s.
const NAV_S: f64 = 60.0;

fn bench(c: &mut Criterion) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let cfg = sextant_lab::config::load(&root.join("config/sextant.toml")).expect("config");
    let scn = Scenario::load(&root.join("config/scenarios/vehicle.toml")).expect("scenario");
    let alignment_s = cfg.navigator.alignment_s;
    let msgs: Vec<Record> = OfflineSim::with_channels(&scn, &Channel::SENSORS)
        .with_duration_s(alignment_s + 5.0 + NAV_S)
        .collect();
    let mut aligned = Navigator::new(cfg.navigator.clone()).expect("navigator");
    let mut k = 0;
    while !aligned.is_navigating() {
        let _ = feed(&mut aligned, &msgs[k]);
        k += 1;
    }
    let drive = &msgs[k..];
    let imu = drive.iter().filter(|m| matches!(m, Record::Imu(_))).count();
    let mut g = c.benchmark_group("navigator_vehicle");
    g.throughput(Throughput::Elements(imu as u64));
    g.sample_size(10);
    g.bench_function("every_aiding_60s_imu_samples", |b| {
        b.iter_batched_ref(
            || aligned.clone(),
            |nav| {
                for m in drive {
                    let _ = black_box(feed(nav, m));
                }
            },
            BatchSize::LargeInput,
        )
    });
    // The recorder keeps one solution per interval of time of validity: the others are not
    // formed (`Navigator::push_deferred`), as in `replay --offline`.
    let solution_rate_hz = cfg.system.recorder.solution_rate_hz;
    g.bench_function("every_aiding_60s_recorded_solutions", |b| {
        b.iter_batched_ref(
            || (aligned.clone(), RateGate::new(solution_rate_hz)),
            |(nav, kept)| {
                for m in drive {
                    let Some(input) = Input::from_record(m) else {
                        continue;
                    };
                    if let (Ok(true), Input::Imu(s)) = (nav.push_deferred(input), input)
                        && kept.admit(log_time_of(s.header.time_ns).unwrap_or(0))
                    {
                        black_box(nav.solution());
                    }
                }
            },
            BatchSize::LargeInput,
        )
    });
    g.finish();
    let mut nav = aligned.clone();
    for m in drive {
        let _ = feed(&mut nav, m);
    }
    let d = nav.diagnostics();
    println!(
        "{imu} IMU samples after the alignment; late samples rewound the filter {} times and \
         replayed {} IMU steps again",
        d.rewinds, d.replayed_imu_steps
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
