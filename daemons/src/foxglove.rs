//! The solution on Foxglove's well-known schemas (in the recording's encoding: JSON, or
//! protobuf on Foxglove's own descriptors, [`ToProtobuf`]), so that Foxglove's Map and 3D panels
//! show it without configuration:
//! - topic `nav/location_fix`, schema `foxglove.LocationFix`: latitude/longitude in degrees,
//!   altitude in m above the WGS-84 ellipsoid, the full ENU position covariance (m²; its
//!   diagonal for a solution recorded before it carried the covariance).
//! - topic `nav/pose`, schema `foxglove.PoseInFrame`: the body frame (x forward, y right,
//!   z down) in the local NED frame `ned` whose origin is the first recorded solution
//!   (position = NED offset from that origin, m; orientation = `q_ned_body`).
//! - topic `tf`, schema `foxglove.FrameTransforms`: the frame tree `ecef` → `ned` (the local
//!   NED frame at that origin) → `body` (the solution) → `imu`, `star_tracker`, `gnss_antenna`
//!   (the sensors' mounting as the filter models it, [`SensorMounts`]: the IMU defines the body
//!   frame, the star tracker is mounted 180° about body x — the navigator's nominal mount, see
//!   `docs/ARCHITECTURE.md` — times the estimated boresight misalignment κ; the antenna sits at
//!   the filter's configured lever arm `[gnss] lever_arm_b_m`, read from the filter
//!   configuration a recording carries). Foxglove's 3D panel draws the vehicle and its sensors
//!   from it, in any of these frames.
//! - topic `status/plot`, schema `sextant.StatusPlot`: the status flattened into plain numbers
//!   (mode, one 0/1 per sensor alive, deadline misses, records dropped…) so that a Plot panel
//!   shows each as a line without decoding bit masks.
//!
//! Foxglove's rule for a transform: `translation` is the child frame's origin in the parent
//! frame and `rotation` the child frame's orientation in the parent, i.e. the rotation that
//! takes child coordinates to parent coordinates (`v_parent = q ⊗ v_child ⊗ q*`); that is
//! Sextant's `C_parent_child`, so the `ned` → `body` rotation is `q_ned_body` itself.
//!
//! Timestamps are Unix time (seconds and nanoseconds since 1970-01-01T00:00:00 UTC, leap
//! seconds not counted), equal to the message's MCAP log time: the solution's GPS time of
//! validity converted to UTC (see [`crate::recorder`]); GPS time stays in the `nav` channel's
//! header.

use fusion::frames::Rotation;
use fusion::navigator::NavigatorConfig;
use msgs::{NavSolution, SensorId, Status};
use nalgebra::{Matrix3, Vector3 as V3};
use serde::Serialize;
use std::collections::BTreeMap;

/// Topic of the LocationFix channel.
pub const LOCATION_FIX_TOPIC: &str = "nav/location_fix";
/// Schema name of the LocationFix channel.
pub const LOCATION_FIX_SCHEMA: &str = "foxglove.LocationFix";
/// Topic of the pose channel.
pub const POSE_TOPIC: &str = "nav/pose";
/// Schema name of the pose channel.
pub const POSE_SCHEMA: &str = "foxglove.PoseInFrame";
/// Frame id of the local NED frame of the pose channel.
pub const NED_FRAME: &str = "ned";
/// Frame id of the Earth-centred Earth-fixed frame (WGS-84).
pub const ECEF_FRAME: &str = "ecef";
/// Frame id of the vehicle body (x forward, y right, z down).
pub const BODY_FRAME: &str = "body";
/// Topic of the frame tree.
pub const TF_TOPIC: &str = "tf";
/// Schema name of the frame tree.
pub const TF_SCHEMA: &str = "foxglove.FrameTransforms";
/// Topic of the plottable status.
pub const STATUS_PLOT_TOPIC: &str = "status/plot";
/// Schema name of the plottable status.
pub const STATUS_PLOT_SCHEMA: &str = "sextant.StatusPlot";

/// Nominal star-tracker mount `C_s_b` (body → sensor): 180° about body x, the optical axis
/// (sensor z) pointing up; the navigator's nominal mount (`docs/ARCHITECTURE.md`).
const C_S_B_NOMINAL: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];

/// Foxglove `time`.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq, schemars::JsonSchema)]
pub struct Timestamp {
    /// Whole seconds.
    pub sec: u32,
    /// Nanoseconds, 0..1e9.
    pub nsec: u32,
}

impl Timestamp {
    /// From Unix ns (seconds beyond 2106 saturate).
    pub fn from_unix_ns(unix_ns: u64) -> Self {
        Self {
            sec: u32::try_from(unix_ns / 1_000_000_000).unwrap_or(u32::MAX),
            nsec: (unix_ns % 1_000_000_000) as u32,
        }
    }
}

/// `foxglove.LocationFix`.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LocationFix {
    /// Time of validity.
    pub timestamp: Timestamp,
    /// Frame of the sensor.
    pub frame_id: &'static str,
    /// Latitude, deg.
    pub latitude: f64,
    /// Longitude, deg.
    pub longitude: f64,
    /// Altitude above the ellipsoid, m.
    pub altitude: f64,
    /// ENU covariance, row-major, m².
    pub position_covariance: [f64; 9],
    /// 3 = known (the full matrix), or 2 = diagonal known for a solution recorded before it
    /// carried its covariance.
    pub position_covariance_type: u8,
}

/// `foxglove.Vector3`.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `foxglove.Quaternion` (scalar last, as Foxglove expects).
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

/// `foxglove.Pose`.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Pose {
    /// Position, m.
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `foxglove.PoseInFrame`.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PoseInFrame {
    /// Time of validity.
    pub timestamp: Timestamp,
    /// Reference frame.
    pub frame_id: &'static str,
    /// The pose.
    pub pose: Pose,
}

/// `foxglove.FrameTransform`: child frame in parent frame.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct FrameTransform {
    /// Time of validity (Unix).
    pub timestamp: Timestamp,
    /// Parent frame id.
    pub parent_frame_id: &'static str,
    /// Child frame id.
    pub child_frame_id: &'static str,
    /// Child origin in the parent frame, m.
    pub translation: Vector3,
    /// Child orientation in the parent frame (child → parent coordinates).
    pub rotation: Quaternion,
}

/// `foxglove.FrameTransforms`.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct FrameTransforms {
    /// The transforms, parents before children.
    pub transforms: Vec<FrameTransform>,
}

/// The plottable status (`sextant.StatusPlot`): every field a plain number.
#[derive(Debug, Clone, Default, Serialize, PartialEq, schemars::JsonSchema)]
pub struct StatusPlot {
    /// Time of the status (Unix).
    pub timestamp: Timestamp,
    /// `NavMode` as a number.
    pub mode: u32,
    /// 1 when the IMU is alive, 0 otherwise.
    pub imu_alive: u8,
    /// 1 when the star tracker is alive.
    pub star_tracker_alive: u8,
    /// 1 when the GNSS receiver is alive.
    pub gnss_alive: u8,
    /// 1 when the odometer is alive.
    pub odometer_alive: u8,
    /// 1 when the barometer is alive.
    pub baro_alive: u8,
    /// Deadline misses so far, per sensor in `SensorId` order.
    pub deadline_misses: [u32; SensorId::COUNT],
    /// Solutions published so far.
    pub solutions_published: u64,
    /// Records written so far.
    pub records_written: u64,
    /// Records dropped so far.
    pub records_dropped: u64,
    /// Recorder write errors so far.
    pub recorder_errors: u64,
    /// IMU channels excluded by fault detection (count of the mask's bits).
    pub imu_channels_excluded: u32,
    /// Filter re-initialisations so far.
    pub reinitializations: u64,
    /// Starts of navigation in motion so far.
    pub motion_alignments: u64,
    /// Starts that resumed the sensor-error estimates from a checkpoint so far.
    pub warm_starts: u64,
    /// Solutions published stale so far.
    pub solutions_stale: u64,
    /// Median latency (IMU sample sent → solution sent) over every solution so far, µs.
    pub latency_p50_us: f64,
    /// 99th percentile of that latency so far, µs.
    pub latency_p99_us: f64,
}

/// A view's protobuf form (recordings of [`crate::recorder::RecordingEncoding::Protobuf`]):
/// the Foxglove views on Foxglove's own protobuf schemas (the `foxglove` crate's generated
/// types and descriptors), the status plot on its own descriptor ([`msgs::protobuf`]).
pub trait ToProtobuf {
    /// The MCAP schema: name and serialized `FileDescriptorSet`.
    fn protobuf_schema() -> (&'static str, Vec<u8>);
    /// Append the protobuf wire form of the view to `buf`.
    fn write_protobuf(&self, buf: &mut Vec<u8>);
}

fn foxglove_schema<T: ::foxglove::Encode>(name: &'static str) -> (&'static str, Vec<u8>) {
    let data = T::get_schema().map_or_else(Vec::new, |s| s.data.into_owned());
    (name, data)
}

fn foxglove_encode<T: ::foxglove::Encode>(view: &T, buf: &mut Vec<u8>) {
    // A Vec grows as needed: encoding into it cannot run out of space.
    let _ = view.encode(buf);
}

impl Timestamp {
    fn to_protobuf(self) -> ::foxglove::schemas::Timestamp {
        ::foxglove::schemas::Timestamp::new(self.sec, self.nsec)
    }
}

impl Vector3 {
    fn to_protobuf(self) -> ::foxglove::schemas::Vector3 {
        ::foxglove::schemas::Vector3 {
            x: self.x,
            y: self.y,
            z: self.z,
        }
    }
}

impl Quaternion {
    fn to_protobuf(self) -> ::foxglove::schemas::Quaternion {
        ::foxglove::schemas::Quaternion {
            x: self.x,
            y: self.y,
            z: self.z,
            w: self.w,
        }
    }
}

impl ToProtobuf for LocationFix {
    fn protobuf_schema() -> (&'static str, Vec<u8>) {
        foxglove_schema::<::foxglove::schemas::LocationFix>(LOCATION_FIX_SCHEMA)
    }
    fn write_protobuf(&self, buf: &mut Vec<u8>) {
        let fix = ::foxglove::schemas::LocationFix {
            timestamp: Some(self.timestamp.to_protobuf()),
            frame_id: self.frame_id.to_string(),
            latitude: self.latitude,
            longitude: self.longitude,
            altitude: self.altitude,
            position_covariance: self.position_covariance.to_vec(),
            position_covariance_type: i32::from(self.position_covariance_type),
            ..Default::default()
        };
        foxglove_encode(&fix, buf);
    }
}

impl ToProtobuf for PoseInFrame {
    fn protobuf_schema() -> (&'static str, Vec<u8>) {
        foxglove_schema::<::foxglove::schemas::PoseInFrame>(POSE_SCHEMA)
    }
    fn write_protobuf(&self, buf: &mut Vec<u8>) {
        let pose = ::foxglove::schemas::PoseInFrame {
            timestamp: Some(self.timestamp.to_protobuf()),
            frame_id: self.frame_id.to_string(),
            pose: Some(::foxglove::schemas::Pose {
                position: Some(self.pose.position.to_protobuf()),
                orientation: Some(self.pose.orientation.to_protobuf()),
            }),
        };
        foxglove_encode(&pose, buf);
    }
}

impl ToProtobuf for FrameTransforms {
    fn protobuf_schema() -> (&'static str, Vec<u8>) {
        foxglove_schema::<::foxglove::schemas::FrameTransforms>(TF_SCHEMA)
    }
    fn write_protobuf(&self, buf: &mut Vec<u8>) {
        let tf = ::foxglove::schemas::FrameTransforms {
            transforms: self
                .transforms
                .iter()
                .map(|t| ::foxglove::schemas::FrameTransform {
                    timestamp: Some(t.timestamp.to_protobuf()),
                    parent_frame_id: t.parent_frame_id.to_string(),
                    child_frame_id: t.child_frame_id.to_string(),
                    translation: Some(t.translation.to_protobuf()),
                    rotation: Some(t.rotation.to_protobuf()),
                })
                .collect(),
        };
        foxglove_encode(&tf, buf);
    }
}

/// The status plot's time as `google.protobuf.Timestamp`, the type Foxglove shows as a time.
impl msgs::protobuf::Field for Timestamp {
    fn encode(&self, number: u32, buf: &mut Vec<u8>) {
        self.to_well_known().encode(number, buf);
    }
    fn merge(
        &mut self,
        at: msgs::protobuf::Occurrence<'_, '_>,
    ) -> Result<(), msgs::protobuf::FieldError> {
        let mut t = self.to_well_known();
        t.merge(at)?;
        self.sec = u32::try_from(t.seconds).map_err(|_| msgs::protobuf::FieldError::OutOfRange)?;
        self.nsec = u32::try_from(t.nanos).map_err(|_| msgs::protobuf::FieldError::OutOfRange)?;
        Ok(())
    }
    fn describe(
        name: &str,
        number: u32,
        nested: &mut BTreeMap<&'static str, msgs::protobuf::prost_types::DescriptorProto>,
    ) -> msgs::protobuf::prost_types::FieldDescriptorProto {
        <msgs::protobuf::Timestamp as msgs::protobuf::Field>::describe(name, number, nested)
    }
}

impl Timestamp {
    fn to_well_known(self) -> msgs::protobuf::Timestamp {
        msgs::protobuf::Timestamp {
            seconds: i64::from(self.sec),
            nanos: self.nsec as i32,
        }
    }
}

msgs::proto_message!(StatusPlot = "sextant.StatusPlot" {
    1 => timestamp, 2 => mode, 3 => imu_alive, 4 => star_tracker_alive, 5 => gnss_alive,
    6 => odometer_alive, 7 => baro_alive, 8 => deadline_misses, 9 => solutions_published,
    10 => records_written, 11 => records_dropped, 12 => recorder_errors,
    13 => imu_channels_excluded, 14 => reinitializations, 15 => motion_alignments,
    16 => warm_starts, 17 => solutions_stale, 18 => latency_p50_us, 19 => latency_p99_us,
});

impl ToProtobuf for StatusPlot {
    fn protobuf_schema() -> (&'static str, Vec<u8>) {
        (
            STATUS_PLOT_SCHEMA,
            msgs::protobuf::file_descriptor_set::<StatusPlot>(),
        )
    }
    fn write_protobuf(&self, buf: &mut Vec<u8>) {
        msgs::protobuf::ProtoMessage::encode_fields(self, buf);
    }
}

/// The plottable view of a status stamped `unix_ns` (its log time).
pub fn status_plot(st: &Status, unix_ns: u64) -> StatusPlot {
    let alive = |s: SensorId| u8::from(st.alive_mask & (1 << s as u32) != 0);
    let mut misses = [0u32; SensorId::COUNT];
    for (m, h) in misses.iter_mut().zip(st.sensors.iter()) {
        *m = h.deadline_misses;
    }
    StatusPlot {
        timestamp: Timestamp::from_unix_ns(unix_ns),
        mode: st.mode,
        imu_alive: alive(SensorId::Imu),
        star_tracker_alive: alive(SensorId::StarTracker),
        gnss_alive: alive(SensorId::Gnss),
        odometer_alive: alive(SensorId::Odometer),
        baro_alive: alive(SensorId::Baro),
        deadline_misses: misses,
        solutions_published: st.solutions_published,
        records_written: st.records_written,
        records_dropped: st.records_dropped,
        recorder_errors: st.recorder_errors,
        imu_channels_excluded: st.imu_channels_excluded_mask.count_ones(),
        reinitializations: st.reinitializations,
        motion_alignments: st.motion_alignments,
        warm_starts: st.warm_starts,
        solutions_stale: st.solutions_stale,
        latency_p50_us: st.latency_p50_us,
        latency_p99_us: st.latency_p99_us,
    }
}

fn quaternion_of<F: fusion::frames::Frame, T: fusion::frames::Frame>(
    r: &Rotation<F, T>,
) -> Quaternion {
    let q = r.to_quaternion();
    Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    }
}

const IDENTITY: Quaternion = Quaternion {
    x: 0.0,
    y: 0.0,
    z: 0.0,
    w: 1.0,
};
const ZERO: Vector3 = Vector3 {
    x: 0.0,
    y: 0.0,
    z: 0.0,
};

/// Where the filter models the sensors in the body frame (the star tracker's mount is the
/// nominal one times the solution's estimated boresight, not configured here).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SensorMounts {
    /// GNSS antenna phase centre from the IMU (body origin), body axes, m (`[gnss]
    /// lever_arm_b_m` of the filter configuration).
    pub gnss_lever_arm_b_m: [f64; 3],
}

impl SensorMounts {
    /// The mounts of a filter configuration.
    pub fn of_filter(cfg: &NavigatorConfig) -> Self {
        Self {
            gnss_lever_arm_b_m: cfg.gnss.lever_arm_b_m,
        }
    }

    /// The mounts of the filter configuration in a recording's metadata (the TOML under
    /// [`crate::recorder::CONFIG_KEY_FILTER_TOML`] of [`crate::recorder::CONFIG_METADATA_NAME`]);
    /// all at the body origin when there is none or it does not parse (a recording of another
    /// version), with a warning for the latter.
    pub fn of_metadata(metadata: &[(String, BTreeMap<String, String>)]) -> Self {
        let Some(text) = metadata
            .iter()
            .find(|(name, _)| name == crate::recorder::CONFIG_METADATA_NAME)
            .and_then(|(_, m)| m.get(crate::recorder::CONFIG_KEY_FILTER_TOML))
        else {
            return Self::default();
        };
        match toml::from_str::<NavigatorConfig>(text) {
            Ok(cfg) => Self::of_filter(&cfg),
            Err(e) => {
                tracing::warn!(
                    "frame tree: filter configuration unreadable ({e}): sensors drawn at the body origin"
                );
                Self::default()
            }
        }
    }
}

/// The frame tree of a solution stamped `unix_ns`: `ecef` → `ned` (at `origin`) → `body` →
/// `imu`, `star_tracker`, `gnss_antenna` (at `mounts`; see the module comment).
pub fn frame_transforms(
    nav: &NavSolution,
    origin: &NedOrigin,
    mounts: &SensorMounts,
    unix_ns: u64,
) -> FrameTransforms {
    let timestamp = Timestamp::from_unix_ns(unix_ns);
    let c_e_n: Rotation<fusion::frames::Ned, fusion::frames::Ecef> =
        fusion::earth::ned_to_ecef(origin.lat_rad, origin.lon_rad);
    let p = ned_offset(origin.r_e, origin.lat_rad, origin.lon_rad, nav.pos_ecef_m);
    let [w, x, y, z] = nav.q_ned_body;
    // C_s_b = C_s_b,nominal · M(κ) (paper 000); the transform wants C_b_s = C_s_bᵀ.
    let kappa = V3::from(nav.boresight_rad);
    let c_s_b = Matrix3::from_fn(|i, j| C_S_B_NOMINAL[i][j])
        * fusion::ekf::measurements::kappa_matrix(&kappa);
    let c_b_s: Rotation<fusion::frames::StarSensor, fusion::frames::Body> =
        Rotation::from_dcm_unchecked(c_s_b.transpose());
    let tf = |parent, child, translation, rotation| FrameTransform {
        timestamp,
        parent_frame_id: parent,
        child_frame_id: child,
        translation,
        rotation,
    };
    let [ox, oy, oz] = origin.r_e;
    FrameTransforms {
        transforms: vec![
            tf(
                ECEF_FRAME,
                NED_FRAME,
                Vector3 {
                    x: ox,
                    y: oy,
                    z: oz,
                },
                quaternion_of(&c_e_n),
            ),
            tf(
                NED_FRAME,
                BODY_FRAME,
                Vector3 {
                    x: p[0],
                    y: p[1],
                    z: p[2],
                },
                Quaternion { x, y, z, w },
            ),
            tf(BODY_FRAME, "imu", ZERO, IDENTITY),
            tf(BODY_FRAME, "star_tracker", ZERO, quaternion_of(&c_b_s)),
            tf(
                BODY_FRAME,
                "gnss_antenna",
                Vector3 {
                    x: mounts.gnss_lever_arm_b_m[0],
                    y: mounts.gnss_lever_arm_b_m[1],
                    z: mounts.gnss_lever_arm_b_m[2],
                },
                IDENTITY,
            ),
        ],
    }
}

/// Rotation NED → ENU (`v_enu = C_ENU_NED · v_ned`): east is the second NED axis, north the
/// first, up the negated down.
pub const C_ENU_NED: [[f64; 3]; 3] = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]];

/// The ENU covariance `C_ENU_NED · P · C_ENU_NEDᵀ` of a NED covariance `p_ned` (m²), row-major.
pub fn covariance_enu_of_ned(p_ned: &[[f64; 3]; 3]) -> [f64; 9] {
    let c = &C_ENU_NED;
    let mut out = [0.0; 9];
    for i in 0..3 {
        for j in 0..3 {
            // Σ_k Σ_l c[i][k] p[k][l] c[j][l]: one term is ±p[k][l], the others exact
            // zeros, so the result is P's elements permuted and signed, bit for bit.
            out[3 * i + j] = (0..3)
                .flat_map(|k| (0..3).map(move |l| c[i][k] * p_ned[k][l] * c[j][l]))
                .sum();
        }
    }
    out
}

/// LocationFix of a solution stamped `unix_ns` (its log time): the full position covariance
/// rotated into ENU (type 3, known); for a solution recorded before it carried its
/// covariance, the diagonal of its σ (type 2, diagonal known).
pub fn location_fix(nav: &NavSolution, unix_ns: u64) -> LocationFix {
    let (position_covariance, position_covariance_type) = if nav.has_pos_cov() {
        (covariance_enu_of_ned(&nav.pos_cov_ned_matrix_m2()), 3)
    } else {
        let [sn, se, sd] = nav.pos_sigma_ned_m;
        ([se * se, 0.0, 0.0, 0.0, sn * sn, 0.0, 0.0, 0.0, sd * sd], 2)
    };
    LocationFix {
        timestamp: Timestamp::from_unix_ns(unix_ns),
        frame_id: BODY_FRAME,
        latitude: nav.lat_rad.to_degrees(),
        longitude: nav.lon_rad.to_degrees(),
        altitude: nav.height_m,
        position_covariance,
        position_covariance_type,
    }
}

/// Rotation ECEF → NED at latitude/longitude (rows = north, east, down in ECEF).
pub fn c_n_e(lat_rad: f64, lon_rad: f64) -> [[f64; 3]; 3] {
    let (sl, cl) = lat_rad.sin_cos();
    let (so, co) = lon_rad.sin_cos();
    [
        [-sl * co, -sl * so, cl],
        [-so, co, 0.0],
        [-cl * co, -cl * so, -sl],
    ]
}

/// NED offset of ECEF point `r` from the origin `r0` (NED axes at latitude/longitude `lat0`,
/// `lon0`), m.
pub fn ned_offset(r0: [f64; 3], lat0: f64, lon0: f64, r: [f64; 3]) -> [f64; 3] {
    let d = [r[0] - r0[0], r[1] - r0[1], r[2] - r0[2]];
    let c = c_n_e(lat0, lon0);
    [
        c[0][0] * d[0] + c[0][1] * d[1] + c[0][2] * d[2],
        c[1][0] * d[0] + c[1][1] * d[1] + c[1][2] * d[2],
        c[2][0] * d[0] + c[2][1] * d[1] + c[2][2] * d[2],
    ]
}

/// Origin of the local NED frame: ECEF position, latitude, longitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NedOrigin {
    /// ECEF position, m.
    pub r_e: [f64; 3],
    /// Latitude, rad.
    pub lat_rad: f64,
    /// Longitude, rad.
    pub lon_rad: f64,
}

impl NedOrigin {
    /// The origin at a solution's position.
    pub fn at(nav: &NavSolution) -> Self {
        Self {
            r_e: nav.pos_ecef_m,
            lat_rad: nav.lat_rad,
            lon_rad: nav.lon_rad,
        }
    }
}

/// Pose of the body in the local NED frame with origin `origin`, stamped `unix_ns`.
pub fn pose_in_frame(nav: &NavSolution, origin: &NedOrigin, unix_ns: u64) -> PoseInFrame {
    let p = ned_offset(origin.r_e, origin.lat_rad, origin.lon_rad, nav.pos_ecef_m);
    let [w, x, y, z] = nav.q_ned_body;
    PoseInFrame {
        timestamp: Timestamp::from_unix_ns(unix_ns),
        frame_id: NED_FRAME,
        pose: Pose {
            position: Vector3 {
                x: p[0],
                y: p[1],
                z: p[2],
            },
            orientation: Quaternion { x, y, z, w },
        },
    }
}

const TIME_SCHEMA: &str = r#"{"type":"object","title":"time","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}}"#;

/// JSON Schema of `foxglove.LocationFix` (the fields we write).
pub fn location_fix_schema() -> String {
    format!(
        r#"{{"title":"foxglove.LocationFix","description":"A navigation satellite fix for any Global Navigation Satellite System","$comment":"Sextant: timestamp is Unix time (UTC) of validity","type":"object","properties":{{"timestamp":{TIME_SCHEMA},"frame_id":{{"type":"string"}},"latitude":{{"type":"number","description":"Latitude in degrees"}},"longitude":{{"type":"number","description":"Longitude in degrees"}},"altitude":{{"type":"number","description":"Altitude in meters"}},"position_covariance":{{"type":"array","items":{{"type":"number"}},"minItems":9,"maxItems":9,"description":"Position covariance (m^2), ENU, row-major"}},"position_covariance_type":{{"type":"integer","description":"0 unknown, 1 approximated, 2 diagonal known, 3 known","oneOf":[{{"title":"UNKNOWN","const":0}},{{"title":"APPROXIMATED","const":1}},{{"title":"DIAGONAL_KNOWN","const":2}},{{"title":"KNOWN","const":3}}]}}}}}}"#
    )
}

/// JSON Schema of `foxglove.FrameTransforms`.
pub fn frame_transforms_schema() -> String {
    let v3 = r#"{"type":"object","title":"foxglove.Vector3","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}}"#;
    let q = r#"{"type":"object","title":"foxglove.Quaternion","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}"#;
    format!(
        r#"{{"title":"foxglove.FrameTransforms","description":"An array of FrameTransform messages","$comment":"Sextant: ecef -> ned (origin: the first solution) -> body -> imu, star_tracker, gnss_antenna; timestamp is Unix time (UTC) of validity","type":"object","properties":{{"transforms":{{"type":"array","items":{{"title":"foxglove.FrameTransform","type":"object","properties":{{"timestamp":{TIME_SCHEMA},"parent_frame_id":{{"type":"string"}},"child_frame_id":{{"type":"string"}},"translation":{v3},"rotation":{q}}}}}}}}}}}"#
    )
}

/// JSON Schema of `sextant.StatusPlot`.
pub fn status_plot_schema() -> String {
    let mut schema = serde_json::to_value(schemars::schema_for!(StatusPlot)).unwrap_or_default();
    schema["title"] = STATUS_PLOT_SCHEMA.into();
    schema.to_string()
}

/// JSON Schema of `foxglove.PoseInFrame`.
pub fn pose_in_frame_schema() -> String {
    let v3 = r#"{"type":"object","title":"foxglove.Vector3","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}}"#;
    let q = r#"{"type":"object","title":"foxglove.Quaternion","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}"#;
    format!(
        r#"{{"title":"foxglove.PoseInFrame","description":"A timestamped pose for an object or reference frame in 3D space","$comment":"Sextant: body (x forward, y right, z down) in the local NED frame 'ned' whose origin is the first solution; timestamp is Unix time (UTC) of validity","type":"object","properties":{{"timestamp":{TIME_SCHEMA},"frame_id":{{"type":"string"}},"pose":{{"type":"object","title":"foxglove.Pose","properties":{{"position":{v3},"orientation":{q}}}}}}}}}"#
    )
}

#[cfg(test)]
#[allow(clippy::field_reassign_with_default)]
mod tests {
    use super::*;

    #[test]
    fn schemas_are_json_and_messages_validate() {
        let mut nav = NavSolution::default();
        nav.header.time_ns = 1_500_000_000_250_000_000;
        let t = crate::recorder::log_time_of(nav.header.time_ns).unwrap();
        nav.lat_rad = 0.5;
        nav.lon_rad = 0.1;
        nav.q_ned_body = [1.0, 0.0, 0.0, 0.0];
        nav.pos_sigma_ned_m = [1.0, 2.0, 3.0];
        for (schema, msg) in [
            (
                location_fix_schema(),
                serde_json::to_value(location_fix(&nav, t)).unwrap(),
            ),
            (
                pose_in_frame_schema(),
                serde_json::to_value(pose_in_frame(&nav, &NedOrigin::at(&nav), t)).unwrap(),
            ),
        ] {
            let s: serde_json::Value = serde_json::from_str(&schema).unwrap();
            let v = jsonschema::validator_for(&s).unwrap();
            assert!(v.is_valid(&msg), "{msg}");
        }
        let fix = location_fix(&nav, t);
        assert_eq!(fix.position_covariance[0], 4.0); // east
        assert_eq!(fix.position_covariance[4], 1.0); // north
        assert_eq!(fix.timestamp.nsec, 250_000_000);
    }

    /// The ENU covariance is the NED one rotated, C·P·Cᵀ, computed here with nalgebra from
    /// the frames' axes for a non-diagonal P (a horizontal error ellipse at 30° from north,
    /// correlated with height); and the variance along a direction is the same in both frames.
    #[test]
    fn location_fix_carries_the_full_covariance_rotated_into_enu() {
        // Horizontal ellipse: σ 3 m along the axis at 30° from north towards east, 1 m
        // across it; down correlated with north.
        let (a, s1, s2) = (30f64.to_radians(), 3.0, 1.0);
        let r = Matrix3::new(a.cos(), -a.sin(), 0.0, a.sin(), a.cos(), 0.0, 0.0, 0.0, 1.0);
        let mut p_ned = r * Matrix3::from_diagonal(&V3::new(s1 * s1, s2 * s2, 4.0)) * r.transpose();
        p_ned[(0, 2)] = 0.7;
        p_ned[(2, 0)] = 0.7;
        let mut nav = NavSolution::default();
        nav.set_pos_cov_ned_m2(&[0, 1, 2].map(|i| [0, 1, 2].map(|j| p_ned[(i, j)])));
        nav.pos_sigma_ned_m = [0, 1, 2].map(|i| p_ned[(i, i)].sqrt());
        let fix = location_fix(&nav, 0);
        assert_eq!(fix.position_covariance_type, 3);
        // ENU axes expressed in NED: east = NED y, north = NED x, up = −NED z.
        let (e, n, u) = (
            V3::new(0.0, 1.0, 0.0),
            V3::new(1.0, 0.0, 0.0),
            V3::new(0.0, 0.0, -1.0),
        );
        let c_enu_ned = Matrix3::from_rows(&[e.transpose(), n.transpose(), u.transpose()]);
        let p_ned_stored = Matrix3::from_fn(|i, j| nav.pos_cov_ned_matrix_m2()[i][j]);
        let expected = c_enu_ned * p_ned_stored * c_enu_ned.transpose();
        let got = Matrix3::from_row_slice(&fix.position_covariance);
        assert_eq!(got, expected);
        assert!(
            got[(0, 1)].abs() > 1.0,
            "the ellipse's EN correlation: {got}"
        );
        assert_eq!(got[(1, 2)], -0.7); // north–up = −(north–down)
        // Variance along the ellipse's major axis, in each frame: 9 m².
        let major_ned = V3::new(a.cos(), a.sin(), 0.0);
        let major_enu = c_enu_ned * major_ned;
        let v_ned = (major_ned.transpose() * p_ned_stored * major_ned)[0];
        let v_enu = (major_enu.transpose() * got * major_enu)[0];
        assert!((v_ned - 9.0).abs() < 1e-12 && (v_enu - v_ned).abs() < 1e-12);
        // A solution recorded before the covariance was carried: its σ on the diagonal.
        nav.pos_cov_ned_m2 = [0.0; 6];
        let old = location_fix(&nav, 0);
        assert_eq!(old.position_covariance_type, 2);
        assert_eq!(old.position_covariance[0], p_ned[(1, 1)].sqrt().powi(2));
    }

    fn rotate(q: &Quaternion, v: [f64; 3]) -> [f64; 3] {
        let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            q.w, q.x, q.y, q.z,
        ));
        let r = q * V3::from(v);
        [r.x, r.y, r.z]
    }

    /// Walking the tree from `body` up to `ecef` lands on the solution's ECEF position, and the
    /// star tracker's optical axis (sensor z) points up for a level vehicle (nominal mount,
    /// κ = 0): the transforms follow Foxglove's child-to-parent rule.
    #[test]
    fn frame_tree_composes_to_the_solution_and_the_tracker_looks_up() {
        let ell = fusion::earth::WGS84;
        let g0 = fusion::earth::Geodetic {
            lat_rad: 55.655_f64.to_radians(),
            lon_rad: 37.6_f64.to_radians(),
            height_m: 200.0,
        };
        let r0 = fusion::earth::geodetic_to_ecef(&ell, &g0);
        let origin = NedOrigin {
            r_e: [r0.x, r0.y, r0.z],
            lat_rad: g0.lat_rad,
            lon_rad: g0.lon_rad,
        };
        let mut nav = NavSolution::default();
        let g = fusion::earth::Geodetic {
            lat_rad: g0.lat_rad + 1e-4,
            lon_rad: g0.lon_rad - 2e-4,
            height_m: 230.0,
        };
        let r = fusion::earth::geodetic_to_ecef(&ell, &g);
        nav.pos_ecef_m = [r.x, r.y, r.z];
        nav.q_ned_body = [1.0, 0.0, 0.0, 0.0];
        // A level vehicle heading east (90° about down): body x = east, y = south.
        let h = std::f64::consts::FRAC_PI_4;
        nav.q_ned_body = [h.cos(), 0.0, 0.0, h.sin()];
        let mounts = SensorMounts {
            gnss_lever_arm_b_m: [0.3, 0.2, -1.5],
        };
        let tf = frame_transforms(&nav, &origin, &mounts, 1);
        let (e_n, n_b, b_s, b_a) = (
            &tf.transforms[0],
            &tf.transforms[1],
            &tf.transforms[3],
            &tf.transforms[4],
        );
        assert_eq!(b_a.child_frame_id, "gnss_antenna");
        // The antenna in ned: p + C_n_b·l = p + (north −0.2, east 0.3, down −1.5).
        let l_n = rotate(
            &n_b.rotation,
            [b_a.translation.x, b_a.translation.y, b_a.translation.z],
        );
        for (got, want) in l_n.iter().zip([-0.2, 0.3, -1.5]) {
            assert!((got - want).abs() < 1e-12, "{l_n:?}");
        }
        assert_eq!((e_n.parent_frame_id, e_n.child_frame_id), ("ecef", "ned"));
        assert_eq!((n_b.parent_frame_id, n_b.child_frame_id), ("ned", "body"));
        assert_eq!(b_s.child_frame_id, "star_tracker");
        // body origin in ned, then in ecef: r = r0 + C_e_n · p_n. Exact up to rounding of
        // ~7e6 m coordinates (1e-9 relative): 1e-6 m.
        let p_n = [n_b.translation.x, n_b.translation.y, n_b.translation.z];
        let p_e = rotate(&e_n.rotation, p_n);
        for i in 0..3 {
            let got = [e_n.translation.x, e_n.translation.y, e_n.translation.z][i] + p_e[i];
            assert!((got - nav.pos_ecef_m[i]).abs() < 1e-6, "{i}: {got}");
        }
        // Sensor z in body, then in ned: up = (0, 0, −1) in NED.
        let z_n = rotate(&n_b.rotation, rotate(&b_s.rotation, [0.0, 0.0, 1.0]));
        assert!((z_n[2] + 1.0).abs() < 1e-12, "{z_n:?}");
    }

    #[test]
    fn ned_offset_points_north_and_down() {
        // At lat 0, lon 0: ECEF x is up, z is north, y is east.
        let r0 = [6_378_137.0, 0.0, 0.0];
        let d = ned_offset(r0, 0.0, 0.0, [6_378_137.0 - 1.0, 2.0, 3.0]);
        assert!(
            (d[0] - 3.0).abs() < 1e-12 && (d[1] - 2.0).abs() < 1e-12 && (d[2] - 1.0).abs() < 1e-12
        );
    }
}
