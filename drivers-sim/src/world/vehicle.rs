//! Truth ground-vehicle motion on a real road: hills, road bank, suspension, sideslip, wheel
//! slip, the odometer wheel's lever arm, and vibration of the IMU.
//!
//! The scenario's profile gives the *driver's intent*: horizontal speed V(t) and course ψ(t).
//! The world makes the car that follows it:
//! - **Terrain**: the road's slope `g(s) = dz/ds` and bank `b(s)` are random functions of the
//!   distance driven s ([`SpectralProcess::gaussian`], correlation length in m), so a stopped
//!   car stays on its slope. The road point moves with `v = (V cos ψ, V sin ψ, −V g)` and
//!   `a = (V̇ cos ψ − Vψ̇ sin ψ, V̇ sin ψ + Vψ̇ cos ψ, −V̇ g − V² g′)`, exactly.
//! - **Suspension** (quasi-static load transfer): the body pitches nose-up by
//!   `k_p·V̇` when accelerating (dives when braking) and rolls out of the turn by
//!   `−k_r·Vψ̇`; **ride**: heave, pitch and roll of the body on its springs excited by the
//!   road, narrow-band processes around the body's natural frequency
//!   ([`SpectralProcess::narrow_band`]) scaled by `V²/(V² + V½²)` (no ride when stopped).
//! - **Sideslip**: the odometer wheel is a rear (non-steered) wheel, and the rear axle (at the
//!   wheel's `x`) is the point whose velocity leaves the body's x–z plane only by the rear
//!   tyres' slip angle `k_β·a_y` (lateral acceleration `a_y = Vψ̇`; the slip angle of a tyre
//!   grows with its lateral force). The IMU, `−x_r` ahead of the rear axle, sees in addition
//!   the turn's geometry: the body's slip angle there is `β = k_β·a_y + x_r·ψ̇/V`, so its
//!   velocity has a body-y component `−V sin β` even in a slow turn. A non-holonomic constraint
//!   is therefore violated at the IMU by the geometry, and at the rear axle by the slip alone,
//!   as on a real car.
//! - **Odometer wheel**: the wheel at body `l` rolls with the road speed of its contact point,
//!   `(V cos β − ψ̇_b l_y)·√(1 + g²)` (a rigid body's yaw makes the inner wheel slower), times
//!   `1 + k_s·V̇`, the longitudinal slip ratio of a driven wheel (tyre longitudinal stiffness:
//!   slip ≈ (a/g)/C_x, C_x ≈ 20–30, Wong, "Theory of Ground Vehicles", 4th ed., §1.3).
//!   The odometer reads the wheel, not the true distance.
//! - **Vibration** of the IMU on its mount ([`VibrationSpec`]): engine orders at fixed engine
//!   speed plus flat broadband, per body axis, as an acceleration whose exact double integral
//!   is the mount's displacement (tens of µm), so velocity and position carry no drift.
//!
//! Euler angles: roll `b + roll_s + ride`, pitch `atan g + pitch_s + ride`, heading `ψ + β`,
//! each with its analytic rate; the truth generator turns them into `ω_ib^b` and the
//! velocity and acceleration into `f^b`, so a perfect strapdown INS follows the truth.

use super::spectral::{Follower, Harmonic, RESYNC_MOVES, SpectralProcess, turn_phasor};
use crate::truth::Kinematics;
use nalgebra::Vector3;
use rand_chacha::ChaCha20Rng;
use serde::Deserialize;

/// `[world.vehicle]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleSpec {
    /// Whether the effect is applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// 1-σ road grade, deg.
    pub grade_sigma_deg: f64,
    /// Correlation length of the grade along the road, m.
    pub grade_length_m: f64,
    /// 1-σ road bank (cross-slope), deg.
    pub bank_sigma_deg: f64,
    /// Correlation length of the bank, m.
    pub bank_length_m: f64,
    /// Body pitch per m/s² of forward acceleration (squat; dive when braking), deg.
    pub pitch_per_accel_deg: f64,
    /// Body roll out of the turn per m/s² of lateral acceleration, deg.
    pub roll_per_lateral_accel_deg: f64,
    /// Rear tyres' slip angle per m/s² of lateral acceleration (the body points into the turn
    /// by it at the rear axle), deg.
    pub sideslip_per_lateral_accel_deg: f64,
    /// 1-σ ride heave at speed, m.
    pub ride_heave_sigma_m: f64,
    /// 1-σ ride pitch at speed, deg.
    pub ride_pitch_sigma_deg: f64,
    /// 1-σ ride roll at speed, deg.
    pub ride_roll_sigma_deg: f64,
    /// Natural frequency of the body on its suspension, Hz.
    pub ride_frequency_hz: f64,
    /// 1-σ spread of the ride spectrum about it, Hz.
    pub ride_bandwidth_hz: f64,
    /// Speed at which the ride reaches half its amplitude, m/s.
    pub ride_half_speed_m_s: f64,
    /// Longitudinal slip ratio of the odometer wheel per m/s² of acceleration, s²/m.
    pub wheel_slip_per_accel_s2_m: f64,
    /// Odometer wheel's contact point from the IMU, body axes, m: a rear wheel, so `x` is also
    /// the rear axle's (the kinematic sideslip at the IMU), and `y` changes the reading (the
    /// wheel's forward speed is `V cos β − ψ̇_b l_y`).
    pub odometer_lever_arm_b_m: [f64; 3],
}

/// `[world.vibration]`: the IMU's mount vibration, per body axis.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VibrationSpec {
    /// Whether the effect is applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// Engine rotation frequency (rpm/60), Hz.
    pub engine_rotation_hz: f64,
    /// rms acceleration of engine orders 1 to 4 per axis, m/s².
    pub engine_order_rms_m_s2: [f64; 4],
    /// rms of the broadband acceleration per axis, m/s².
    pub broadband_rms_m_s2: f64,
    /// Band of the broadband part, Hz.
    pub broadband_band_hz: [f64; 2],
}

/// The driver's intent at one instant with the derivatives the body's motion needs.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Intent {
    /// Distance driven (horizontal), m.
    pub distance_m: f64,
    /// Horizontal speed V, m/s, and its first and second derivatives.
    pub speed: [f64; 3],
    /// Course ψ, rad, and its first and second derivatives.
    pub course: [f64; 3],
}

/// The vehicle's true state at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleState {
    /// Body attitude (heading, pitch, roll) and their rates; speed fields are V, V̇.
    pub kinematics: Kinematics,
    /// Velocity of the road point, NED, m/s.
    pub v_road_ned_m_s: Vector3<f64>,
    /// Acceleration of the road point, NED, m/s².
    pub a_road_ned_m_s2: Vector3<f64>,
    /// Ride heave of the body up from the road point: displacement, velocity, acceleration.
    pub heave_up: [f64; 3],
    /// Rolling speed the odometer wheel reads, m/s.
    pub odometer_speed_m_s: f64,
}

/// Speed below which the kinematic sideslip's `1/V` is regularised as `V/(V² + v₀²)`, m/s
/// (turns happen at speed; this only keeps a turn on the spot finite).
pub const KINEMATIC_SPEED_FLOOR_M_S: f64 = 0.1;

/// One realisation of the vehicle's road and body.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleWorld {
    spec: VehicleSpec,
    slope: SpectralProcess,
    bank: SpectralProcess,
    ride: [SpectralProcess; 3],
}

impl VehicleWorld {
    /// Draw a realisation of `spec` from `rng`.
    pub fn new(spec: VehicleSpec, rng: &mut ChaCha20Rng) -> Self {
        let s = &spec;
        let (f, bw) = (s.ride_frequency_hz, s.ride_bandwidth_hz);
        Self {
            slope: SpectralProcess::gaussian(
                s.grade_sigma_deg.to_radians().tan(),
                s.grade_length_m,
                rng,
            ),
            bank: SpectralProcess::gaussian(s.bank_sigma_deg.to_radians(), s.bank_length_m, rng),
            ride: [
                SpectralProcess::narrow_band(s.ride_heave_sigma_m, f, bw, rng),
                SpectralProcess::narrow_band(s.ride_pitch_sigma_deg.to_radians(), f, bw, rng),
                SpectralProcess::narrow_band(s.ride_roll_sigma_deg.to_radians(), f, bw, rng),
            ],
            spec,
        }
    }

    /// Road slope dz/ds at distance `s_m` (what the height integration needs).
    pub fn slope(&self, s_m: f64) -> f64 {
        self.slope.eval(s_m)[0]
    }

    /// Road slope and bank (rad) at distance `s_m`.
    pub fn road(&self, s_m: f64) -> (f64, f64) {
        (self.slope.eval(s_m)[0], self.bank.eval(s_m)[0])
    }

    /// A [`VehicleFollower`] at time `t_s` and distance `s_m`; `grid_step_s` is the step of
    /// the time grid it will move on.
    pub fn follower(&self, t_s: f64, s_m: f64, grid_step_s: Option<f64>) -> VehicleFollower {
        VehicleFollower {
            slope: self.slope.follower(s_m, None),
            bank: self.bank.follower(s_m, None),
            ride: [0, 1, 2].map(|k| self.ride[k].follower(t_s, grid_step_s)),
        }
    }

    /// Move `f` to time `t_s` and distance `s_m`.
    pub fn move_to(&self, f: &mut VehicleFollower, t_s: f64, s_m: f64) {
        self.slope.move_to(&mut f.slope, s_m);
        self.bank.move_to(&mut f.bank, s_m);
        for (p, r) in self.ride.iter().zip(&mut f.ride) {
            p.move_to(r, t_s);
        }
    }

    /// Road slope dz/ds at distance `s_m` near the follower's (an integration stage).
    pub fn slope_near(&self, f: &VehicleFollower, s_m: f64) -> f64 {
        self.slope.value_near(&f.slope, s_m)
    }

    /// The state at time `t_s` for the driver's intent `i`.
    pub fn state(&self, t_s: f64, i: &Intent) -> VehicleState {
        self.state_followed(&self.follower(t_s, i.distance_m, None), i)
    }

    /// The state for the driver's intent `i` at the follower's time and distance (which must
    /// be `i.distance_m`).
    pub fn state_followed(&self, f: &VehicleFollower, i: &Intent) -> VehicleState {
        let sp = &self.spec;
        let [v, vd, vdd] = i.speed;
        let [psi, psid, psidd] = i.course;
        debug_assert_eq!(f.slope.at(), i.distance_m);
        let g = self.slope.eval_followed(&f.slope);
        let b = self.bank.eval_followed(&f.bank);
        // Road point.
        let (sn, cs) = psi.sin_cos();
        let v_road = Vector3::new(v * cs, v * sn, -v * g[0]);
        let a_road = Vector3::new(
            vd * cs - v * psid * sn,
            vd * sn + v * psid * cs,
            -vd * g[0] - v * v * g[1],
        );
        // Load transfer and sideslip from the longitudinal and lateral accelerations.
        let (a_lat, a_lat_d) = (v * psid, vd * psid + v * psidd);
        let kp = sp.pitch_per_accel_deg.to_radians();
        let kr = sp.roll_per_lateral_accel_deg.to_radians();
        let kb = sp.sideslip_per_lateral_accel_deg.to_radians();
        // Ride amplitude m(V) = V²/(V² + V½²) and its time derivatives.
        let vh2 = sp.ride_half_speed_m_s * sp.ride_half_speed_m_s;
        let q = v * v + vh2;
        let m = v * v / q;
        let md = 2.0 * v * vd * vh2 / (q * q);
        let mdd = 2.0 * vh2 * ((vd * vd + v * vdd) * q - 4.0 * v * v * vd * vd) / (q * q * q);
        let [h, p, r] = [0, 1, 2].map(|k| self.ride[k].eval_followed(&f.ride[k]));
        let heave = [
            m * h[0],
            md * h[0] + m * h[1],
            mdd * h[0] + 2.0 * md * h[1] + m * h[2],
        ];
        // Body slip angle at the IMU: the rear axle's tyre slip `k_β·a_y` plus the geometry of
        // a point `−x_r` ahead of the rear axle (`x_r` < 0 behind the IMU), whose velocity
        // turns into the curve by `−x_r·κ` (κ = ψ̇/V, the path's curvature, regularised
        // below `KINEMATIC_SPEED_FLOOR_M_S`): the rear axle's lateral velocity is then
        // `−V·sin(k_β·a_y)` up to the transient `x_r·β̇` and `O(β³)`.
        let x_r = sp.odometer_lever_arm_b_m[0];
        let e2 = KINEMATIC_SPEED_FLOOR_M_S * KINEMATIC_SPEED_FLOOR_M_S;
        let qk = v * v + e2;
        let (inv_v, inv_v_d) = (v / qk, vd * (e2 - v * v) / (qk * qk));
        let beta = kb * a_lat + x_r * psid * inv_v;
        let heading_rate = psid + kb * a_lat_d + x_r * (psidd * inv_v + psid * inv_v_d);
        let kinematics = Kinematics {
            speed_m_s: v,
            speed_rate_m_s2: vd,
            heading_rad: psi + beta,
            heading_rate_rad_s: heading_rate,
            pitch_rad: g[0].atan() + kp * vd + m * p[0],
            pitch_rate_rad_s: g[1] * v / (1.0 + g[0] * g[0]) + kp * vdd + md * p[0] + m * p[1],
            roll_rad: b[0] - kr * a_lat + m * r[0],
            roll_rate_rad_s: b[1] * v - kr * a_lat_d + md * r[0] + m * r[1],
            turntable_rad: 0.0,
        };
        let slip = sp.wheel_slip_per_accel_s2_m * vd;
        let odometer_speed_m_s = (v * beta.cos() - heading_rate * sp.odometer_lever_arm_b_m[1])
            * (1.0 + g[0] * g[0]).sqrt()
            * (1.0 + slip);
        VehicleState {
            kinematics,
            v_road_ned_m_s: v_road,
            a_road_ned_m_s2: a_road,
            heave_up: heave,
            odometer_speed_m_s,
        }
    }
}

/// The road's and the body's processes of a [`VehicleWorld`] followed along the truth's time
/// grid and the distance driven ([`Follower`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleFollower {
    slope: Follower,
    bank: Follower,
    ride: [Follower; 3],
}

/// Engine orders a [`VibrationSpec`] has.
const ENGINE_ORDERS: usize = 4;

/// A [`Vibration`] followed along the truth's time grid: the broadband processes'
/// [`Follower`]s and the engine orders' phasors `(cos, sin)` per order and axis, turned by the
/// grid step (re-anchored like a [`Follower`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VibrationFollower {
    broadband: [Follower; 3],
    t_s: f64,
    moves: u32,
    grid_step_s: Option<f64>,
    engine: [[(f64, f64); 3]; ENGINE_ORDERS],
    engine_turn: [[(f64, f64); 3]; ENGINE_ORDERS],
}

/// One realisation of the IMU's mount vibration.
#[derive(Debug, Clone, PartialEq)]
pub struct Vibration {
    engine: Vec<[Harmonic; 3]>,
    broadband: [SpectralProcess; 3],
}

impl Vibration {
    /// Draw a realisation of `spec` from `rng` (orders with zero rms are left out).
    pub fn new(spec: &VibrationSpec, rng: &mut ChaCha20Rng) -> Self {
        let engine = spec
            .engine_order_rms_m_s2
            .iter()
            .enumerate()
            .filter(|(_, rms)| **rms > 0.0)
            .map(|(k, rms)| {
                let f = spec.engine_rotation_hz * (k + 1) as f64;
                [0, 1, 2].map(|_| Harmonic::new(*rms, f, rng))
            })
            .collect();
        let [lo, hi] = spec.broadband_band_hz;
        let broadband =
            [0, 1, 2].map(|_| SpectralProcess::flat_band(spec.broadband_rms_m_s2, lo, hi, rng));
        Self { engine, broadband }
    }

    /// A [`VibrationFollower`] at `t_s` on a time grid of step `grid_step_s`.
    pub fn follower(&self, t_s: f64, grid_step_s: Option<f64>) -> VibrationFollower {
        let mut f = VibrationFollower {
            broadband: [0, 1, 2].map(|k| self.broadband[k].follower(t_s, grid_step_s)),
            t_s,
            moves: 0,
            grid_step_s,
            engine: [[(1.0, 0.0); 3]; ENGINE_ORDERS],
            engine_turn: [[(1.0, 0.0); 3]; ENGINE_ORDERS],
        };
        for (k, order) in self.engine.iter().enumerate() {
            f.engine[k] = order.map(|h| h.phasor(t_s));
            f.engine_turn[k] = order.map(|h| h.turn(grid_step_s.unwrap_or(0.0)));
        }
        f
    }

    /// Move `f` to `t_s`: one grid step by the phasors' turns, otherwise (and every
    /// [`RESYNC_MOVES`] moves) in closed form.
    pub fn move_to(&self, f: &mut VibrationFollower, t_s: f64) {
        for (p, b) in self.broadband.iter().zip(&mut f.broadband) {
            p.move_to(b, t_s);
        }
        f.moves += 1;
        let one_step = f
            .grid_step_s
            .is_some_and(|h| ((t_s - f.t_s) - h).abs() <= 1e-9 * h);
        for (k, order) in self.engine.iter().enumerate() {
            for (axis, h) in order.iter().enumerate() {
                f.engine[k][axis] = if one_step && f.moves < RESYNC_MOVES {
                    turn_phasor(f.engine[k][axis], f.engine_turn[k][axis])
                } else {
                    h.phasor(t_s)
                };
            }
        }
        if f.moves >= RESYNC_MOVES {
            f.moves = 0;
        }
        f.t_s = t_s;
    }

    /// Displacement (m), velocity (m/s) and acceleration (m/s²) of the IMU on its mount, body
    /// axes, at `t_s`.
    pub fn at(&self, t_s: f64) -> [Vector3<f64>; 3] {
        self.at_followed(&self.follower(t_s, None))
    }

    /// [`Self::at`] at the follower's time.
    pub fn at_followed(&self, f: &VibrationFollower) -> [Vector3<f64>; 3] {
        let mut out = [Vector3::zeros(); 3];
        for axis in 0..3 {
            let mut x = self.broadband[axis].eval_double_integral_followed(&f.broadband[axis]);
            for (k, h) in self.engine.iter().enumerate() {
                let e = h[axis].eval_phasor(f.engine[k][axis]);
                for k in 0..3 {
                    x[k] += e[k];
                }
            }
            for k in 0..3 {
                out[k][axis] = x[k];
            }
        }
        out
    }
}
