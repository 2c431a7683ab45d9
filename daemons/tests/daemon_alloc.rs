//! Does the fusion daemon's loop allocate per sample? The navigator is proven allocation-free
//! per IMU step (fusion/tests/no_alloc_filter.rs); this measures what the daemon adds around it
//! with a counting allocator that counts per thread — the daemon's own thread, not the
//! recorder's writer thread (which serialises records to JSON and may allocate).
//!
//! Finding, per mechanism, each measured on its own in
//! `each_step_of_the_loop_costs_what_it_costs` and together in `daemon_loop_allocations`:
//! - publishing a message (`msgs::ipc::Pub::send_raw`): none. Inside iceoryx2 0.10 every loan
//!   (`Publisher::loan_uninit`, which `send_copy` goes through too) creates a reference-counted
//!   shared state through the service type's thread-safety policy; with iceoryx2's `ipc`
//!   service that is an `Rc::new`, one heap allocation per message. Sextant's service type
//!   (`msgs::ipc_service`) takes those blocks from a per-thread pool. Before that, 1 per
//!   message (and 3 before the error contexts were formatted only on failure). The daemon
//!   publishes one solution per IMU step (decimation 1).
//! - each wake-up: none. The loop waits on the IMU listener itself (`Sub::wait_for_wake_up`, a
//!   receive with a timeout on its socket). It used to wait on a WaitSet over every channel,
//!   whose waits allocate twice each inside iceoryx2 0.10 (`WaitSet::wait_and_process_once*`
//!   collects the triggered file descriptors into a `vec![]` and builds a second `Vec` in
//!   `handle_all_attachments`): 3.0–3.4 allocations per IMU step then, 1.05 with the wait on
//!   the listener, 0.05 with the pooled shared state (the GNSS samples' and statuses' boxes).
//! - `Record::Gnss(Box::new(..))` and `Record::Status(Box::new(..))`: 1 per GNSS sample / status.
//! - receiving a sample, building the other records, the recorder hand-off (`try_send` into the
//!   bounded channel): none.
//!
//! `SEXTANT_ALLOC_TRACE=1 cargo test --release -p sextant-daemons --test daemon_alloc --
//! --nocapture` prints the allocation sites of the loop (call stacks of a random sample).

use msgs::ipc::Bus;
use msgs::{
    BaroSample, GnssSample, ImuSample, MAX_SENSORS, NavSolution, OdometerSample, SensorHealth,
    StarTrackerSample, TruthSample,
};
use sextant_daemons::config::SystemConfig;
use sextant_daemons::daemon::{DaemonOptions, NavEngine, run};
use sextant_daemons::recorder::{Record, Recorder, RecorderOptions};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

struct Counting;

thread_local! {
    /// Set on the measured thread only.
    static TRACKED: Cell<bool> = const { Cell::new(false) };
    /// Allocations of this thread since it was tracked.
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

/// Allocations of the calling thread so far (0 unless it is tracked).
fn allocations() -> u64 {
    ALLOCATIONS.try_with(Cell::get).unwrap_or(0)
}

fn track_this_thread() {
    TRACKED.with(|t| t.set(true));
}

fn note() {
    // The tracer's own allocations are not the daemon's.
    let in_trace = IN_TRACE.try_with(Cell::get).unwrap_or(true);
    if !in_trace && TRACKED.try_with(Cell::get).unwrap_or(false) {
        let _ = ALLOCATIONS.try_with(|a| a.set(a.get() + 1));
        if TRACE.load(Ordering::SeqCst) {
            // One in 8 at random (a fixed stride would alias with the loop's period).
            let mut x = RNG.load(Ordering::Relaxed);
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            RNG.store(x, Ordering::Relaxed);
            if x.is_multiple_of(8) {
                trace();
            }
        }
    }
}

/// `SEXTANT_ALLOC_TRACE=1`: where the daemon allocates (one allocation in 8 at random in the window,
/// its call stack reduced to the project's and iceoryx2's frames).
static TRACE: AtomicBool = AtomicBool::new(false);
static RNG: AtomicU64 = AtomicU64::new(0x2545_f491_4f6c_dd1d);
static SITES: Mutex<Vec<String>> = Mutex::new(Vec::new());

thread_local! {
    static IN_TRACE: Cell<bool> = const { Cell::new(false) };
}

fn trace() {
    if IN_TRACE.with(|t| t.replace(true)) {
        return;
    }
    let bt = std::backtrace::Backtrace::force_capture().to_string();
    let mut frames = Vec::new();
    let mut lines = bt.lines();
    while let Some(l) = lines.next() {
        let l = l.trim();
        if let Some((_, f)) = l.split_once(": ") {
            let at = lines.next().unwrap_or("").trim().to_string();
            if (at.contains("/work/") || at.contains("iceoryx2")) && !at.contains("daemon_alloc") {
                let f: String = f.chars().take(60).collect();
                frames.push(format!("{f} {at}"));
            }
        }
    }
    if let Ok(mut s) = SITES.lock() {
        frames.truncate(5);
        s.push(frames.join("\n    <- "));
    }
    IN_TRACE.with(|t| t.set(false));
}

// SAFETY: forwards to the system allocator unchanged; only counts calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// What the engine saw inside the measured window, and the daemon thread's allocation count at
/// its first and last engine call there.
#[derive(Default)]
struct Tally {
    /// Counting on.
    on: AtomicBool,
    /// Engine calls per sample kind: IMU, star tracker, GNSS, odometer, baro.
    calls: [AtomicU64; 5],
    first: AtomicU64,
    last: AtomicU64,
}

impl Tally {
    fn note(&self, kind: usize) {
        if !self.on.load(Ordering::SeqCst) {
            return;
        }
        let now = allocations();
        if self.calls.iter().all(|c| c.load(Ordering::SeqCst) == 0) {
            self.first.store(now, Ordering::SeqCst);
        }
        self.last.store(now, Ordering::SeqCst);
        self.calls[kind].fetch_add(1, Ordering::SeqCst);
    }
    fn calls(&self, kind: usize) -> u64 {
        self.calls[kind].load(Ordering::SeqCst)
    }
}

struct Probe(Arc<Tally>);

impl NavEngine for Probe {
    fn push_imu(&mut self, s: &ImuSample) -> Result<Option<NavSolution>, fusion::Rejection> {
        self.0.note(0);
        let mut n = NavSolution::default();
        n.header.time_ns = s.header.time_ns;
        n.q_ned_body = [1.0, 0.0, 0.0, 0.0];
        Ok(Some(n))
    }
    fn push_star_tracker(&mut self, _: &StarTrackerSample) -> Result<(), fusion::Rejection> {
        self.0.note(1);
        Ok(())
    }
    fn push_gnss(&mut self, _: &GnssSample) -> Result<(), fusion::Rejection> {
        self.0.note(2);
        Ok(())
    }
    fn push_odometer(&mut self, _: &OdometerSample) -> Result<(), fusion::Rejection> {
        self.0.note(3);
        Ok(())
    }
    fn push_baro(&mut self, _: &BaroSample) -> Result<(), fusion::Rejection> {
        self.0.note(4);
        Ok(())
    }
    fn set_sensor_alive(&mut self, _: usize, _: bool) {}
    fn health(&self) -> [SensorHealth; MAX_SENSORS] {
        Default::default()
    }
    fn mode(&self) -> u32 {
        msgs::NavMode::GnssInertial as u32
    }
}

/// Allocations per published message (`Pub::send_raw`): none (iceoryx2's per-loan shared
/// state comes from `msgs::ipc_service`'s pool; its error contexts are formatted on failure
/// only).
const PER_SEND: u64 = 0;
/// Allocations per wake-up of the loop's wait (`Sub::wait_for_wake_up`).
const PER_WAKEUP: u64 = 0;

/// Each step of the loop measured on its own, on this thread.
#[test]
fn each_step_of_the_loop_costs_what_it_costs() {
    let prefix = format!("sextant-test-alloc-parts-{}", std::process::id());
    let bus = Bus::new(&prefix, "alloc-parts").expect("bus");
    let mut nav_pub = bus.publisher::<NavSolution>().expect("pub");
    let nav_sub = bus.subscriber::<NavSolution>().expect("sub");
    let dir = std::env::temp_dir().join(&prefix);
    std::fs::create_dir_all(&dir).expect("temp dir");
    let rec = Recorder::start(
        &dir.join("r.mcap"),
        &RecorderOptions {
            queue_capacity: 4096,
            chunk_size_bytes: 1 << 20,
            flush_interval: Duration::from_secs(1),
            metadata: Vec::new(),
            ..Default::default()
        },
    )
    .expect("recorder");
    track_this_thread();
    let n = 200u64;
    let cost = |f: &mut dyn FnMut()| {
        f(); // warm-up (first-use allocations)
        let a0 = allocations();
        for _ in 0..n {
            f();
        }
        allocations() - a0
    };
    let sol = NavSolution::default();
    let send = cost(&mut || nav_pub.send_raw(sol).expect("send"));
    let mut received = 0;
    let receive = cost(&mut || {
        while let Ok(Some(_)) = nav_sub.receive() {
            received += 1;
        }
    });
    let wake = cost(&mut || {
        nav_pub.send_raw(sol).expect("send");
        nav_sub
            .wait_for_wake_up(Duration::from_secs(1))
            .expect("wait");
        while let Ok(Some(_)) = nav_sub.receive() {}
    }) - (n * PER_SEND);
    let record_imu = cost(&mut || {
        rec.record(Record::Imu(ImuSample::default()), 1);
    });
    let record_gnss = cost(&mut || {
        rec.record(Record::Gnss(Box::default()), 1);
    });
    TRACKED.with(|t| t.set(false));
    let stats = rec.finish().expect("finish");
    let _ = std::fs::remove_dir_all(&dir);
    eprintln!(
        "allocations per call: send {}, receive {}, wake-up {}, record IMU {}, record GNSS {}",
        send as f64 / n as f64,
        receive as f64 / n as f64,
        wake as f64 / n as f64,
        record_imu as f64 / n as f64,
        record_gnss as f64 / n as f64
    );
    assert!(received > 0);
    assert_eq!(stats.dropped, 0);
    assert_eq!(send, PER_SEND * n, "Pub::send_raw");
    assert_eq!(receive, 0, "Sub::receive");
    assert_eq!(wake, PER_WAKEUP * n, "Sub::wait_for_wake_up");
    assert_eq!(record_imu, 0, "Recorder::record of an unboxed record");
    assert_eq!(record_gnss, n, "Record::Gnss boxes its sample");
}

#[test]
fn daemon_loop_allocations() {
    let prefix = format!("sextant-test-alloc-{}", std::process::id());
    let dir = std::env::temp_dir().join(&prefix);
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = std::path::Path::new("sextant.toml");
    let mut system = SystemConfig::parse(include_str!("../../config/sextant.toml"), path)
        .expect("config/sextant.toml parses");
    // Status once a second (the default); generous deadlines so that no sensor goes dead
    // (and logs) inside the measured window.
    system.fusion.status_period_s = 1.0;
    system.validate(path).expect("valid");
    let opts = DaemonOptions {
        prefix: prefix.clone(),
        out: dir.join("recording.mcap"),
        speed: 1.0,
        system,
        node_name: "alloc-fusion".into(),
        metadata: Vec::new(),
        checkpoint: None,
    };
    let tally = Arc::new(Tally::default());
    let engine = Probe(tally.clone());
    let stop = Arc::new(AtomicBool::new(false));
    let stop2 = stop.clone();
    let report = Arc::new(Mutex::new(None));
    let report2 = report.clone();
    let daemon = std::thread::spawn(move || {
        track_this_thread();
        let r = run(engine, &opts, &stop2);
        *report2.lock().unwrap_or_else(|e| e.into_inner()) = Some(r.map(|r| r.recorder.dropped));
    });
    std::thread::sleep(Duration::from_millis(500));
    let bus = Bus::new(&prefix, "alloc-drivers").expect("bus");
    let mut imu = bus.publisher::<ImuSample>().expect("imu pub");
    let mut star = bus.publisher::<StarTrackerSample>().expect("star pub");
    let mut gnss = bus.publisher::<GnssSample>().expect("gnss pub");
    let mut odo = bus.publisher::<OdometerSample>().expect("odo pub");
    let mut baro = bus.publisher::<BaroSample>().expect("baro pub");
    let mut truth = bus.publisher::<TruthSample>().expect("truth pub");
    let t0 = 1_400_000_000_000_000_000i64;
    // 200 Hz IMU with the default rates of the aiding (star tracker 10 Hz, GNSS 10 Hz,
    // odometer 100 Hz, baro 50 Hz), sent at 1 kHz wall (5× real time) for 4 s: the first
    // second warms up (every sensor alive, first chunk of the recorder), 3 s are measured.
    let n = 4000i64;
    for k in 0..n {
        if k == 1000 {
            // Let the daemon drain the warm-up, then count from its next engine call.
            std::thread::sleep(Duration::from_millis(50));
            tally.on.store(true, Ordering::SeqCst);
            TRACE.store(
                std::env::var_os("SEXTANT_ALLOC_TRACE").is_some(),
                Ordering::SeqCst,
            );
        }
        let t = t0 + k * 5_000_000;
        let mut s = ImuSample::default();
        s.header.time_ns = t;
        s.dt_s = 0.005;
        let mut tr = TruthSample::default();
        tr.header.time_ns = t;
        tr.q_ned_body = [1.0, 0.0, 0.0, 0.0];
        if k % 20 == 0 {
            let mut m = StarTrackerSample::default();
            m.header.time_ns = t;
            star.send(m).expect("send");
            let mut g = GnssSample::default();
            g.header.time_ns = t;
            gnss.send(g).expect("send");
        }
        if k % 2 == 0 {
            let mut m = OdometerSample::default();
            m.header.time_ns = t;
            odo.send(m).expect("send");
        }
        if k % 4 == 0 {
            let mut m = BaroSample::default();
            m.header.time_ns = t;
            baro.send(m).expect("send");
        }
        imu.send(s).expect("send");
        truth.send(tr).expect("send");
        std::thread::sleep(Duration::from_millis(1));
    }
    std::thread::sleep(Duration::from_millis(100));
    tally.on.store(false, Ordering::SeqCst);
    TRACE.store(false, Ordering::SeqCst);
    stop.store(true, Ordering::SeqCst);
    daemon.join().expect("daemon thread");
    let dropped = report
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .take()
        .expect("daemon ran")
        .expect("daemon ok");
    assert_eq!(dropped, 0, "records dropped");
    let _ = std::fs::remove_dir_all(&dir);

    if let Ok(sites) = SITES.lock() {
        let mut counts: std::collections::BTreeMap<&str, u64> = Default::default();
        for site in sites.iter() {
            *counts.entry(site.as_str()).or_default() += 1;
        }
        let mut v: Vec<_> = counts.into_iter().collect();
        v.sort_by_key(|(_, n)| std::cmp::Reverse(*n));
        for (site, n) in v.iter().take(12) {
            eprintln!("{n} × (one in 8 sampled)\n    {site}");
        }
    }
    // Between the first and the last engine call of the window: every IMU step published
    // one solution (PER_SEND each); the wake-ups (at most one per IMU sample, and the
    // timeouts) allocate nothing (PER_WAKEUP); every GNSS sample was boxed; at most 4
    // statuses (1 Hz over ≈ 3 s: a box and a send each).
    let imu_steps = tally.calls(0);
    let gnss_n = tally.calls(2);
    let total = tally.last.load(Ordering::SeqCst) - tally.first.load(Ordering::SeqCst);
    let lower = PER_SEND * (imu_steps - 1) + gnss_n - 1;
    let upper = (PER_SEND + PER_WAKEUP) * imu_steps + gnss_n + 4 * (1 + PER_SEND);
    eprintln!(
        "daemon loop: {total} allocations over {imu_steps} IMU steps = {:.2} per step \
         (bounds from the parts: {lower} ≤ n ≤ {upper})",
        total as f64 / imu_steps as f64
    );
    assert!(imu_steps >= 2900, "{imu_steps} IMU steps measured");
    assert!(
        (lower..=upper).contains(&total),
        "{total} not in [{lower}, {upper}]"
    );
}

/// The daemon's checkpoint hand-off (`CheckpointWriter::buffer`, fill, `submit`) allocates
/// nothing on the daemon's thread once two snapshots have gone round: the writer thread hands
/// each written snapshot back, covariance storage and all. (The navigator's own
/// `snapshot_into` is proven allocation-free in fusion's `no_alloc_filter`.)
#[test]
fn checkpoint_hand_off_allocates_nothing() {
    use sextant_daemons::checkpoint::{CheckpointWriter, read};
    let dir = std::env::temp_dir().join(format!("sextant-test-alloc-ckpt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("navigator.checkpoint");
    let w = CheckpointWriter::start(path.clone()).expect("writer");
    let nx = fusion::ekf::NX;
    // What the daemon does at each checkpoint, with the navigator's fill done by hand.
    let round = |k: i64| {
        let mut s = w.buffer();
        s.gps_time_ns = k;
        s.q_e_b = [1.0, 0.0, 0.0, 0.0];
        s.covariance.clear();
        s.covariance
            .extend((0..nx * nx).map(|i| if i % (nx + 1) == 0 { 1.0 } else { 0.0 }));
        w.submit(s);
        // Wait until it is written, as a checkpoint interval (1 s) would.
        let t0 = std::time::Instant::now();
        while w.stats().written + w.stats().failed < k as u64 {
            assert!(
                t0.elapsed() < Duration::from_secs(10),
                "checkpoint not written"
            );
            std::thread::sleep(Duration::from_millis(1));
        }
    };
    track_this_thread();
    round(1);
    round(2);
    let a0 = allocations();
    for k in 3..=22 {
        round(k);
    }
    let used = allocations() - a0;
    assert_eq!(
        used, 0,
        "20 checkpoints allocated {used} times on the daemon's thread"
    );
    let stats = w.finish();
    assert_eq!((stats.written, stats.failed), (22, 0));
    let back = read(&path).expect("readable").expect("written");
    assert_eq!(back.gps_time_ns, 22);
    let _ = std::fs::remove_dir_all(&dir);
}
