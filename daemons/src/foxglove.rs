//! The solution on Foxglove's well-known schemas (JSON encoding), so that Foxglove's Map and 3D
//! panels show it without configuration:
//! - topic `nav/location_fix`, schema `foxglove.LocationFix`: latitude/longitude in degrees,
//!   altitude in m above the WGS-84 ellipsoid, diagonal ENU position covariance (m²).
//! - topic `nav/pose`, schema `foxglove.PoseInFrame`: the body frame (x forward, y right,
//!   z down) in the local NED frame `ned` whose origin is the first recorded solution
//!   (position = NED offset from that origin, m; orientation = `q_ned_body`).
//!
//! Timestamps are GPS time (seconds and nanoseconds since 1980-01-06), like the MCAP log times.

use msgs::NavSolution;
use serde::Serialize;

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

/// Foxglove `time`.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Timestamp {
    /// Whole seconds.
    pub sec: u32,
    /// Nanoseconds, 0..1e9.
    pub nsec: u32,
}

impl Timestamp {
    /// From GPS ns (negative times clamp to 0).
    pub fn from_ns(ns: i64) -> Self {
        let ns = ns.max(0);
        Self {
            sec: u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
            nsec: (ns % 1_000_000_000) as u32,
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
    /// 2 = diagonal known.
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

/// LocationFix of a solution.
pub fn location_fix(nav: &NavSolution) -> LocationFix {
    let [sn, se, sd] = nav.pos_sigma_ned_m;
    LocationFix {
        timestamp: Timestamp::from_ns(nav.header.time_ns),
        frame_id: "body",
        latitude: nav.lat_rad.to_degrees(),
        longitude: nav.lon_rad.to_degrees(),
        altitude: nav.height_m,
        position_covariance: [se * se, 0.0, 0.0, 0.0, sn * sn, 0.0, 0.0, 0.0, sd * sd],
        position_covariance_type: 2,
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

/// Pose of the body in the local NED frame with origin `origin`.
pub fn pose_in_frame(nav: &NavSolution, origin: &NedOrigin) -> PoseInFrame {
    let p = ned_offset(origin.r_e, origin.lat_rad, origin.lon_rad, nav.pos_ecef_m);
    let [w, x, y, z] = nav.q_ned_body;
    PoseInFrame {
        timestamp: Timestamp::from_ns(nav.header.time_ns),
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
        r#"{{"title":"foxglove.LocationFix","description":"A navigation satellite fix for any Global Navigation Satellite System","$comment":"Sextant: timestamp is GPS time","type":"object","properties":{{"timestamp":{TIME_SCHEMA},"frame_id":{{"type":"string"}},"latitude":{{"type":"number","description":"Latitude in degrees"}},"longitude":{{"type":"number","description":"Longitude in degrees"}},"altitude":{{"type":"number","description":"Altitude in meters"}},"position_covariance":{{"type":"array","items":{{"type":"number"}},"minItems":9,"maxItems":9,"description":"Position covariance (m^2), ENU, row-major"}},"position_covariance_type":{{"type":"integer","description":"0 unknown, 1 approximated, 2 diagonal known, 3 known","oneOf":[{{"title":"UNKNOWN","const":0}},{{"title":"APPROXIMATED","const":1}},{{"title":"DIAGONAL_KNOWN","const":2}},{{"title":"KNOWN","const":3}}]}}}}}}"#
    )
}

/// JSON Schema of `foxglove.PoseInFrame`.
pub fn pose_in_frame_schema() -> String {
    let v3 = r#"{"type":"object","title":"foxglove.Vector3","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}}"#;
    let q = r#"{"type":"object","title":"foxglove.Quaternion","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}"#;
    format!(
        r#"{{"title":"foxglove.PoseInFrame","description":"A timestamped pose for an object or reference frame in 3D space","$comment":"Sextant: body (x forward, y right, z down) in the local NED frame 'ned' whose origin is the first solution; timestamp is GPS time","type":"object","properties":{{"timestamp":{TIME_SCHEMA},"frame_id":{{"type":"string"}},"pose":{{"type":"object","title":"foxglove.Pose","properties":{{"position":{v3},"orientation":{q}}}}}}}}}"#
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
        nav.lat_rad = 0.5;
        nav.lon_rad = 0.1;
        nav.q_ned_body = [1.0, 0.0, 0.0, 0.0];
        nav.pos_sigma_ned_m = [1.0, 2.0, 3.0];
        for (schema, msg) in [
            (
                location_fix_schema(),
                serde_json::to_value(location_fix(&nav)).unwrap(),
            ),
            (
                pose_in_frame_schema(),
                serde_json::to_value(pose_in_frame(&nav, &NedOrigin::at(&nav))).unwrap(),
            ),
        ] {
            let s: serde_json::Value = serde_json::from_str(&schema).unwrap();
            let v = jsonschema::validator_for(&s).unwrap();
            assert!(v.is_valid(&msg), "{msg}");
        }
        let fix = location_fix(&nav);
        assert_eq!(fix.position_covariance[0], 4.0); // east
        assert_eq!(fix.position_covariance[4], 1.0); // north
        assert_eq!(fix.timestamp.nsec, 250_000_000);
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
