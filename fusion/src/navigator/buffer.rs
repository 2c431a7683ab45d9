//! The delayed-fusion buffers (module docs of [`super`], "Delayed fusion"): time-ordered,
//! fixed-capacity queues of the aiding samples waiting for (or already past) their time of
//! validity, and the rings of validated IMU steps and checkpoints a replay starts from.
//! Nothing here allocates after construction.

use super::*;

/// Time-ordered ring buffer of fixed capacity (no allocation).
#[derive(Debug, Clone)]
pub(super) struct TimeQueue<T: Copy + Default, const CAP: usize> {
    /// (time of validity, value, already counted in the health counters).
    pub(super) buf: [(GpsTime, T, bool); CAP],
    pub(super) head: usize,
    pub(super) len: usize,
}

impl<T: Copy + Default, const CAP: usize> TimeQueue<T, CAP> {
    pub(super) fn new() -> Self {
        Self {
            buf: [(GpsTime::EPOCH, T::default(), false); CAP],
            head: 0,
            len: 0,
        }
    }
    pub(super) fn slot(&self, i: usize) -> usize {
        (self.head + i) % CAP
    }
    /// Insert keeping time order; when full, the oldest entry is evicted and returned.
    pub(super) fn insert(&mut self, t: GpsTime, v: T) -> Option<(GpsTime, T, bool)> {
        self.insert_flagged(t, v, false)
    }
    /// Insert with the "already counted" flag (samples re-queued for a replay).
    pub(super) fn insert_flagged(
        &mut self,
        t: GpsTime,
        v: T,
        counted: bool,
    ) -> Option<(GpsTime, T, bool)> {
        let evicted = if self.len == CAP {
            self.pop_oldest()
        } else {
            None
        };
        let mut i = self.len;
        self.len += 1;
        while i > 0 && self.buf[self.slot(i - 1)].0 > t {
            let (a, b) = (self.slot(i), self.slot(i - 1));
            self.buf[a] = self.buf[b];
            i -= 1;
        }
        let s = self.slot(i);
        self.buf[s] = (t, v, counted);
        evicted
    }
    /// Remove and return the newest entry if its time is > `t`.
    pub(super) fn pop_newer(&mut self, t: GpsTime) -> Option<(GpsTime, T, bool)> {
        if self.len > 0 {
            let s = self.slot(self.len - 1);
            if self.buf[s].0 > t {
                self.len -= 1;
                return Some(self.buf[s]);
            }
        }
        None
    }
    /// Whether the oldest entry's time is ≤ `t` (an entry [`Self::pop_due`] would return).
    pub(super) fn next_due(&self, t: GpsTime) -> bool {
        self.len > 0 && self.buf[self.head].0 <= t
    }
    /// Remove and return the oldest entry if its time is ≤ `t`.
    pub(super) fn pop_due(&mut self, t: GpsTime) -> Option<(GpsTime, T, bool)> {
        if self.len > 0 && self.buf[self.head].0 <= t {
            self.pop_oldest()
        } else {
            None
        }
    }
    /// Remove and return the oldest entry (None when empty).
    fn pop_oldest(&mut self) -> Option<(GpsTime, T, bool)> {
        if self.len == 0 {
            return None;
        }
        let e = self.buf[self.head];
        self.head = (self.head + 1) % CAP;
        self.len -= 1;
        Some(e)
    }
    pub(super) fn clear(&mut self) {
        self.len = 0;
    }
}

/// One navigating IMU step as logged for replay (validated, channels already combined).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct ImuLogEntry {
    /// Time of validity of the step's end.
    pub(super) t: GpsTime,
    /// Time of validity of the step before (None for the first after alignment).
    pub(super) prev_t: Option<GpsTime>,
    pub(super) dth: Vector3<f64>,
    pub(super) dv: Vector3<f64>,
    pub(super) dt_s: f64,
}

/// Fixed-capacity ring (allocated once at construction, never again).
#[derive(Debug, Clone)]
pub(super) struct Ring<T: Clone> {
    pub(super) buf: Vec<T>,
    pub(super) head: usize,
    pub(super) len: usize,
}

impl<T: Clone> Ring<T> {
    pub(super) fn new(cap: usize, fill: T) -> Self {
        Self {
            buf: vec![fill; cap],
            head: 0,
            len: 0,
        }
    }
    pub(super) fn get(&self, i: usize) -> &T {
        &self.buf[self.slot(i)]
    }
    /// Index in `buf` of entry `i` (`i < len ≤ cap`, `head < cap`: one wrap at most, no
    /// division).
    fn slot(&self, i: usize) -> usize {
        let k = self.head + i;
        if k >= self.buf.len() {
            k - self.buf.len()
        } else {
            k
        }
    }
    /// Moves the head one entry on (the oldest entry evicted).
    fn advance_head(&mut self) {
        self.head += 1;
        if self.head == self.buf.len() {
            self.head = 0;
        }
    }
    /// Append, evicting the oldest entry when full.
    pub(super) fn push(&mut self, v: T) {
        *self.push_slot() = v;
    }
    /// The slot the next entry goes to, appended (evicting the oldest entry when full) for
    /// the caller to overwrite in place: a large entry is written once, not built and moved.
    pub(super) fn push_slot(&mut self) -> &mut T {
        let i = if self.len == self.buf.len() {
            // Full: the new entry takes the oldest one's slot.
            let i = self.head;
            self.advance_head();
            i
        } else {
            self.len += 1;
            self.slot(self.len - 1)
        };
        &mut self.buf[i]
    }
    pub(super) fn truncate(&mut self, len: usize) {
        self.len = self.len.min(len);
    }
    pub(super) fn clear(&mut self) {
        self.len = 0;
    }
}

/// Checkpoints are taken at this period of IMU time (20 ms). A late sample rewinds to the
/// checkpoint before its time of validity and replays the IMU steps since: a sensor that is
/// always late by its latency (the odometer's 10 ms at 20 Hz, a receiver's 50 ms) rewinds at
/// every sample, so the period bounds the work repeated each time (half a period on average
/// beyond the latency itself), unless its epoch has a checkpoint before its updates
/// ([`EPOCH_CHECKPOINT_SPACING`]). A checkpoint is one copy of the navigation core (≈ 10 kB).
pub(super) const CHECKPOINT_PERIOD: Duration = Duration::from_ns(20_000_000);

/// At an epoch where aiding is due or the covariance has just been propagated, the state
/// before its updates is checkpointed too when the last checkpoint is at least this old (half
/// the period): the ring then holds at most two checkpoints per period
/// ([`NavigatorConfig::checkpoint_capacity`]). With the car's sensors the odometer's samples
/// (10 ms late) have their epoch's covariance propagation checkpointed: its rewinds neither
/// repeat that propagation nor replay the steps before the epoch.
pub(super) const EPOCH_CHECKPOINT_SPACING: Duration = Duration::from_ns(10_000_000);

/// Largest delayed-fusion IMU log, steps (≈ 5 MB; 2 kHz with the 2 s window needs 4 082).
pub(super) const IMU_LOG_MAX_CAP: usize = 65_536;

pub(super) const GNSS_CAP: usize = 32;

/// Late samples held per sensor until the next IMU step's solution is formed
/// ([`hold_late`]); a sensor late more often than this between two IMU samples has its oldest
/// one queued at once.
pub(super) const INBOX_CAP: usize = 8;

/// When an aiding sample arrives relative to the inertial solution ([`Navigator::arrival`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Arrival {
    /// Before its time of validity is reached: queued, fused in the IMU step that reaches it.
    InTime,
    /// After the solution passed its time of validity: held out of the next IMU step
    /// ([`hold_late`]), fused by a rewind once that step's solution is formed.
    Late,
    /// Older than the delayed-fusion window: dropped.
    TooLate,
}

/// Queue an aiding sample (`ts`, `v`) as its `arrival` asks: into `q`, held in `inbox`, or
/// not at all. Returns the samples dropped (the sample itself when too late, or the oldest
/// queued one evicted to make room), for the sensor's `dropped_late`.
pub(super) fn enqueue<T: Copy + Default, const Q: usize>(
    q: &mut TimeQueue<T, Q>,
    inbox: &mut TimeQueue<T, INBOX_CAP>,
    rewind_to: &mut Option<GpsTime>,
    arrival: Arrival,
    ts: GpsTime,
    v: T,
) -> u64 {
    match arrival {
        Arrival::TooLate => 1,
        Arrival::Late => hold_late(inbox, q, rewind_to, ts, v),
        Arrival::InTime => u64::from(q.insert(ts, v).is_some()),
    }
}

/// Hold the late sample (`ts`, `v`) in `inbox`, out of the step about to be formed. When the
/// inbox is full its oldest sample goes to `q` at once, its rewind due (`rewind_to`). Returns
/// the queue entries evicted to make room (counted as dropped by the caller).
fn hold_late<T: Copy + Default, const Q: usize>(
    inbox: &mut TimeQueue<T, INBOX_CAP>,
    q: &mut TimeQueue<T, Q>,
    rewind_to: &mut Option<GpsTime>,
    ts: GpsTime,
    v: T,
) -> u64 {
    match inbox.insert(ts, v) {
        Some((t_old, v_old, _)) => queue_late(q, rewind_to, t_old, v_old),
        None => 0,
    }
}

/// Move every held sample of `inbox` into `q`, each making its rewind due (`rewind_to`).
/// Returns the queue entries evicted to make room.
pub(super) fn ripen<T: Copy + Default, const Q: usize>(
    inbox: &mut TimeQueue<T, INBOX_CAP>,
    q: &mut TimeQueue<T, Q>,
    rewind_to: &mut Option<GpsTime>,
) -> u64 {
    let mut evicted = 0;
    while let Some((t, v, _)) = inbox.pop_oldest() {
        evicted += queue_late(q, rewind_to, t, v);
    }
    evicted
}

fn queue_late<T: Copy + Default, const Q: usize>(
    q: &mut TimeQueue<T, Q>,
    rewind_to: &mut Option<GpsTime>,
    t: GpsTime,
    v: T,
) -> u64 {
    *rewind_to = Some(rewind_to.map_or(t, |r| r.min(t)));
    u64::from(q.insert(t, v).is_some())
}

pub(super) const STAR_CAP: usize = 64;

pub(super) const ODO_CAP: usize = 256;

pub(super) const BARO_CAP: usize = 128;
