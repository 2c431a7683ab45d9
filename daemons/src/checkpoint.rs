//! The fusion daemon's checkpoint file: the navigator's [`NavSnapshot`] written atomically and
//! checksummed, read back by a restarted daemon (warm restart, `fusion::navigator` module
//! `warm_start`); and in the same format the calibration memory ([`SavedCalibration`]), saved
//! at the end of a run and read at the next start (`fusion::navigator` module
//! `calibration_memory`).
//!
//! # Format
//! `SXNAVCK1` (8 bytes; `SXNAVCL1` for a calibration memory), payload length (u32 little-endian), payload (the snapshot as JSON,
//! floats round-trip exactly), CRC-32 (IEEE) of the payload (u32 little-endian). Anything else
//! — a short file, another magic, a length that does not match, a checksum that does not —
//! is refused with a [`CheckpointError`] naming the file.
//!
//! # Atomic replacement
//! Written to `NAME.tmp` in the same directory, `fsync`ed, renamed over `NAME` and the
//! directory `fsync`ed: a reader sees the old checkpoint or the new one, never a mix, also
//! after a power loss. The writes happen on their own thread ([`CheckpointWriter`]) so that
//! the filter thread never waits for the disk; when the previous write is still in progress
//! the newer snapshot replaces the one waiting.

use fusion::navigator::NavSnapshot;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Condvar, Mutex};

/// File magic and format version.
pub const MAGIC: &[u8; 8] = b"SXNAVCK1";

/// File magic and format version of a calibration memory ([`SavedCalibration`]).
pub const CALIBRATION_MAGIC: &[u8; 8] = b"SXNAVCL1";

/// Largest payload accepted, bytes (a snapshot is ≈ 25 kB).
const MAX_PAYLOAD: usize = 1 << 20;

/// Which kind of file an error is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    /// The warm-restart checkpoint ([`MAGIC`]).
    Checkpoint,
    /// The calibration memory ([`CALIBRATION_MAGIC`]).
    Calibration,
}

impl FileKind {
    fn magic(self) -> &'static [u8; 8] {
        match self {
            Self::Checkpoint => MAGIC,
            Self::Calibration => CALIBRATION_MAGIC,
        }
    }
}

impl std::fmt::Display for FileKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Checkpoint => "checkpoint",
            Self::Calibration => "calibration",
        })
    }
}

/// Errors reading or writing a checkpoint or a calibration memory.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// The file could not be read or written.
    #[error("{kind} {path}: {source}")]
    Io {
        /// Checkpoint or calibration.
        kind: FileKind,
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The file is not a file of this format, or is damaged.
    #[error("{kind} {path} is corrupt: {what}")]
    Corrupt {
        /// Checkpoint or calibration.
        kind: FileKind,
        /// The file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
}

/// A calibration memory as saved at the end of a run: the navigator's final estimate (only its
/// sensor errors are used, `fusion::navigator` module `calibration_memory`) and the wall-clock
/// time it was saved, which the next start measures the time off from.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedCalibration {
    /// When it was saved, Unix ns (the system clock).
    pub saved_unix_ns: i64,
    /// The estimate the run ended with.
    pub snapshot: NavSnapshot,
}

/// The bytes of a checkpoint file for `snapshot`.
pub fn encode(snapshot: &NavSnapshot) -> Vec<u8> {
    encode_as(FileKind::Checkpoint, snapshot)
}

fn encode_as<T: serde::Serialize>(kind: FileKind, value: &T) -> Vec<u8> {
    // Serializing plain numbers, arrays and a Vec cannot fail.
    let payload = serde_json::to_vec(value).unwrap_or_default();
    let mut out = Vec::with_capacity(payload.len() + 16);
    out.extend_from_slice(kind.magic());
    out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    out.extend_from_slice(&payload);
    out.extend_from_slice(&crc32fast::hash(&payload).to_le_bytes());
    out
}

/// The snapshot in the bytes of a checkpoint file (`path` names it in the error).
pub fn decode(bytes: &[u8], path: &Path) -> Result<NavSnapshot, CheckpointError> {
    decode_as(FileKind::Checkpoint, bytes, path)
}

fn decode_as<T: serde::de::DeserializeOwned>(
    kind: FileKind,
    bytes: &[u8],
    path: &Path,
) -> Result<T, CheckpointError> {
    let corrupt = |what: String| CheckpointError::Corrupt {
        kind,
        path: path.to_path_buf(),
        what,
    };
    if bytes.len() < 16 {
        return Err(corrupt(format!(
            "{} bytes, shorter than a header",
            bytes.len()
        )));
    }
    if &bytes[..8] != kind.magic() {
        return Err(corrupt(format!("not a Sextant navigator {kind} (magic)")));
    }
    let len = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize;
    if len > MAX_PAYLOAD || bytes.len() != 12 + len + 4 {
        return Err(corrupt(format!(
            "payload length {len} does not match the file size {}",
            bytes.len()
        )));
    }
    let payload = &bytes[12..12 + len];
    let t = &bytes[12 + len..];
    let stored = u32::from_le_bytes([t[0], t[1], t[2], t[3]]);
    let actual = crc32fast::hash(payload);
    if stored != actual {
        return Err(corrupt(format!(
            "checksum {actual:08x}, file says {stored:08x}"
        )));
    }
    serde_json::from_slice(payload).map_err(|e| corrupt(format!("payload: {e}")))
}

fn read_as<T: serde::de::DeserializeOwned>(
    kind: FileKind,
    path: &Path,
) -> Result<Option<T>, CheckpointError> {
    match std::fs::read(path) {
        Ok(bytes) => decode_as(kind, &bytes, path).map(Some),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) => Err(CheckpointError::Io {
            kind,
            path: path.to_path_buf(),
            source,
        }),
    }
}

/// Read the checkpoint at `path`; Ok(None) when there is none.
pub fn read(path: &Path) -> Result<Option<NavSnapshot>, CheckpointError> {
    read_as(FileKind::Checkpoint, path)
}

/// Read the calibration memory at `path`; Ok(None) when there is none.
pub fn read_calibration(path: &Path) -> Result<Option<SavedCalibration>, CheckpointError> {
    read_as(FileKind::Calibration, path)
}

/// Write `snapshot` to `path` atomically (module docs).
pub fn write(path: &Path, snapshot: &NavSnapshot) -> Result<(), CheckpointError> {
    write_atomic(FileKind::Checkpoint, path, &encode(snapshot))
}

/// Write the calibration memory `saved` to `path` atomically (module docs).
pub fn write_calibration(path: &Path, saved: &SavedCalibration) -> Result<(), CheckpointError> {
    write_atomic(
        FileKind::Calibration,
        path,
        &encode_as(FileKind::Calibration, saved),
    )
}

fn write_atomic(kind: FileKind, path: &Path, bytes: &[u8]) -> Result<(), CheckpointError> {
    let io = |source| CheckpointError::Io {
        kind,
        path: path.to_path_buf(),
        source,
    };
    let mut tmp_name = path.file_name().unwrap_or_default().to_os_string();
    tmp_name.push(".tmp");
    let tmp = path.with_file_name(tmp_name);
    let mut f = std::fs::File::create(&tmp).map_err(io)?;
    f.write_all(bytes).map_err(io)?;
    f.sync_all().map_err(io)?;
    drop(f);
    std::fs::rename(&tmp, path).map_err(io)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::File::open(dir)
            .and_then(|d| d.sync_all())
            .map_err(io)?;
    }
    Ok(())
}

#[derive(Default)]
struct Slot {
    pending: Option<NavSnapshot>,
    /// A written (or superseded) snapshot handed back for the next [`CheckpointWriter::buffer`],
    /// so the filter thread reuses its covariance's storage instead of allocating one per
    /// checkpoint.
    spare: Option<NavSnapshot>,
    closed: bool,
}

/// Counters of a [`CheckpointWriter`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CheckpointStats {
    /// Checkpoints written.
    pub written: u64,
    /// Writes that failed (each logged).
    pub failed: u64,
    /// Snapshots replaced by a newer one before they were written.
    pub superseded: u64,
}

/// Writes checkpoints on its own thread; [`CheckpointWriter::submit`] never blocks on the disk.
pub struct CheckpointWriter {
    shared: Arc<(Mutex<Slot>, Condvar)>,
    stats: Arc<Mutex<CheckpointStats>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl CheckpointWriter {
    /// A writer of the checkpoint at `path`.
    pub fn start(path: PathBuf) -> std::io::Result<Self> {
        let shared = Arc::new((Mutex::new(Slot::default()), Condvar::new()));
        let stats = Arc::new(Mutex::new(CheckpointStats::default()));
        let (s2, st2) = (shared.clone(), stats.clone());
        let thread = std::thread::Builder::new()
            .name("checkpoint".into())
            .spawn(move || {
                let (lock, cv) = &*s2;
                loop {
                    let snap = {
                        let mut slot = lock.lock().unwrap_or_else(|e| e.into_inner());
                        while slot.pending.is_none() && !slot.closed {
                            slot = cv.wait(slot).unwrap_or_else(|e| e.into_inner());
                        }
                        match slot.pending.take() {
                            Some(s) => s,
                            None => return,
                        }
                    };
                    let r = write(&path, &snap);
                    {
                        let mut slot = lock.lock().unwrap_or_else(|e| e.into_inner());
                        if slot.spare.is_none() {
                            slot.spare = Some(snap);
                        }
                    }
                    let mut st = st2.lock().unwrap_or_else(|e| e.into_inner());
                    match r {
                        Ok(()) => st.written += 1,
                        Err(e) => {
                            st.failed += 1;
                            if st.failed <= 5 || st.failed.is_power_of_two() {
                                tracing::warn!("{e} ({} failed writes)", st.failed);
                            }
                        }
                    }
                }
            })?;
        Ok(Self {
            shared,
            stats,
            thread: Some(thread),
        })
    }

    /// A snapshot to fill and [`submit`](Self::submit): one handed back by the writer thread
    /// when there is one (no allocation once two have gone round), else a new one.
    pub fn buffer(&self) -> NavSnapshot {
        let (lock, _) = &*self.shared;
        lock.lock()
            .unwrap_or_else(|e| e.into_inner())
            .spare
            .take()
            .unwrap_or_default()
    }

    /// Hand back a [`buffer`](Self::buffer) that was not submitted (the engine had no
    /// estimate), for the next one.
    pub fn recycle(&self, snapshot: NavSnapshot) {
        let (lock, _) = &*self.shared;
        lock.lock()
            .unwrap_or_else(|e| e.into_inner())
            .spare
            .get_or_insert(snapshot);
    }

    /// Queue `snapshot` for writing (replacing one still waiting, which becomes the spare).
    pub fn submit(&self, snapshot: NavSnapshot) {
        let (lock, cv) = &*self.shared;
        let mut slot = lock.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(old) = slot.pending.replace(snapshot) {
            slot.spare.get_or_insert(old);
            self.stats
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .superseded += 1;
        }
        cv.notify_one();
    }

    /// Counters so far.
    pub fn stats(&self) -> CheckpointStats {
        *self.stats.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Write what is waiting and stop the thread.
    pub fn finish(mut self) -> CheckpointStats {
        self.close();
        self.stats()
    }

    fn close(&mut self) {
        {
            let (lock, cv) = &*self.shared;
            lock.lock().unwrap_or_else(|e| e.into_inner()).closed = true;
            cv.notify_one();
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for CheckpointWriter {
    fn drop(&mut self) {
        self.close();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn snapshot() -> NavSnapshot {
        NavSnapshot {
            gps_time_ns: 1_400_000_000_123_456_789,
            r_e_m: [2_846_000.1, 2_195_000.2, 5_249_000.3],
            v_e_m_s: [1.0 / 3.0, -2.0, 0.1],
            q_e_b: [1.0, 0.0, 0.0, 0.0],
            gyro_bias_rad_s: [1e-8, -2e-8, 3.3e-9],
            accel_bias_m_s2: [1e-4, 2e-4, -3e-4],
            baro_bias_m: 1.5,
            odo_scale: 1e-3,
            gyro_scale: [1e-5; 3],
            accel_scale: [-1e-5; 3],
            kappa_rad: [0.0; 3],
            gyro_misalignment_rad: [1e-6; 3],
            clock_bias_m: 12.0,
            clock_drift_m_s: 0.3,
            clock_initialized: true,
            covariance: (0..31 * 31)
                .map(|k| if k % 32 == 0 { 0.1 + k as f64 } else { 0.0 })
                .collect(),
        }
    }

    fn tempdir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("sextant-ckpt-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Written and read back bit for bit; no temporary left behind; the writer thread writes
    /// the last snapshot submitted.
    #[test]
    fn round_trip_through_a_file_and_the_writer() {
        let dir = tempdir("rt");
        let path = dir.join("navigator.checkpoint");
        assert!(read(&path).unwrap().is_none());
        let s = snapshot();
        write(&path, &s).unwrap();
        assert_eq!(read(&path).unwrap(), Some(s.clone()));
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
        assert_eq!(names.len(), 1, "temporary file left behind");

        let w = CheckpointWriter::start(path.clone()).unwrap();
        let mut later = s;
        later.gps_time_ns += 1_000_000_000;
        w.submit(later.clone());
        let st = w.finish();
        assert_eq!(st.failed, 0);
        assert_eq!(read(&path).unwrap(), Some(later));
    }

    /// A calibration memory round-trips through its file; a checkpoint is not taken for one.
    #[test]
    fn calibration_round_trip_and_kind_check() {
        let dir = tempdir("cal");
        let path = dir.join("sextant.calibration");
        assert!(read_calibration(&path).unwrap().is_none());
        let saved = SavedCalibration {
            saved_unix_ns: 1_764_000_000_123_456_789,
            snapshot: snapshot(),
        };
        write_calibration(&path, &saved).unwrap();
        assert_eq!(read_calibration(&path).unwrap(), Some(saved));
        write(&path, &snapshot()).unwrap();
        let e = read_calibration(&path).unwrap_err().to_string();
        assert!(e.contains("calibration") && e.contains("magic"), "{e}");
    }

    /// Every damaged file is refused with an error naming it, never a panic.
    #[test]
    fn damaged_files_are_refused() {
        let path = Path::new("x/navigator.checkpoint");
        let good = encode(&snapshot());
        let mut flipped = good.clone();
        flipped[40] ^= 0x01;
        for (bytes, what) in [
            (Vec::new(), "shorter"),
            (b"PK\x03\x04 something else entirely".to_vec(), "magic"),
            (good[..good.len() - 1].to_vec(), "length"),
            (flipped, "checksum"),
        ] {
            let e = decode(&bytes, path).unwrap_err().to_string();
            assert!(
                e.contains("x/navigator.checkpoint") && e.contains(what),
                "{e}"
            );
        }
    }

    proptest! {
        /// Arbitrary bytes, and a valid file with arbitrary bytes changed, never panic.
        #[test]
        fn decoding_arbitrary_bytes_never_panics(
            bytes in proptest::collection::vec(any::<u8>(), 0..200),
            edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..4),
        ) {
            let _ = decode(&bytes, Path::new("p"));
            let mut good = encode(&snapshot());
            let n = good.len();
            for (i, b) in edits {
                good[i % n] = b;
            }
            let _ = decode(&good, Path::new("p"));
        }
    }
}
