//! The whole simulated system in one process: a deterministic, time-ordered stream of every
//! channel's messages for a scenario, and a helper that feeds it to a
//! [`fusion::navigator::Navigator`] and compares the solution with the truth.
//!
//! The stream is built from the same [`crate::sources`] the driver processes run
//! ([`crate::driver::run`]): for each channel, sample `k` at `t_k = k·period` for
//! `k = first_index, first_index + 1, …` while `t_k ≤ duration`, sequence numbers counting from 1
//! as the iceoryx2 publisher stamps them. Offline and live therefore see the same samples,
//! including the scenario's outages (the sources flag them, exactly as live). Only
//! `header.send_mono_ns` differs (0 offline: no process sent anything).
//!
//! # Order
//! Messages come out by time of validity. Ties (several channels sampling the same instant)
//! are broken by [`Channel`] order: aiding, then the IMU, then the truth (the reasons are on
//! [`Channel`]).
//!
//! # Offline-only modification: satellite limits
//! [`OfflineSim::limit_satellites`] keeps at most `n` satellites (those of highest C/N0, i.e.
//! highest elevation) in a time window and, with fewer than four, invalidates the receiver's
//! position/velocity fix — what a receiver tracking only those satellites would output. It is
//! off by default and used by the tight-coupling experiment.

use crate::scenario::Scenario;
use crate::sources::{
    BaroSource, GnssSource, ImuSource, OdometerSource, SampleSource, StarTrackerSource, TruthSource,
};
use fusion::Rejection;
use fusion::ekf::idx;
use fusion::navigator::{Input, Navigator};
use msgs::{Channel, GnssSample, GnssSatellite, NavSolution, Record, TruthSample};
use nalgebra::{Matrix3, Vector3};

/// One channel's source with its sample counter and publisher-style sequence number.
#[derive(Debug, Clone)]
struct Stream<S: SampleSource> {
    source: S,
    k: i64,
    seq: u64,
}

impl<S: SampleSource> Stream<S> {
    fn new(source: S) -> Self {
        let k = source.first_index();
        Self { source, k, seq: 0 }
    }

    /// Sim time (ns since the epoch) of the next sample, if within `duration_ns`.
    fn next_t(&self, duration_ns: i64) -> Option<i64> {
        let t = self.k * self.source.period_ns();
        (t <= duration_ns).then_some(t)
    }

    fn take(&mut self, stamp: impl FnOnce(&mut S::Msg, u64)) -> S::Msg {
        let t = self.k * self.source.period_ns();
        let mut m = self.source.sample(t);
        self.seq += 1;
        stamp(&mut m, self.seq);
        self.k += 1;
        m
    }
}

/// A satellite limit: at most `max_satellites` tracked in `[start_s, start_s + duration_s)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SatelliteLimit {
    /// Start, s since the scenario epoch.
    pub start_s: f64,
    /// Length, s.
    pub duration_s: f64,
    /// Satellites kept (highest C/N0 first).
    pub max_satellites: usize,
}

/// The time-ordered message stream of a scenario (an [`Iterator`] of [`Record`]s).
#[derive(Debug, Clone)]
pub struct OfflineSim {
    epoch_ns: i64,
    duration_ns: i64,
    imu: Option<Stream<ImuSource>>,
    star: Option<Stream<StarTrackerSource>>,
    gnss: Option<Stream<GnssSource>>,
    odo: Option<Stream<OdometerSource>>,
    baro: Option<Stream<BaroSource>>,
    truth: Option<Stream<TruthSource>>,
    limits: Vec<SatelliteLimit>,
}

fn stamp(h: &mut msgs::Header, seq: u64) {
    h.seq = seq;
    h.send_mono_ns = 0;
}

impl OfflineSim {
    /// Every simulated channel of `scn` (the sensors and the truth) over the scenario's
    /// duration.
    pub fn new(scn: &Scenario) -> Self {
        Self::with_channels(scn, &Channel::ALL)
    }

    /// Only the listed channels (each costs its own truth integration; leave out the truth
    /// when not needed). The fusion's outputs (nav, status) are not simulated.
    pub fn with_channels(scn: &Scenario, channels: &[Channel]) -> Self {
        let epoch_ns = scn.epoch_gps().ns;
        let on = |c: Channel| channels.contains(&c);
        Self {
            epoch_ns,
            duration_ns: scn.duration_ns(),
            imu: on(Channel::Imu).then(|| Stream::new(ImuSource::new(scn, epoch_ns))),
            star: on(Channel::StarTracker)
                .then(|| Stream::new(StarTrackerSource::new(scn, epoch_ns))),
            gnss: on(Channel::Gnss).then(|| Stream::new(GnssSource::new(scn, epoch_ns))),
            odo: on(Channel::Odometer).then(|| Stream::new(OdometerSource::new(scn, epoch_ns))),
            baro: on(Channel::Baro).then(|| Stream::new(BaroSource::new(scn, epoch_ns))),
            truth: on(Channel::Truth).then(|| Stream::new(TruthSource::new(scn, epoch_ns))),
            limits: Vec::new(),
        }
    }

    /// Override the duration (s), like the drivers' `--duration`.
    pub fn with_duration_s(mut self, duration_s: f64) -> Self {
        self.duration_ns = (duration_s * 1e9).round() as i64;
        self
    }

    /// Keep at most `limit.max_satellites` satellites during the limit's window (see the
    /// module comment).
    pub fn limit_satellites(mut self, limit: SatelliteLimit) -> Self {
        self.limits.push(limit);
        self
    }

    /// GPS time of the scenario epoch, ns.
    pub fn epoch_ns(&self) -> i64 {
        self.epoch_ns
    }

    /// Duration, ns since the epoch.
    pub fn duration_ns(&self) -> i64 {
        self.duration_ns
    }

    fn apply_limits(&self, g: &mut GnssSample) {
        let t_s = (g.header.time_ns - self.epoch_ns) as f64 * 1e-9;
        let Some(max) = self
            .limits
            .iter()
            .filter(|l| t_s >= l.start_s && t_s < l.start_s + l.duration_s)
            .map(|l| l.max_satellites)
            .min()
        else {
            return;
        };
        let n = (g.n_satellites as usize).min(g.satellites.len());
        if n <= max {
            if n < 4 {
                invalidate_fix(g);
            }
            return;
        }
        let mut sats: Vec<GnssSatellite> = g.satellites[..n].to_vec();
        // Highest C/N0 (= highest elevation in the receiver model) first; PRN breaks ties.
        sats.sort_by(|a, b| b.cn0_dbhz.total_cmp(&a.cn0_dbhz).then(a.prn.cmp(&b.prn)));
        for (i, slot) in g.satellites.iter_mut().enumerate() {
            *slot = if i < max {
                sats[i]
            } else {
                GnssSatellite::default()
            };
        }
        g.n_satellites = max as u32;
        if max < 4 {
            invalidate_fix(g);
        }
    }
}

fn invalidate_fix(g: &mut GnssSample) {
    g.fix_valid = 0;
    g.pos_ecef_m = [0.0; 3];
    g.vel_ecef_m_s = [0.0; 3];
    g.pos_cov_ecef_m2 = [0.0; 9];
    g.vel_cov_ecef_m2_s2 = [0.0; 9];
    g.pdop = 0.0;
}

impl Iterator for OfflineSim {
    type Item = Record;

    fn next(&mut self) -> Option<Record> {
        let d = self.duration_ns;
        // (time, channel) of each stream's next sample; the smallest goes out.
        let candidates = [
            (
                self.star.as_ref().and_then(|s| s.next_t(d)),
                Channel::StarTracker,
            ),
            (self.gnss.as_ref().and_then(|s| s.next_t(d)), Channel::Gnss),
            (
                self.odo.as_ref().and_then(|s| s.next_t(d)),
                Channel::Odometer,
            ),
            (self.baro.as_ref().and_then(|s| s.next_t(d)), Channel::Baro),
            (self.imu.as_ref().and_then(|s| s.next_t(d)), Channel::Imu),
            (
                self.truth.as_ref().and_then(|s| s.next_t(d)),
                Channel::Truth,
            ),
        ];
        let (_, ch) = candidates
            .iter()
            .filter_map(|(t, c)| t.map(|t| (t, *c)))
            .min()?;
        let msg = match ch {
            Channel::StarTracker => {
                Record::StarTracker(self.star.as_mut()?.take(|m, q| stamp(&mut m.header, q)))
            }
            Channel::Gnss => {
                let mut g = self.gnss.as_mut()?.take(|m, q| stamp(&mut m.header, q));
                self.apply_limits(&mut g);
                Record::Gnss(Box::new(g))
            }
            Channel::Odometer => {
                Record::Odometer(self.odo.as_mut()?.take(|m, q| stamp(&mut m.header, q)))
            }
            Channel::Baro => Record::Baro(self.baro.as_mut()?.take(|m, q| stamp(&mut m.header, q))),
            Channel::Imu => Record::Imu(self.imu.as_mut()?.take(|m, q| stamp(&mut m.header, q))),
            Channel::Truth => {
                Record::Truth(self.truth.as_mut()?.take(|m, q| stamp(&mut m.header, q)))
            }
            Channel::Nav | Channel::Status => return None,
        };
        Some(msg)
    }
}

/// Why an offline run failed.
#[derive(Debug, thiserror::Error)]
pub enum OfflineError {
    /// The navigator rejected a simulated sample (a simulator/filter contract violation).
    #[error("navigator rejected the {topic} sample at GPS {time_ns} ns: {source}")]
    Rejected {
        /// Recording topic of the sample.
        topic: &'static str,
        /// Its time of validity, GPS ns.
        time_ns: i64,
        /// The navigator's reason.
        source: Rejection,
    },
}

/// Solution against truth at one truth epoch.
///
/// Errors are *truth minus estimate* in the filter's error-state convention
/// ([`fusion::ekf`]): `δr_e`, `δv_e` in ECEF, `ψ` with `C_e_b = (I + [ψ×])·Ĉ_e_b`, so they
/// compare directly with the covariance blocks, which are copied from the navigator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunPoint {
    /// Time since the scenario epoch, s.
    pub t_s: f64,
    /// Navigation mode (`msgs::NavMode` as u32).
    pub mode: u32,
    /// Position error (truth − estimate), ECEF, m.
    pub pos_err_e_m: Vector3<f64>,
    /// Velocity error (truth − estimate), ECEF, m/s.
    pub vel_err_e_m_s: Vector3<f64>,
    /// Attitude error ψ (rotation vector of `C_e_b,true · Ĉ_e_bᵀ`), ECEF, rad.
    pub att_err_e_rad: Vector3<f64>,
    /// Position covariance, ECEF, m².
    pub pos_cov_e_m2: Matrix3<f64>,
    /// Velocity covariance, ECEF, m²/s².
    pub vel_cov_e_m2_s2: Matrix3<f64>,
    /// Attitude-error covariance, ECEF, rad².
    pub att_cov_e_rad2: Matrix3<f64>,
    /// `C_e_n` (NED → ECEF) at the true position.
    pub c_e_n: Matrix3<f64>,
    /// True accelerometer bias, body, m/s².
    pub accel_bias_true_m_s2: Vector3<f64>,
    /// True gyro bias, body, rad/s.
    pub gyro_bias_true_rad_s: Vector3<f64>,
    /// True body → NED DCM.
    pub c_n_b_true: Matrix3<f64>,
    /// True position, ECEF, m.
    pub pos_true_e_m: Vector3<f64>,
    /// Estimated accelerometer bias, body, m/s².
    pub accel_bias_est_m_s2: Vector3<f64>,
    /// Estimated gyro bias, body, rad/s.
    pub gyro_bias_est_rad_s: Vector3<f64>,
}

fn to_ned(c_e_n: &Matrix3<f64>, v_e: &Vector3<f64>) -> Vector3<f64> {
    c_e_n.transpose() * v_e
}

fn cov_to_ned(c_e_n: &Matrix3<f64>, p_e: &Matrix3<f64>) -> Matrix3<f64> {
    c_e_n.transpose() * p_e * c_e_n
}

impl RunPoint {
    /// Position error in NED at the true position, m.
    pub fn pos_err_ned_m(&self) -> Vector3<f64> {
        to_ned(&self.c_e_n, &self.pos_err_e_m)
    }
    /// Velocity error in NED, m/s.
    pub fn vel_err_ned_m_s(&self) -> Vector3<f64> {
        to_ned(&self.c_e_n, &self.vel_err_e_m_s)
    }
    /// Attitude error resolved in NED (x, y: tilt about north/east, z: about down), rad.
    pub fn att_err_ned_rad(&self) -> Vector3<f64> {
        to_ned(&self.c_e_n, &self.att_err_e_rad)
    }
    /// Horizontal position error, m.
    pub fn horizontal_error_m(&self) -> f64 {
        let e = self.pos_err_ned_m();
        e.x.hypot(e.y)
    }
    /// 1-σ of the position per NED axis, m.
    pub fn pos_sigma_ned_m(&self) -> Vector3<f64> {
        cov_to_ned(&self.c_e_n, &self.pos_cov_e_m2)
            .diagonal()
            .map(|v| v.max(0.0).sqrt())
    }
    /// 1-σ of the velocity per NED axis, m/s.
    pub fn vel_sigma_ned_m_s(&self) -> Vector3<f64> {
        cov_to_ned(&self.c_e_n, &self.vel_cov_e_m2_s2)
            .diagonal()
            .map(|v| v.max(0.0).sqrt())
    }
    /// 1-σ of the attitude error per NED axis, rad.
    pub fn att_sigma_ned_rad(&self) -> Vector3<f64> {
        cov_to_ned(&self.c_e_n, &self.att_cov_e_rad2)
            .diagonal()
            .map(|v| v.max(0.0).sqrt())
    }
    /// Horizontal radial 1-σ, `sqrt(σ_N² + σ_E²)`, m.
    pub fn horizontal_sigma_m(&self) -> f64 {
        let s = self.pos_sigma_ned_m();
        s.x.hypot(s.y)
    }
    /// Normalized estimation error squared of position, velocity and attitude
    /// (`eᵀ P⁻¹ e`, each χ²₃ for a consistent filter); NaN for a singular block.
    pub fn nees(&self) -> [f64; 3] {
        let q = |e: &Vector3<f64>, p: &Matrix3<f64>| match p.cholesky() {
            Some(c) => e.dot(&c.solve(e)),
            None => f64::NAN,
        };
        [
            q(&self.pos_err_e_m, &self.pos_cov_e_m2),
            q(&self.vel_err_e_m_s, &self.vel_cov_e_m2_s2),
            q(&self.att_err_e_rad, &self.att_cov_e_rad2),
        ]
    }
}

/// Counts of an offline run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RunCounts {
    /// Messages per channel (index = [`Channel`] as usize).
    pub messages: [u64; Channel::COUNT],
    /// Truth epochs compared (navigating, truth on an IMU epoch).
    pub compared: u64,
}

/// Compare the navigator's current state with `truth` (the navigator must have processed the
/// IMU sample of the truth's time).
pub fn compare(nav: &Navigator, truth: &TruthSample, epoch_ns: i64) -> RunPoint {
    let c_e_n = fusion::earth::c_e_n(truth.lat_rad, truth.lon_rad);
    let s = nav.nav_state();
    let r_true = Vector3::from(truth.pos_ecef_m);
    let v_true = c_e_n * Vector3::from(truth.vel_ned_m_s);
    let c_n_b = fusion::attitude::quat_from_wire(&truth.q_ned_body)
        .to_rotation_matrix()
        .into_inner();
    let c_e_b_true = c_e_n * c_n_b;
    let c_e_b_est = s.q_e_b.to_rotation_matrix().into_inner();
    let d = nalgebra::Rotation3::from_matrix_unchecked(c_e_b_true * c_e_b_est.transpose());
    let psi = d.scaled_axis();
    let p = nav.covariance();
    let (gyro_bias_est, accel_bias_est) = nav.biases();
    RunPoint {
        t_s: (truth.header.time_ns - epoch_ns) as f64 * 1e-9,
        mode: nav.mode(),
        pos_err_e_m: r_true - s.r_e,
        vel_err_e_m_s: v_true - s.v_e,
        att_err_e_rad: psi,
        pos_cov_e_m2: p.fixed_view::<3, 3>(idx::POS, idx::POS).into_owned(),
        vel_cov_e_m2_s2: p.fixed_view::<3, 3>(idx::VEL, idx::VEL).into_owned(),
        att_cov_e_rad2: p.fixed_view::<3, 3>(idx::ATT, idx::ATT).into_owned(),
        c_e_n,
        accel_bias_true_m_s2: Vector3::from(truth.accel_bias_m_s2),
        gyro_bias_true_rad_s: Vector3::from(truth.gyro_bias_rad_s),
        c_n_b_true: c_n_b,
        pos_true_e_m: r_true,
        accel_bias_est_m_s2: accel_bias_est,
        gyro_bias_est_rad_s: gyro_bias_est,
    }
}

/// Push one message into the navigator (truth and outputs are ignored). Errors name the
/// channel and time. Returns the solution an IMU sample produced.
pub fn feed(nav: &mut Navigator, msg: &Record) -> Result<Option<NavSolution>, OfflineError> {
    let r = Input::from_record(msg).map_or(Ok(None), |input| nav.push(input));
    r.map_err(|source| OfflineError::Rejected {
        topic: msg.topic(),
        time_ns: msg.time_ns(),
        source,
    })
}

/// [`feed`] without forming the solution ([`Navigator::push_deferred`]): true when an IMU
/// sample produced one, which [`Navigator::solution`] forms until the next input.
pub fn feed_deferred(nav: &mut Navigator, msg: &Record) -> Result<bool, OfflineError> {
    let r = Input::from_record(msg).map_or(Ok(false), |input| nav.push_deferred(input));
    r.map_err(|source| OfflineError::Rejected {
        topic: msg.topic(),
        time_ns: msg.time_ns(),
        source,
    })
}

/// Feed `messages` (time-ordered, e.g. an [`OfflineSim`]) to `nav`; at each truth message on
/// an IMU epoch while navigating, call `each` with the comparison (read from the navigator's
/// state: no solution message is formed). `epoch_ns` is the
/// scenario epoch (GPS ns) from which [`RunPoint::t_s`] counts.
pub fn run_navigator<I, F>(
    messages: I,
    epoch_ns: i64,
    nav: &mut Navigator,
    mut each: F,
) -> Result<RunCounts, OfflineError>
where
    I: IntoIterator<Item = Record>,
    F: FnMut(&RunPoint),
{
    let mut counts = RunCounts::default();
    for msg in messages {
        if let Some(c) = msg.channel() {
            counts.messages[c as usize] += 1;
        }
        match &msg {
            Record::Truth(t) => {
                if nav.is_navigating() && nav.time().ns == t.header.time_ns {
                    each(&compare(nav, t, epoch_ns));
                    counts.compared += 1;
                }
            }
            m => {
                feed_deferred(nav, m)?;
            }
        }
    }
    Ok(counts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn scenario(extra_duration_s: f64) -> Scenario {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/scenarios/vehicle.toml");
        let text = std::fs::read_to_string(&path).expect("vehicle scenario");
        assert!(
            text.contains("duration_s = 600.0"),
            "vehicle.toml's duration"
        );
        let text = text.replace(
            "duration_s = 600.0",
            &format!("duration_s = {extra_duration_s:.1}"),
        );
        // The stream's plumbing on the matched world: no time tags shift the samples.
        crate::matched::scenario(Scenario::from_toml_str(&text, &path).expect("valid"))
    }

    /// What a driver process publishes: its loop in `driver::run` without the pacing.
    fn driver_samples<S: SampleSource>(mut s: S, duration_ns: i64) -> Vec<S::Msg> {
        let mut out = Vec::new();
        let mut k = s.first_index();
        while k * s.period_ns() <= duration_ns {
            out.push(s.sample(k * s.period_ns()));
            k += 1;
        }
        out
    }

    #[test]
    fn stream_equals_driver_samples_in_order_with_counts() {
        // 12.5 s: not a multiple of the 1 s GNSS period, so the `≤ duration` end rule matters.
        let scn = scenario(12.5);
        let e = scn.epoch_gps().ns;
        let d = scn.duration_ns();
        let msgs: Vec<Record> = OfflineSim::new(&scn).collect();
        let by = |c: Channel| msgs.iter().filter(move |m| m.channel() == Some(c));

        // Same samples as calling the sources directly (publisher stamps the seq from 1).
        macro_rules! same {
            ($ch:expr, $src:expr) => {{
                let want = driver_samples($src, d);
                let got: Vec<&Record> = by($ch).collect();
                assert_eq!(got.len(), want.len(), "{:?} count", $ch);
                for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                    let mut w = *w;
                    w.header.seq = i as u64 + 1;
                    assert_eq!(**g, Record::from(w), "{:?} sample {i}", $ch);
                }
                got.len()
            }};
        }
        let n_imu = same!(Channel::Imu, ImuSource::new(&scn, e));
        let n_st = same!(Channel::StarTracker, StarTrackerSource::new(&scn, e));
        let n_gnss = same!(Channel::Gnss, GnssSource::new(&scn, e));
        let n_odo = same!(Channel::Odometer, OdometerSource::new(&scn, e));
        let n_baro = same!(Channel::Baro, BaroSource::new(&scn, e));
        let n_truth = same!(Channel::Truth, TruthSource::new(&scn, e));

        // Counts = rate × duration (+1 for instant channels, which include t = 0; interval
        // channels start at their first interval's end). Rates of vehicle.toml.
        assert_eq!(n_imu, 200 * 12 + 100); // 12.5 s × 200 Hz, k = 1..=2500
        assert_eq!(n_st, 5 * 12 + 2 + 1); // 0, 0.2, …, 12.4 s
        assert_eq!(n_gnss, 13); // 0..=12 s
        assert_eq!(n_odo, 250); // 20 Hz, k = 1..=250
        assert_eq!(n_baro, 251);
        assert_eq!(n_truth, 50 * 12 + 25 + 1);
        assert_eq!(msgs.len(), n_imu + n_st + n_gnss + n_odo + n_baro + n_truth);

        // Time order; ties aiding < IMU < truth.
        for w in msgs.windows(2) {
            let (a, b) = (&w[0], &w[1]);
            assert!(
                (a.time_ns(), a.channel()) < (b.time_ns(), b.channel()),
                "{:?}@{} before {:?}@{}",
                a.channel(),
                a.time_ns(),
                b.channel(),
                b.time_ns()
            );
        }
    }

    #[test]
    fn outages_pass_through_and_satellite_limits_apply() {
        // vehicle.toml: GNSS outage 300–360 s; limit 2 satellites in 10–20 s, 5 in 20–30 s.
        let scn = scenario(400.0);
        let sim = OfflineSim::with_channels(&scn, &[Channel::Gnss])
            .limit_satellites(SatelliteLimit {
                start_s: 10.0,
                duration_s: 10.0,
                max_satellites: 2,
            })
            .limit_satellites(SatelliteLimit {
                start_s: 20.0,
                duration_s: 10.0,
                max_satellites: 5,
            });
        let e = sim.epoch_ns();
        for m in sim {
            let Record::Gnss(g) = m else {
                panic!("only GNSS requested")
            };
            let t = (g.header.time_ns - e) as f64 * 1e-9;
            let n = g.n_satellites;
            if (300.0..360.0).contains(&t) {
                assert_eq!((n, g.fix_valid, g.header.status), (0, 0, 1), "outage {t}");
            } else if (10.0..20.0).contains(&t) {
                assert_eq!((n, g.fix_valid), (2, 0), "{t}");
                assert!(g.satellites[0].cn0_dbhz >= g.satellites[1].cn0_dbhz);
                assert_eq!(g.satellites[2], GnssSatellite::default());
            } else if (20.0..30.0).contains(&t) {
                assert_eq!((n, g.fix_valid), (5, 1), "{t}");
            } else {
                assert!(n >= 5 && g.fix_valid == 1, "{t}: {n} satellites");
            }
        }
    }
}
