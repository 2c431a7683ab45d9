//! One sample source per driver: truth generator + sensor model, producing the message for
//! sample time `t_ns` (ns since the scenario epoch; the message's `time_ns` is GPS time).

use crate::gnss::GnssSim;
use crate::imu::{ImuErrorModel, IntervalErrors};
use crate::scenario::{Scenario, period_ns};
use crate::sensors::{BaroSim, OdometerSim, StarTrackerSim};
use crate::truth::TruthGenerator;
use msgs::{BaroSample, GnssSample, ImuSample, OdometerSample, StarTrackerSample, TruthSample};
use nalgebra::{Rotation3, UnitQuaternion};

/// A deterministic producer of one channel's messages.
pub trait SampleSource {
    /// Message type published.
    type Msg: msgs::Message;
    /// Sample period, ns (a multiple of the truth grid).
    fn period_ns(&self) -> i64;
    /// Index of the first sample: 1 for interval samples (IMU, odometer), 0 for instants.
    fn first_index(&self) -> i64;
    /// The message of the sample at `t_ns` since the epoch. Times must increase.
    fn sample(&mut self, t_ns: i64) -> Self::Msg;
}

fn secs(t_ns: i64) -> f64 {
    t_ns as f64 * 1e-9
}

/// IMU: delta-angle / delta-velocity with the error model.
///
/// With `[imu.channels]` in the scenario the sample carries the N single-axis channels
/// (`n_channels`, `channel_axis`, `channel_delta_*`, `channel_temperature_c`), and the triad
/// fields `delta_angle_rad` / `delta_velocity_m_s` hold the least-squares combination of all
/// channels `(HᵀH)⁻¹Hᵀz` (no fault exclusion), so that a consumer unaware of channels still
/// navigates; the fusion's own combination with fault detection replaces it.
#[derive(Debug, Clone)]
pub struct ImuSource {
    gen_: TruthGenerator,
    /// The error model (public so tests can disable it).
    pub model: ImuErrorModel,
    /// The redundant channels, if configured.
    pub channels: Option<crate::imu::ChannelErrorModel>,
    ls: Option<fusion::redundancy::LsMatrix>,
    epoch_ns: i64,
    period_ns: i64,
}

impl ImuSource {
    /// For scenario `scn` whose epoch is GPS `epoch_ns`.
    pub fn new(scn: &Scenario, epoch_ns: i64) -> Self {
        let channels = crate::imu::ChannelErrorModel::new(scn);
        let ls = channels.as_ref().and_then(|c| {
            let mut a = [[0.0; 3]; msgs::MAX_IMU_CHANNELS];
            a[..c.axes().len()].copy_from_slice(c.axes());
            let h = fusion::redundancy::measurement_matrix(&a, (1u32 << c.axes().len()) - 1);
            fusion::redundancy::ls_covariance_per_unit_variance(&h).map(|inv| inv * h.transpose())
        });
        Self {
            gen_: TruthGenerator::new(scn),
            model: ImuErrorModel::new(scn),
            channels,
            ls,
            epoch_ns,
            period_ns: period_ns(scn.spec.imu.rate_hz),
        }
    }
}

impl SampleSource for ImuSource {
    type Msg = ImuSample;
    fn period_ns(&self) -> i64 {
        self.period_ns
    }
    fn first_index(&self) -> i64 {
        1
    }
    fn sample(&mut self, t_ns: i64) -> ImuSample {
        let inc = self.gen_.advance_to(t_ns);
        let e = self.model.next_interval(secs(t_ns), inc.dt_s);
        let (da, dv) = self.model.corrupt(&e, &inc);
        let mut s = ImuSample {
            dt_s: inc.dt_s,
            delta_angle_rad: [da.x, da.y, da.z],
            delta_velocity_m_s: [dv.x, dv.y, dv.z],
            turntable_angle_rad: self.gen_.current().turntable_rad,
            ..Default::default()
        };
        if let (Some(ch), Some(ls)) = (self.channels.as_mut(), self.ls.as_ref()) {
            let out = ch.sample(secs(t_ns), &inc);
            s.n_channels = out.n as u32;
            for (i, a) in ch.axes().iter().enumerate() {
                s.channel_axis[i] = *a;
            }
            s.channel_delta_angle_rad = out.delta_angle_rad;
            s.channel_delta_velocity_m_s = out.delta_velocity_m_s;
            s.channel_temperature_c = out.temperature_c;
            let da = ls * fusion::redundancy::ChannelVector::from(out.delta_angle_rad);
            let dv = ls * fusion::redundancy::ChannelVector::from(out.delta_velocity_m_s);
            s.delta_angle_rad = [da.x, da.y, da.z];
            s.delta_velocity_m_s = [dv.x, dv.y, dv.z];
        }
        s.header.time_ns = self.epoch_ns + t_ns;
        s
    }
}

/// Star tracker.
#[derive(Debug, Clone)]
pub struct StarTrackerSource {
    gen_: TruthGenerator,
    sim: StarTrackerSim,
    epoch_ns: i64,
    period_ns: i64,
    /// `[world.star_tracker]` latency and `[world.time_tags]` jitter: the sample stamped t
    /// is the attitude at t − latency − jitter.
    tag: crate::world::time_tags::TimeTag,
}

impl StarTrackerSource {
    /// For scenario `scn` whose epoch is GPS `epoch_ns`.
    pub fn new(scn: &Scenario, epoch_ns: i64) -> Self {
        Self {
            gen_: TruthGenerator::new(scn),
            sim: StarTrackerSim::new(scn),
            epoch_ns,
            period_ns: period_ns(scn.spec.star_tracker.rate_hz),
            tag: time_tag(scn, msgs::SensorId::StarTracker),
        }
    }
}

impl SampleSource for StarTrackerSource {
    type Msg = StarTrackerSample;
    fn period_ns(&self) -> i64 {
        self.period_ns
    }
    fn first_index(&self) -> i64 {
        0
    }
    fn sample(&mut self, t_ns: i64) -> StarTrackerSample {
        if !self.tag.is_delayed() {
            self.gen_.advance_to(t_ns);
            return self
                .sim
                .sample(secs(t_ns), self.epoch_ns + t_ns, self.gen_.current());
        }
        // Validation keeps latency and jitter whole truth-grid steps below one period.
        let t_meas_ns = self.tag.measurement_instant_ns(t_ns);
        self.gen_.advance_to(t_meas_ns);
        let mut s = self.sim.sample(
            secs(t_meas_ns),
            self.epoch_ns + t_meas_ns,
            self.gen_.current(),
        );
        s.header.time_ns = self.epoch_ns + t_ns;
        s
    }
}

/// How `sensor` is stamped in `scn`'s world (no delay without one).
fn time_tag(scn: &Scenario, sensor: msgs::SensorId) -> crate::world::time_tags::TimeTag {
    scn.spec.world.map_or_else(
        || crate::world::time_tags::TimeTag::fixed(0),
        |w| w.time_tag(scn.spec.scenario.seed, sensor),
    )
}

/// GNSS receiver. With a `[world.gnss_antenna]` latency `L` (and a `[world.time_tags]` jitter
/// `j`), the sample stamped `t` is the measurement made at `t − L − j` (a time-tag error the
/// filter must be told about: `L`, not `j`).
#[derive(Debug, Clone)]
pub struct GnssSource {
    gen_: TruthGenerator,
    /// The receiver model.
    pub sim: GnssSim,
    epoch_ns: i64,
    period_ns: i64,
    tag: crate::world::time_tags::TimeTag,
}

impl GnssSource {
    /// For scenario `scn` whose epoch is GPS `epoch_ns`.
    pub fn new(scn: &Scenario, epoch_ns: i64) -> Self {
        Self {
            gen_: TruthGenerator::new(scn),
            sim: GnssSim::new(scn),
            epoch_ns,
            period_ns: period_ns(scn.spec.gnss.rate_hz),
            tag: time_tag(scn, msgs::SensorId::Gnss),
        }
    }

    /// Sample with the hidden truth of the epoch (clock, geometric ranges).
    pub fn sample_with_truth(&mut self, t_ns: i64) -> (GnssSample, crate::gnss::GnssEpochTruth) {
        // Validation keeps latency and jitter whole truth-grid steps below one period.
        let t_meas_ns = self.tag.measurement_instant_ns(t_ns);
        self.gen_.advance_to(t_meas_ns);
        let (mut s, truth) = self.sim.sample(
            secs(t_meas_ns),
            self.epoch_ns + t_meas_ns,
            self.gen_.current(),
        );
        s.header.time_ns = self.epoch_ns + t_ns;
        (s, truth)
    }
}

impl SampleSource for GnssSource {
    type Msg = GnssSample;
    fn period_ns(&self) -> i64 {
        self.period_ns
    }
    fn first_index(&self) -> i64 {
        0
    }
    fn sample(&mut self, t_ns: i64) -> GnssSample {
        self.sample_with_truth(t_ns).0
    }
}

/// Odometer. With `[world.time_tags]`, the sample stamped `t` holds the distance up to
/// `t − L − j`.
#[derive(Debug, Clone)]
pub struct OdometerSource {
    gen_: TruthGenerator,
    sim: OdometerSim,
    epoch_ns: i64,
    period_ns: i64,
    tag: crate::world::time_tags::TimeTag,
}

impl OdometerSource {
    /// For scenario `scn` whose epoch is GPS `epoch_ns`.
    pub fn new(scn: &Scenario, epoch_ns: i64) -> Self {
        Self {
            gen_: TruthGenerator::new(scn),
            sim: OdometerSim::new(scn),
            epoch_ns,
            period_ns: period_ns(scn.spec.odometer.rate_hz),
            tag: time_tag(scn, msgs::SensorId::Odometer),
        }
    }
}

impl SampleSource for OdometerSource {
    type Msg = OdometerSample;
    fn period_ns(&self) -> i64 {
        self.period_ns
    }
    fn first_index(&self) -> i64 {
        1
    }
    fn sample(&mut self, t_ns: i64) -> OdometerSample {
        let inc = self.gen_.advance_to(self.tag.measurement_instant_ns(t_ns));
        self.sim.sample(self.epoch_ns + t_ns, &inc)
    }
}

/// Barometer.
#[derive(Debug, Clone)]
pub struct BaroSource {
    gen_: TruthGenerator,
    sim: BaroSim,
    epoch_ns: i64,
    period_ns: i64,
}

impl BaroSource {
    /// For scenario `scn` whose epoch is GPS `epoch_ns`.
    pub fn new(scn: &Scenario, epoch_ns: i64) -> Self {
        Self {
            gen_: TruthGenerator::new(scn),
            sim: BaroSim::new(scn),
            epoch_ns,
            period_ns: period_ns(scn.spec.baro.rate_hz),
        }
    }
}

impl SampleSource for BaroSource {
    type Msg = BaroSample;
    fn period_ns(&self) -> i64 {
        self.period_ns
    }
    fn first_index(&self) -> i64 {
        0
    }
    fn sample(&mut self, t_ns: i64) -> BaroSample {
        self.gen_.advance_to(t_ns);
        self.sim
            .sample(secs(t_ns), self.epoch_ns + t_ns, self.gen_.current())
    }
}

/// Truth, including the IMU's true biases re-derived by running the IMU error model's stream.
#[derive(Debug, Clone)]
pub struct TruthSource {
    gen_: TruthGenerator,
    imu: ImuErrorModel,
    imu_period_ns: i64,
    imu_next_end_ns: i64,
    imu_last: Option<IntervalErrors>,
    epoch_ns: i64,
    period_ns: i64,
}

impl TruthSource {
    /// For scenario `scn` whose epoch is GPS `epoch_ns`.
    pub fn new(scn: &Scenario, epoch_ns: i64) -> Self {
        let imu_period_ns = period_ns(scn.spec.imu.rate_hz);
        Self {
            gen_: TruthGenerator::new(scn),
            imu: ImuErrorModel::new(scn),
            imu_period_ns,
            imu_next_end_ns: imu_period_ns,
            imu_last: None,
            epoch_ns,
            period_ns: period_ns(scn.spec.truth.rate_hz),
        }
    }
}

impl SampleSource for TruthSource {
    type Msg = TruthSample;
    fn period_ns(&self) -> i64 {
        self.period_ns
    }
    fn first_index(&self) -> i64 {
        0
    }
    fn sample(&mut self, t_ns: i64) -> TruthSample {
        // Biases of the IMU interval that contains t (the one ending at the first IMU sample
        // time ≥ t), drawn exactly as the IMU process draws them.
        while self.imu_last.is_none() || self.imu_next_end_ns - self.imu_period_ns < t_ns {
            let dt = self.imu_period_ns as f64 * 1e-9;
            self.imu_last = Some(self.imu.next_interval(secs(self.imu_next_end_ns), dt));
            self.imu_next_end_ns += self.imu_period_ns;
        }
        self.gen_.advance_to(t_ns);
        let p = self.gen_.current();
        let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(p.c_n_b));
        let (gb, ab) = match &self.imu_last {
            Some(e) => (e.gyro_bias_rad_s, e.accel_bias_m_s2),
            None => Default::default(),
        };
        let mut s = TruthSample {
            lat_rad: p.geodetic.lat_rad,
            lon_rad: p.geodetic.lon_rad,
            height_m: p.geodetic.height_m,
            pos_ecef_m: [p.r_e_m.x, p.r_e_m.y, p.r_e_m.z],
            vel_ned_m_s: [p.v_ned_m_s.x, p.v_ned_m_s.y, p.v_ned_m_s.z],
            q_ned_body: fusion::attitude::quat_to_wire(&q),
            roll_pitch_heading_rad: [
                p.roll_pitch_heading_rad.x,
                p.roll_pitch_heading_rad.y,
                p.roll_pitch_heading_rad.z,
            ],
            gyro_bias_rad_s: [gb.x, gb.y, gb.z],
            accel_bias_m_s2: [ab.x, ab.y, ab.z],
            ..Default::default()
        };
        s.header.time_ns = self.epoch_ns + t_ns;
        s
    }
}
