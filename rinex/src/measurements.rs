//! From observation records to the raw measurements of [`fusion::point_positioning`].

use crate::observation::{ObservationEpoch, ObservationFile};
use fusion::point_positioning::CodeMeasurement;

/// A requested observation code is not in the file's GPS observation types.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("observation code {code} is not among the file's GPS observation types")]
pub struct MissingCode {
    /// The code asked for.
    pub code: String,
}

/// Which observation codes feed a fix: the L1 code (e.g. `C1C`), optionally an L2 code for
/// the ionosphere-free combination (e.g. `C2W`), the L1 Doppler (`D1C`) and C/N0 (`S1C`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GpsCodes {
    l1: usize,
    l2: Option<usize>,
    doppler: Option<usize>,
    cn0: Option<usize>,
}

impl GpsCodes {
    /// Column indices of the codes in `file`; the Doppler and C/N0 are taken from the same
    /// signal as the L1 code (`C1C` → `D1C`, `S1C`) when present.
    pub fn select(file: &ObservationFile, l1: &str, l2: Option<&str>) -> Result<Self, MissingCode> {
        let find = |c: &str| {
            file.gps_index(c).ok_or(MissingCode {
                code: c.to_string(),
            })
        };
        let signal = &l1[1.min(l1.len())..];
        Ok(Self {
            l1: find(l1)?,
            l2: l2.map(find).transpose()?,
            doppler: file.gps_index(&format!("D{signal}")),
            cn0: file.gps_index(&format!("S{signal}")),
        })
    }
}

/// The GPS measurements of one epoch: every satellite with an L1 code (the L2 code, Doppler
/// and C/N0 when present and, for the code, positive).
pub fn epoch_measurements(epoch: &ObservationEpoch, codes: &GpsCodes) -> Vec<CodeMeasurement> {
    let get = |v: &[Option<f64>], i: Option<usize>| i.and_then(|i| v.get(i).copied().flatten());
    epoch
        .gps
        .iter()
        .filter_map(|s| {
            let p1 = get(&s.values, Some(codes.l1)).filter(|p| *p > 0.0)?;
            Some(CodeMeasurement {
                prn: s.prn,
                p1_m: p1,
                p2_m: get(&s.values, codes.l2).filter(|p| *p > 0.0),
                doppler_l1_hz: get(&s.values, codes.doppler),
                cn0_dbhz: get(&s.values, codes.cn0).filter(|c| *c > 0.0),
            })
        })
        .collect()
}
