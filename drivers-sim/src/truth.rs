//! Truth trajectory: the same deterministic integration in every driver process.
//!
//! The motion is specified kinematically in geodetic/NED form (speed, heading, pitch, roll as
//! analytic functions of time with raised-cosine transitions). Position (lat, lon, h) is
//! integrated with RK4 on a fixed grid from t = 0 (1 ms, or finer where a sensor's period is
//! not a whole number of milliseconds: [`Scenario::truth_grid_ns`]), using the analytic NED
//! velocity and the WGS-84 radii of curvature; every quantity at a grid point is then computed
//! analytically: NED acceleration, body rate relative to NED from the Euler-angle rates, Earth
//! and transport rates, J2 gravity, specific force `f^n = a^n + (2ω_ie^n + ω_en^n)×v^n − g^n`,
//! and the inertial body rate `ω_ib^b = C_b_n(ω_ie^n + ω_en^n) + ω_nb^b`. The grid index is an integer and the
//! time of grid point k is `k·step` s computed the same way everywhere, so all processes follow
//! bit-identical floating-point paths without talking to each other.

use crate::scenario::{Scenario, Segment, TRUTH_GRID_NS, Trajectory};
use crate::world::MotionWorld;
use crate::world::vehicle::{Intent, VehicleFollower, VehicleState, VibrationFollower};
use fusion::attitude::c_n_b_from_rpy;
use fusion::earth::{self, Ellipsoid, Geodetic, GravityModel, WGS84};
use nalgebra::{Matrix3, Vector3};
use std::f64::consts::{PI, TAU};

/// Raised-cosine ramp: fraction completed `τ/T − sin(2πτ/T)/2π` and its rate (1/s), for
/// `0 ≤ τ ≤ T` (clamped outside). The rate `(1 − cos(2πτ/T))/T` is zero at both ends, so the
/// acceleration / turn rate it drives is continuous.
fn ramp(tau_s: f64, dur_s: f64) -> (f64, f64) {
    let x = (tau_s / dur_s).clamp(0.0, 1.0);
    let frac = x - (TAU * x).sin() / TAU;
    let rate = (1.0 - (TAU * x).cos()) / dur_s;
    (frac, rate)
}

/// Euler-angle kinematics of the body at one instant (z-y-x: heading, pitch, roll).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Kinematics {
    /// Speed along the velocity direction (horizontal heading, pitch), m/s.
    pub speed_m_s: f64,
    /// Time derivative of the speed, m/s².
    pub speed_rate_m_s2: f64,
    /// Heading of the body (unwrapped), rad.
    pub heading_rad: f64,
    /// Heading rate, rad/s.
    pub heading_rate_rad_s: f64,
    /// Pitch, rad.
    pub pitch_rad: f64,
    /// Pitch rate, rad/s.
    pub pitch_rate_rad_s: f64,
    /// Roll, rad.
    pub roll_rad: f64,
    /// Roll rate, rad/s.
    pub roll_rate_rad_s: f64,
    /// Turntable angle (already included in the attitude angles), rad.
    pub turntable_rad: f64,
}

#[derive(Debug, Clone, Copy)]
struct Piece {
    t0_s: f64,
    dur_s: f64,
    v0_m_s: f64,
    dv_m_s: f64,
    psi0_rad: f64,
    dpsi_rad: f64,
}

#[derive(Debug, Clone, Copy)]
struct TableMove {
    t0_s: f64,
    dur_s: f64,
    beta0_rad: f64,
    dbeta_rad: f64,
}

/// The kinematic profile of a scenario: analytic functions of time.
#[derive(Debug, Clone)]
pub enum Profile {
    /// Static body (possibly on a turntable).
    Static {
        /// Roll, rad.
        roll_rad: f64,
        /// Pitch, rad.
        pitch_rad: f64,
        /// Heading at turntable zero, rad.
        heading_rad: f64,
        /// Turntable moves.
        moves: Vec<TurntableMoveRad>,
    },
    /// Ground vehicle at zero pitch and roll.
    Vehicle {
        /// Pieces in time order.
        pieces: Vec<VehiclePiece>,
    },
    /// Fixed-wing aircraft with coordinated turns and flight-path-angle changes.
    Aircraft {
        /// Pieces in time order.
        pieces: Vec<AircraftPiece>,
    },
    /// A spline through a recorded reference trajectory.
    Reference(std::sync::Arc<crate::reference_trajectory::ReferenceTrajectory>),
}

/// An aircraft segment resolved to start time and the start/change of speed, heading and
/// pitch (SI). Exactly one of the changes is non-zero per piece.
#[derive(Debug, Clone, Copy)]
pub struct AircraftPiece {
    t0_s: f64,
    dur_s: f64,
    v0_m_s: f64,
    dv_m_s: f64,
    psi0_rad: f64,
    dpsi_rad: f64,
    theta0_rad: f64,
    dtheta_rad: f64,
}

/// Standard gravity for the coordinated-turn bank, m/s².
const G0_BANK_M_S2: f64 = 9.806_65;

impl AircraftPiece {
    fn kinematics(&self, t_s: f64) -> Kinematics {
        if self.dur_s.is_infinite() {
            return Kinematics {
                speed_m_s: self.v0_m_s,
                heading_rad: self.psi0_rad,
                pitch_rad: self.theta0_rad,
                ..Default::default()
            };
        }
        let (frac, rate) = ramp(t_s - self.t0_s, self.dur_s);
        // d(rate)/dt of the raised cosine: 2π sin(2πx)/T².
        let x = ((t_s - self.t0_s) / self.dur_s).clamp(0.0, 1.0);
        let rate_dot = TAU * (TAU * x).sin() / (self.dur_s * self.dur_s);
        let speed = self.v0_m_s + self.dv_m_s * frac;
        let psi_dot = self.dpsi_rad * rate;
        let psi_ddot = self.dpsi_rad * rate_dot;
        // Coordinated turn: φ = atan(k ψ̇), k = V/g (V constant while turning), so
        // φ̇ = k ψ̈ / (1 + (k ψ̇)²).
        let k = speed / G0_BANK_M_S2;
        let roll = (k * psi_dot).atan();
        let roll_rate = k * psi_ddot / (1.0 + (k * psi_dot).powi(2));
        Kinematics {
            speed_m_s: speed,
            speed_rate_m_s2: self.dv_m_s * rate,
            heading_rad: self.psi0_rad + self.dpsi_rad * frac,
            heading_rate_rad_s: psi_dot,
            pitch_rad: self.theta0_rad + self.dtheta_rad * frac,
            pitch_rate_rad_s: self.dtheta_rad * rate,
            roll_rad: roll,
            roll_rate_rad_s: roll_rate,
            turntable_rad: 0.0,
        }
    }
}

/// A turntable move in SI units (see [`crate::scenario::TurntableMove`]).
#[derive(Debug, Clone, Copy)]
pub struct TurntableMoveRad(TableMove);

/// A ground-vehicle segment resolved to start time, speeds and headings (SI).
#[derive(Debug, Clone, Copy)]
pub struct VehiclePiece(Piece);

impl Profile {
    /// Build the profile of a validated scenario.
    pub fn new(scn: &Scenario) -> Self {
        match &scn.spec.trajectory {
            Trajectory::Static(st) => {
                let mut beta = 0.0;
                let moves = st
                    .turntable
                    .iter()
                    .map(|m| {
                        let to = m.to_deg.to_radians();
                        let mv = TableMove {
                            t0_s: m.start_s,
                            dur_s: m.duration_s,
                            beta0_rad: beta,
                            dbeta_rad: to - beta,
                        };
                        beta = to;
                        TurntableMoveRad(mv)
                    })
                    .collect();
                Profile::Static {
                    roll_rad: st.roll_deg.to_radians(),
                    pitch_rad: st.pitch_deg.to_radians(),
                    heading_rad: st.heading_deg.to_radians(),
                    moves,
                }
            }
            Trajectory::GroundVehicle(gv) => {
                let mut t = 0.0;
                let mut v = 0.0;
                let mut psi = gv.initial_heading_deg.to_radians();
                let mut pieces = Vec::with_capacity(gv.segments.len());
                for seg in &gv.segments {
                    let dur = seg.duration_s();
                    let (dv, dpsi) = match *seg {
                        Segment::Speed { to_m_s, .. } => (to_m_s - v, 0.0),
                        Segment::Turn { angle_deg, .. } => (0.0, angle_deg.to_radians()),
                        // Validation refuses a ground vehicle's `pitch`.
                        Segment::Hold { .. } | Segment::Cruise { .. } | Segment::Pitch { .. } => {
                            (0.0, 0.0)
                        }
                    };
                    pieces.push(VehiclePiece(Piece {
                        t0_s: t,
                        dur_s: dur,
                        v0_m_s: v,
                        dv_m_s: dv,
                        psi0_rad: psi,
                        dpsi_rad: dpsi,
                    }));
                    t += dur;
                    v += dv;
                    psi += dpsi;
                }
                // Terminal piece: keep the final speed and heading forever.
                pieces.push(VehiclePiece(Piece {
                    t0_s: t,
                    dur_s: f64::INFINITY,
                    v0_m_s: v,
                    dv_m_s: 0.0,
                    psi0_rad: psi,
                    dpsi_rad: 0.0,
                }));
                Profile::Vehicle { pieces }
            }
            Trajectory::Aircraft(ac) => {
                let mut t = 0.0;
                let (mut v, mut th) = (0.0, 0.0);
                let mut psi = ac.initial_heading_deg.to_radians();
                let mut pieces = Vec::with_capacity(ac.segments.len() + 1);
                for seg in &ac.segments {
                    let dur = seg.duration_s();
                    let (dv, dpsi, dth) = match *seg {
                        Segment::Speed { to_m_s, .. } => (to_m_s - v, 0.0, 0.0),
                        Segment::Turn { angle_deg, .. } => (0.0, angle_deg.to_radians(), 0.0),
                        Segment::Pitch { to_deg, .. } => (0.0, 0.0, to_deg.to_radians() - th),
                        Segment::Hold { .. } | Segment::Cruise { .. } => (0.0, 0.0, 0.0),
                    };
                    pieces.push(AircraftPiece {
                        t0_s: t,
                        dur_s: dur,
                        v0_m_s: v,
                        dv_m_s: dv,
                        psi0_rad: psi,
                        dpsi_rad: dpsi,
                        theta0_rad: th,
                        dtheta_rad: dth,
                    });
                    t += dur;
                    v += dv;
                    psi += dpsi;
                    th += dth;
                }
                pieces.push(AircraftPiece {
                    t0_s: t,
                    dur_s: f64::INFINITY,
                    v0_m_s: v,
                    dv_m_s: 0.0,
                    psi0_rad: psi,
                    dpsi_rad: 0.0,
                    theta0_rad: th,
                    dtheta_rad: 0.0,
                });
                Profile::Aircraft { pieces }
            }
            Trajectory::Reference(r) => match &r.spline {
                Some(spline) => Profile::Reference(spline.clone()),
                // Scenario::validate builds the spline; an unvalidated spec stands still.
                None => Profile::Static {
                    roll_rad: 0.0,
                    pitch_rad: 0.0,
                    heading_rad: 0.0,
                    moves: Vec::new(),
                },
            },
        }
    }

    /// Kinematics at time `t_s` since the epoch.
    pub fn at(&self, t_s: f64) -> Kinematics {
        match self {
            Profile::Static {
                roll_rad,
                pitch_rad,
                heading_rad,
                moves,
            } => {
                let (mut beta, mut beta_rate) = (0.0, 0.0);
                for TurntableMoveRad(m) in moves {
                    if t_s < m.t0_s {
                        break;
                    }
                    let (frac, rate) = ramp(t_s - m.t0_s, m.dur_s);
                    beta = m.beta0_rad + m.dbeta_rad * frac;
                    beta_rate = if t_s <= m.t0_s + m.dur_s {
                        m.dbeta_rad * rate
                    } else {
                        0.0
                    };
                }
                turntable_kinematics(*roll_rad, *pitch_rad, *heading_rad, beta, beta_rate)
            }
            Profile::Vehicle { pieces } => {
                let i = pieces
                    .partition_point(|VehiclePiece(p)| p.t0_s <= t_s)
                    .saturating_sub(1);
                let p = pieces[i].0;
                if p.dur_s.is_infinite() {
                    return Kinematics {
                        speed_m_s: p.v0_m_s,
                        heading_rad: p.psi0_rad,
                        ..Default::default()
                    };
                }
                let (frac, rate) = ramp(t_s - p.t0_s, p.dur_s);
                Kinematics {
                    speed_m_s: p.v0_m_s + p.dv_m_s * frac,
                    speed_rate_m_s2: p.dv_m_s * rate,
                    heading_rad: p.psi0_rad + p.dpsi_rad * frac,
                    heading_rate_rad_s: p.dpsi_rad * rate,
                    ..Default::default()
                }
            }
            Profile::Aircraft { pieces } => {
                let i = pieces.partition_point(|p| p.t0_s <= t_s).saturating_sub(1);
                pieces[i].kinematics(t_s)
            }
            Profile::Reference(spline) => spline.kinematics(t_s),
        }
    }
}

/// Kinematics of a body on a turntable whose axis is the body z axis (the table top carries
/// the IMU square; roll and pitch are the tilt of the table, heading its zero direction):
/// `C_n_b(β) = C_n_b0 · R_z(β)`, so the body rate relative to NED is exactly `(0, 0, β̇)` in
/// body axes. With a level table this is a pure heading change `ψ0 + β`; with a tilted table
/// all three Euler angles vary, and a 0°/180° indexing reverses the horizontal body axes
/// (paper 003: the half-differences of the horizontal sensors then cancel their biases).
/// The Euler rates are the exact inverse of [`w_nb_b`] for that body rate:
/// `φ̇ = β̇ cos φ tan θ`, `θ̇ = −β̇ sin φ`, `ψ̇ = β̇ cos φ / cos θ`.
fn turntable_kinematics(
    roll0: f64,
    pitch0: f64,
    heading0: f64,
    beta_rad: f64,
    beta_rate_rad_s: f64,
) -> Kinematics {
    let (roll, pitch, heading) = if beta_rad == 0.0 {
        (roll0, pitch0, heading0)
    } else {
        let (sb, cb) = beta_rad.sin_cos();
        let r_z = Matrix3::new(cb, -sb, 0.0, sb, cb, 0.0, 0.0, 0.0, 1.0);
        let c = c_n_b_from_rpy(roll0, pitch0, heading0) * r_z;
        let roll = c[(2, 1)].atan2(c[(2, 2)]);
        let pitch = -c[(2, 0)].clamp(-1.0, 1.0).asin();
        // Heading unwrapped around ψ0 + β so that it is continuous through the move.
        let h = c[(1, 0)].atan2(c[(0, 0)]);
        let nominal = heading0 + beta_rad;
        (roll, pitch, nominal + wrap_pi(h - nominal))
    };
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    Kinematics {
        heading_rad: heading,
        heading_rate_rad_s: beta_rate_rad_s * cr / cp,
        pitch_rad: pitch,
        pitch_rate_rad_s: -beta_rate_rad_s * sr,
        roll_rad: roll,
        roll_rate_rad_s: beta_rate_rad_s * cr * sp / cp,
        turntable_rad: beta_rad,
        ..Default::default()
    }
}

/// NED velocity of the kinematics (speed along heading/pitch), m/s.
fn v_ned(k: &Kinematics) -> Vector3<f64> {
    let (sp, cp) = k.pitch_rad.sin_cos();
    let (sh, ch) = k.heading_rad.sin_cos();
    if k.speed_m_s == 0.0 {
        return Vector3::zeros();
    }
    Vector3::new(
        k.speed_m_s * ch * cp,
        k.speed_m_s * sh * cp,
        -k.speed_m_s * sp,
    )
}

/// Time derivative of the NED velocity components, m/s².
fn a_ned(k: &Kinematics) -> Vector3<f64> {
    let (sp, cp) = k.pitch_rad.sin_cos();
    let (sh, ch) = k.heading_rad.sin_cos();
    let (s, sd, hd, pd) = (
        k.speed_m_s,
        k.speed_rate_m_s2,
        k.heading_rate_rad_s,
        k.pitch_rate_rad_s,
    );
    Vector3::new(
        sd * ch * cp - s * sh * cp * hd - s * ch * sp * pd,
        sd * sh * cp + s * ch * cp * hd - s * sh * sp * pd,
        -sd * sp - s * cp * pd,
    )
}

/// Body rate relative to NED in body axes from z-y-x Euler-angle rates, rad/s.
fn w_nb_b(k: &Kinematics) -> Vector3<f64> {
    let (sr, cr) = k.roll_rad.sin_cos();
    let (sp, cp) = k.pitch_rad.sin_cos();
    let (rd, pd, hd) = (k.roll_rate_rad_s, k.pitch_rate_rad_s, k.heading_rate_rad_s);
    Vector3::new(
        rd - hd * sp,
        pd * cr + hd * sr * cp,
        -pd * sr + hd * cr * cp,
    )
}

/// Wrap an angle to (−π, π].
pub fn wrap_pi(a: f64) -> f64 {
    let w = a.rem_euclid(TAU);
    if w > PI { w - TAU } else { w }
}

/// Everything true at one grid point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthPoint {
    /// Time since the scenario epoch, ns.
    pub t_ns: i64,
    /// Geodetic position (WGS-84).
    pub geodetic: Geodetic,
    /// Position, ECEF, m.
    pub r_e_m: Vector3<f64>,
    /// Velocity relative to the Earth in NED, m/s.
    pub v_ned_m_s: Vector3<f64>,
    /// Time derivative of the NED velocity components, m/s².
    pub a_ned_m_s2: Vector3<f64>,
    /// Roll, pitch, heading (heading wrapped to (−π, π]), rad.
    pub roll_pitch_heading_rad: Vector3<f64>,
    /// Body → NED DCM.
    pub c_n_b: Matrix3<f64>,
    /// NED → ECEF DCM at the current position.
    pub c_e_n: Matrix3<f64>,
    /// Inertial angular rate of the body in body axes, rad/s.
    pub w_ib_b_rad_s: Vector3<f64>,
    /// Specific force in body axes, m/s².
    pub f_b_m_s2: Vector3<f64>,
    /// Turntable angle, rad.
    pub turntable_rad: f64,
    /// Rolling speed of the odometer wheel, m/s: the body-x speed, or with
    /// `[world.vehicle]` the wheel's own (lever arm, slope, slip).
    pub odometer_speed_m_s: f64,
    /// Velocity of the IMU's mount vibration, body axes, m/s (zero without
    /// `[world.vibration]`).
    pub vibration_velocity_b_m_s: Vector3<f64>,
    /// Acceleration of the IMU's mount vibration (included in `f_b_m_s2`), body axes, m/s².
    pub vibration_accel_b_m_s2: Vector3<f64>,
}

impl TruthPoint {
    /// A strapdown started exactly on this point: the navigation state (WGS-84 position,
    /// NED velocity, body → NED attitude) and the finest mechanization (J2 gravity, RK4 with
    /// coning and sculling). Fed an error-free IMU it must follow the truth: the oracle of the
    /// simulator's motion against the navigation equations.
    pub fn reference_ins(&self) -> (fusion::strapdown::NavState, fusion::strapdown::Strapdown) {
        use fusion::strapdown::{Integrator, MechanizationConfig, NavState, Strapdown};
        use nalgebra::{Rotation3, UnitQuaternion};
        let q_n_b =
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(self.c_n_b));
        let state = NavState::from_geodetic(&WGS84, &self.geodetic, &self.v_ned_m_s, &q_n_b);
        let strapdown = Strapdown::new(MechanizationConfig {
            ellipsoid: WGS84,
            gravity: GravityModel::J2,
            integrator: Integrator::Rk4,
            coning_sculling: true,
        });
        (state, strapdown)
    }

    /// Velocity relative to the Earth in ECEF axes, m/s.
    pub fn v_e_m_s(&self) -> Vector3<f64> {
        self.c_e_n * self.v_ned_m_s
    }
    /// Body-x (forward) speed, m/s.
    pub fn forward_speed_m_s(&self) -> f64 {
        (self.c_n_b.transpose() * self.v_ned_m_s).x
    }
}

/// Integrals of the truth over one sample interval (trapezoid rule on the truth grid).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Increments {
    /// Interval, s.
    pub dt_s: f64,
    /// ∫ω_ib^b dt, rad.
    pub delta_angle_b_rad: Vector3<f64>,
    /// ∫f^b dt, m/s.
    pub delta_velocity_b_m_s: Vector3<f64>,
    /// ∫(body-x speed) dt, m.
    pub distance_x_m: f64,
    /// ∫(odometer wheel's rolling speed) dt, m: `distance_x_m` unless `[world.vehicle]`.
    pub odometer_distance_m: f64,
    /// `ω_ib^b(end) − ω_ib^b(start)` = ∫ω̇ dt, rad/s: the tangential part of the
    /// accelerometers' size effect.
    pub delta_rate_b_rad_s: Vector3<f64>,
    /// ∫ω_ib^b ω_ib^bᵀ dt, rad²/s: the centripetal part (`∫ω×(ω×r) dt = (W − tr W·I) r`).
    pub rate_outer_b_rad2_s: Matrix3<f64>,
}

/// Steps the truth along its grid.
#[derive(Debug, Clone)]
pub struct TruthGenerator {
    /// Grid step, ns.
    grid_ns: i64,
    profile: Profile,
    ell: Ellipsoid,
    world: MotionWorld,
    site: Geodetic,
    k: i64,
    lat_rad: f64,
    lon_rad: f64,
    height_m: f64,
    /// Horizontal distance driven, m (the argument of the world's road).
    distance_m: f64,
    point: TruthPoint,
    acc: Increments,
    /// The profile at the current grid point's time (the next step's first RK4 stage).
    profile_now: ProfileAt,
    /// The world's road, body and vibration processes at the current grid point.
    followers: Followers,
}

/// The motion world's processes followed along the grid (`world::spectral::Follower`): the
/// world's sums cost a rotation per term and step instead of a sine and a cosine.
#[derive(Debug, Clone, Copy, Default)]
struct Followers {
    vehicle: Option<VehicleFollower>,
    vibration: Option<VibrationFollower>,
}

/// The profile's kinematics at one time with its horizontal velocity, evaluated once per
/// distinct time of a step: RK4 evaluates the rates at the step's start, twice at its middle
/// and at its end, and the end is the next step's start and the next grid point. The profile
/// is a pure function of time, so reusing it changes no result; it saves most of the
/// trigonometry of the truth, which dominates the cost of a simulation.
#[derive(Debug, Clone, Copy)]
struct ProfileAt {
    kin: Kinematics,
    /// (sin, cos) of the heading.
    heading_sin_cos: (f64, f64),
    /// The profile's own NED velocity (flat road), m/s.
    v_ned_m_s: Vector3<f64>,
}

impl ProfileAt {
    fn of(profile: &Profile, t_s: f64) -> Self {
        let kin = profile.at(t_s);
        Self {
            kin,
            heading_sin_cos: kin.heading_rad.sin_cos(),
            v_ned_m_s: v_ned(&kin),
        }
    }
}

/// Step of the central differences that give the driver intent's second derivatives (V̈, ψ̈)
/// to the world's vehicle, s: the profile's raised-cosine pieces make the truncation error
/// `ε²/6·|x⁗|` below 1e-10 of the value.
const INTENT_FD_STEP_S: f64 = 1e-4;

impl TruthGenerator {
    /// Start at grid point 0 of the scenario, on its grid ([`Scenario::truth_grid_ns`]).
    pub fn new(scn: &Scenario) -> Self {
        let world = MotionWorld::new(scn.spec.world.as_ref(), scn.spec.scenario.seed);
        Self::on_grid(Profile::new(scn), scn.spec.site, world, scn.truth_grid_ns())
    }

    /// Start at grid point 0 of `profile` from the geodetic point `s`.
    pub fn from_profile(profile: Profile, s: crate::scenario::Site) -> Self {
        Self::from_profile_in_world(profile, s, MotionWorld::default())
    }

    /// Start at grid point 0 of `profile` from the geodetic point `s` in the motion `world`, on
    /// the 1 ms grid.
    pub fn from_profile_in_world(
        profile: Profile,
        s: crate::scenario::Site,
        world: MotionWorld,
    ) -> Self {
        Self::on_grid(profile, s, world, TRUTH_GRID_NS)
    }

    /// [`Self::from_profile_in_world`] on a grid of `grid_ns` ns (a divisor of 1 ms).
    fn on_grid(
        profile: Profile,
        s: crate::scenario::Site,
        world: MotionWorld,
        grid_ns: i64,
    ) -> Self {
        let grid_s = grid_ns as f64 * 1e-9;
        let ell = WGS84;
        let lat = s.lat_deg.to_radians();
        let lon = s.lon_deg.to_radians();
        let site = Geodetic {
            lat_rad: lat,
            lon_rad: lon,
            height_m: s.height_m,
        };
        let profile_now = ProfileAt::of(&profile, 0.0);
        let followers = Followers {
            vehicle: world
                .vehicle
                .as_ref()
                .map(|v| v.follower(0.0, 0.0, Some(grid_s))),
            vibration: world
                .vibration
                .as_ref()
                .map(|v| v.follower(0.0, Some(grid_s))),
        };
        let mut g = Self {
            grid_ns,
            profile,
            ell,
            world,
            site,
            k: 0,
            lat_rad: lat,
            lon_rad: lon,
            height_m: s.height_m,
            distance_m: 0.0,
            point: TruthPoint {
                t_ns: 0,
                geodetic: site,
                r_e_m: Vector3::zeros(),
                v_ned_m_s: Vector3::zeros(),
                a_ned_m_s2: Vector3::zeros(),
                roll_pitch_heading_rad: Vector3::zeros(),
                c_n_b: Matrix3::identity(),
                c_e_n: Matrix3::identity(),
                w_ib_b_rad_s: Vector3::zeros(),
                f_b_m_s2: Vector3::zeros(),
                turntable_rad: 0.0,
                odometer_speed_m_s: 0.0,
                vibration_velocity_b_m_s: Vector3::zeros(),
                vibration_accel_b_m_s2: Vector3::zeros(),
            },
            acc: Increments::default(),
            profile_now,
            followers,
        };
        g.point = g.point_at(0, &g.profile_now.kin, lat, lon, s.height_m, 0.0);
        g
    }

    /// The motion world the truth runs in.
    pub fn world(&self) -> &MotionWorld {
        &self.world
    }

    /// Horizontal distance driven since t = 0, m.
    pub fn distance_m(&self) -> f64 {
        self.distance_m
    }

    /// The truth at the current grid point.
    pub fn current(&self) -> &TruthPoint {
        &self.point
    }

    /// Grid step, ns.
    pub fn grid_ns(&self) -> i64 {
        self.grid_ns
    }

    fn t_of(&self, k: i64) -> f64 {
        k as f64 * (self.grid_ns as f64 * 1e-9)
    }

    /// Rates of (lat, lon, h, distance) for the profile `p` at a time, position and distance
    /// driven `s_m`, rad/s, rad/s, m/s, m/s.
    fn pos_rate(&self, p: &ProfileAt, lat: f64, h: f64, s_m: f64) -> [f64; 4] {
        let kin = &p.kin;
        let v = match (&self.world.vehicle, &self.followers.vehicle) {
            (Some(veh), Some(f)) => {
                let (sn, cs) = p.heading_sin_cos;
                let vh = kin.speed_m_s;
                Vector3::new(vh * cs, vh * sn, -vh * veh.slope_near(f, s_m))
            }
            _ => p.v_ned_m_s,
        };
        let (r_n, r_e) = earth::radii_of_curvature(&self.ell, lat);
        [
            v.x / (r_n + h),
            v.y / ((r_e + h) * lat.cos()),
            -v.z,
            kin.speed_m_s,
        ]
    }

    /// The vehicle's state at `t_s`, where `f` stands (the driver's intent with its second
    /// derivatives by central differences of the analytic profile).
    fn vehicle_state(
        &self,
        veh: &crate::world::vehicle::VehicleWorld,
        f: &VehicleFollower,
        t_s: f64,
        kin: &Kinematics,
        s_m: f64,
    ) -> VehicleState {
        let e = INTENT_FD_STEP_S;
        let (km, kp) = (self.profile.at(t_s - e), self.profile.at(t_s + e));
        let intent = Intent {
            distance_m: s_m,
            speed: [
                kin.speed_m_s,
                kin.speed_rate_m_s2,
                (kp.speed_rate_m_s2 - km.speed_rate_m_s2) / (2.0 * e),
            ],
            course: [
                kin.heading_rad,
                kin.heading_rate_rad_s,
                (kp.heading_rate_rad_s - km.heading_rate_rad_s) / (2.0 * e),
            ],
        };
        veh.state_followed(f, &intent)
    }

    /// The truth at grid point `k`, whose profile kinematics are `kin` (the followers stand
    /// at its time and distance `s_m`).
    fn point_at(
        &self,
        k: i64,
        kin: &Kinematics,
        lat: f64,
        lon: f64,
        h: f64,
        s_m: f64,
    ) -> TruthPoint {
        let ell = &self.ell;
        let t = self.t_of(k);
        let mut kin = *kin;
        let mut geo = Geodetic {
            lat_rad: lat,
            lon_rad: lon,
            height_m: h,
        };
        let mut v = v_ned(&kin);
        let mut a = a_ned(&kin);
        let mut odometer_speed = None;
        let mut vib = [Vector3::zeros(); 3];
        let w = &self.world;
        if w.vehicle.is_some() || w.vibration.is_some() {
            // The IMU is offset from the integrated (road) point by the ride heave and the
            // mount vibration; the offset's own rate and acceleration join the velocity and
            // acceleration (the body's rotation of the µm-sized vibration offset is neglected).
            let mut off = [Vector3::zeros(); 3];
            if let (Some(veh), Some(f)) = (&w.vehicle, &self.followers.vehicle) {
                let st = self.vehicle_state(veh, f, t, &kin, s_m);
                kin = st.kinematics;
                v = st.v_road_ned_m_s;
                a = st.a_road_ned_m_s2;
                for (o, z) in off.iter_mut().zip(st.heave_up) {
                    o.z -= z;
                }
                odometer_speed = Some(st.odometer_speed_m_s);
            }
            if let (Some(vibration), Some(f)) = (&w.vibration, &self.followers.vibration) {
                let c_n_b = c_n_b_from_rpy(kin.roll_rad, kin.pitch_rad, kin.heading_rad);
                vib = vibration.at_followed(f);
                for (o, x) in off.iter_mut().zip(&vib) {
                    *o += c_n_b * x;
                }
            }
            let (r_n, r_e) = earth::radii_of_curvature(ell, lat);
            geo = Geodetic {
                lat_rad: lat + off[0].x / (r_n + h),
                lon_rad: lon + off[0].y / ((r_e + h) * lat.cos()),
                height_m: h - off[0].z,
            };
            v += off[1];
            a += off[2];
        }
        let lat = geo.lat_rad;
        let c_n_b = c_n_b_from_rpy(kin.roll_rad, kin.pitch_rad, kin.heading_rad);
        let c_b_n = c_n_b.transpose();
        let w_ie_n = Vector3::new(
            ell.omega_ie_rad_s * lat.cos(),
            0.0,
            -ell.omega_ie_rad_s * lat.sin(),
        );
        let w_en_n = earth::transport_rate_n(ell, &geo, &v);
        let r_e = earth::geodetic_to_ecef(ell, &geo);
        let c_e_n = earth::c_e_n(geo.lat_rad, geo.lon_rad);
        let mut g_n = c_e_n.transpose() * earth::gravity_ecef(ell, GravityModel::J2, &r_e);
        if let Some(field) = &w.gravity {
            let (r_n, r_e0) = earth::radii_of_curvature(ell, self.site.lat_rad);
            let s0 = &self.site;
            g_n += field.disturbance_ned_m_s2(
                (geo.lat_rad - s0.lat_rad) * (r_n + s0.height_m),
                wrap_pi(geo.lon_rad - s0.lon_rad) * (r_e0 + s0.height_m) * s0.lat_rad.cos(),
                geo.height_m - s0.height_m,
            );
        }
        let f_n = a + (2.0 * w_ie_n + w_en_n).cross(&v) - g_n;
        TruthPoint {
            t_ns: k * self.grid_ns,
            geodetic: geo,
            r_e_m: r_e,
            v_ned_m_s: v,
            a_ned_m_s2: a,
            roll_pitch_heading_rad: Vector3::new(
                kin.roll_rad,
                kin.pitch_rad,
                wrap_pi(kin.heading_rad),
            ),
            c_n_b,
            c_e_n,
            w_ib_b_rad_s: c_b_n * (w_ie_n + w_en_n) + w_nb_b(&kin),
            f_b_m_s2: c_b_n * f_n,
            turntable_rad: kin.turntable_rad,
            odometer_speed_m_s: odometer_speed.unwrap_or_else(|| (c_b_n * v).x),
            vibration_velocity_b_m_s: vib[1],
            vibration_accel_b_m_s2: vib[2],
        }
    }

    /// Advance one grid step (RK4 on lat, lon, h and distance), accumulating the interval
    /// integrals.
    pub fn step(&mut self) {
        let t0 = self.t_of(self.k);
        let t1 = self.t_of(self.k + 1);
        let h = t1 - t0;
        let tm = t0 + 0.5 * h;
        let (lat, lon, hh, s) = (self.lat_rad, self.lon_rad, self.height_m, self.distance_m);
        let (p0, pm, p1) = (
            self.profile_now,
            ProfileAt::of(&self.profile, tm),
            ProfileAt::of(&self.profile, t1),
        );
        let k1 = self.pos_rate(&p0, lat, hh, s);
        let k2 = self.pos_rate(
            &pm,
            lat + 0.5 * h * k1[0],
            hh + 0.5 * h * k1[2],
            s + 0.5 * h * k1[3],
        );
        let k3 = self.pos_rate(
            &pm,
            lat + 0.5 * h * k2[0],
            hh + 0.5 * h * k2[2],
            s + 0.5 * h * k2[3],
        );
        let k4 = self.pos_rate(&p1, lat + h * k3[0], hh + h * k3[2], s + h * k3[3]);
        self.profile_now = p1;
        let d = |i: usize| h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        self.lat_rad = lat + d(0);
        self.lon_rad = lon + d(1);
        self.height_m = hh + d(2);
        self.distance_m = s + d(3);
        self.k += 1;
        if let (Some(veh), Some(f)) = (&self.world.vehicle, &mut self.followers.vehicle) {
            veh.move_to(f, t1, self.distance_m);
        }
        if let (Some(vib), Some(f)) = (&self.world.vibration, &mut self.followers.vibration) {
            vib.move_to(f, t1);
        }
        let next = self.point_at(
            self.k,
            &p1.kin,
            self.lat_rad,
            self.lon_rad,
            self.height_m,
            self.distance_m,
        );
        let prev = &self.point;
        self.acc.dt_s += h;
        self.acc.delta_angle_b_rad += 0.5 * h * (prev.w_ib_b_rad_s + next.w_ib_b_rad_s);
        self.acc.delta_rate_b_rad_s += next.w_ib_b_rad_s - prev.w_ib_b_rad_s;
        self.acc.rate_outer_b_rad2_s += 0.5
            * h
            * (prev.w_ib_b_rad_s * prev.w_ib_b_rad_s.transpose()
                + next.w_ib_b_rad_s * next.w_ib_b_rad_s.transpose());
        if self.world.vibration.is_some() {
            // The vibration's integral is exact (its velocity's change), the trapezoid would
            // misstate lines near the grid's Nyquist frequency.
            self.acc.delta_velocity_b_m_s += 0.5
                * h
                * (prev.f_b_m_s2 - prev.vibration_accel_b_m_s2 + next.f_b_m_s2
                    - next.vibration_accel_b_m_s2)
                + (next.vibration_velocity_b_m_s - prev.vibration_velocity_b_m_s);
        } else {
            self.acc.delta_velocity_b_m_s += 0.5 * h * (prev.f_b_m_s2 + next.f_b_m_s2);
        }
        self.acc.distance_x_m += 0.5 * h * (prev.forward_speed_m_s() + next.forward_speed_m_s());
        self.acc.odometer_distance_m +=
            0.5 * h * (prev.odometer_speed_m_s + next.odometer_speed_m_s);
        self.point = next;
    }

    /// Advance to the grid point at `t_ns` (a multiple of the grid step, not before the current
    /// point) and return the integrals since the previous call (or since t = 0).
    pub fn advance_to(&mut self, t_ns: i64) -> Increments {
        let target = t_ns.div_euclid(self.grid_ns);
        while self.k < target {
            self.step();
        }
        std::mem::take(&mut self.acc)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_is_smooth_and_complete() {
        let (f0, r0) = ramp(0.0, 10.0);
        let (f1, r1) = ramp(10.0, 10.0);
        assert_eq!(f0, 0.0);
        assert!((f1 - 1.0).abs() < 1e-15);
        assert!(r0.abs() < 1e-15 && r1.abs() < 1e-15);
        // Numerical derivative of the fraction equals the rate.
        let (fa, _) = ramp(3.0, 10.0);
        let (fb, _) = ramp(3.0 + 1e-6, 10.0);
        let (_, r) = ramp(3.0 + 0.5e-6, 10.0);
        assert!(((fb - fa) / 1e-6 - r).abs() < 1e-8);
    }

    #[test]
    fn body_rate_from_euler_rates_matches_finite_difference() {
        let k0 = Kinematics {
            roll_rad: 0.1,
            pitch_rad: 0.2,
            heading_rad: 0.3,
            roll_rate_rad_s: 0.01,
            pitch_rate_rad_s: -0.02,
            heading_rate_rad_s: 0.03,
            ..Default::default()
        };
        let dt = 1e-6;
        let mut k1 = k0;
        k1.roll_rad += k0.roll_rate_rad_s * dt;
        k1.pitch_rad += k0.pitch_rate_rad_s * dt;
        k1.heading_rad += k0.heading_rate_rad_s * dt;
        let c0 = c_n_b_from_rpy(k0.roll_rad, k0.pitch_rad, k0.heading_rad);
        let c1 = c_n_b_from_rpy(k1.roll_rad, k1.pitch_rad, k1.heading_rad);
        // Ċ_n_b = C_n_b [ω_nb^b ×]  ⇒  [ω×] ≈ C_n_bᵀ (C1 − C0)/dt
        let w = c0.transpose() * (c1 - c0) / dt;
        let w_fd = Vector3::new(w[(2, 1)], w[(0, 2)], w[(1, 0)]);
        assert!(
            (w_fd - w_nb_b(&k0)).norm() < 1e-7,
            "{w_fd} vs {}",
            w_nb_b(&k0)
        );
    }
    /// A tilted turntable turns the body about its own z axis: C_n_b(β) = C_n_b0·R_z(β), the
    /// body rate relative to NED is (0, 0, β̇), and the truth generator's inertial rate is the
    /// Earth rate resolved in the rotated body plus that.
    #[test]
    fn tilted_turntable_rotates_about_body_z() {
        let (r0, p0, h0) = (0.02, -0.015, 0.4);
        let (beta, rate) = (1.1, 0.2);
        let k = turntable_kinematics(r0, p0, h0, beta, rate);
        let (sb, cb) = f64::sin_cos(beta);
        let r_z = Matrix3::new(cb, -sb, 0.0, sb, cb, 0.0, 0.0, 0.0, 1.0);
        let expect = c_n_b_from_rpy(r0, p0, h0) * r_z;
        let got = c_n_b_from_rpy(k.roll_rad, k.pitch_rad, k.heading_rad);
        assert!((got - expect).norm() < 1e-14, "{}", got - expect);
        assert!((w_nb_b(&k) - Vector3::new(0.0, 0.0, rate)).norm() < 1e-15);
        // At 180° the horizontal body axes are reversed in NED, the z axis is unchanged.
        let k = turntable_kinematics(r0, p0, h0, std::f64::consts::PI, 0.0);
        let c180 = c_n_b_from_rpy(k.roll_rad, k.pitch_rad, k.heading_rad);
        let c0 = c_n_b_from_rpy(r0, p0, h0);
        assert!((c180.column(0) + c0.column(0)).norm() < 1e-14);
        assert!((c180.column(1) + c0.column(1)).norm() < 1e-14);
        assert!((c180.column(2) - c0.column(2)).norm() < 1e-14);
        // Level table: a pure heading change.
        let k = turntable_kinematics(0.0, 0.0, h0, beta, rate);
        assert!(k.roll_rad.abs() < 1e-15 && k.pitch_rad.abs() < 1e-15);
        assert!((k.heading_rad - (h0 + beta)).abs() < 1e-14);
        assert!((k.heading_rate_rad_s - rate).abs() < 1e-15);
    }
}
