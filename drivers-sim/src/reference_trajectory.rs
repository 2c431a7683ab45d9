//! Trajectory kind `reference`: the body follows a recorded reference trajectory (e.g. the
//! ground truth of a GNSS/INS reference system), so that a simulated IMU can be flown along a
//! real drive and fused with the drive's real GNSS and odometer data.
//!
//! # Construction
//! The reference is a list of time-stamped ECEF positions. They are expressed in curvilinear
//! local coordinates about the first point, `x = (M₀·(φ − φ₀), N₀·cos φ₀·(λ − λ₀), h − h₀)` m
//! (north, east, up; `M₀ = R_N(φ₀) + h₀`, `N₀ = R_E(φ₀) + h₀`), which map back to geodetic
//! coordinates exactly. The motion is then split into geometry and timing (the classical
//! arc-length reparametrisation of a curve):
//!
//! * **time law** `s(t)`: the cumulative chord length of the points, interpolated in time by a
//!   C² quintic Hermite spline whose node slopes are the Fritsch–Butland harmonic means of the
//!   neighbouring secants (zero where one of them is zero, so a stop is a stop) and whose node
//!   second derivatives are centred differences of the slopes (zero at a standing node).
//!   Segments whose speed would turn negative have their node accelerations, then their node
//!   speeds, reduced (a zero-acceleration, zero-speed quintic is monotone), so the vehicle never
//!   reverses;
//! * **path** `x(s)`: a natural cubic spline (C²) in `s` through the points spaced at least
//!   `path_node_spacing_m` apart along the chord length: the points in between are smoothed
//!   onto it, which removes the reference's centimetre jitter from the geometry.
//!
//! Inside the given standstill intervals every point is replaced by their mean, so the chord
//! length does not grow, `s(t)` is exactly constant and the body exactly still.
//!
//! # Kinematics
//! With `T = D(x)·x'(s)` the NED tangent (`D = diag((R_N(φ)+h)/M₀, (R_E(φ)+h)·cos φ/(N₀ cos φ₀),
//! −1)` turns local-coordinate rates into NED velocity exactly) the NED velocity is `v = T·ṡ`,
//! and its time derivative `a = Ṫ·ṡ + T·s̈` with `Ṫ = Ḋ·x'·… + D·x''·ṡ`. The body axes are the
//! road's: x along the tangent (heading `atan2(T_E, T_N)`, pitch `atan2(−T_D, |T_NE|)`), no
//! roll (the reference gives no bank). Speed, heading and pitch rates are the exact time
//! derivatives, so the truth generator ([`crate::truth`]) derives specific force and angular
//! rate consistent with the position to its integration accuracy. Heading and pitch come from
//! the path's tangent, which exists at a standstill: no heading jitter while standing, and
//! every rate is proportional to `ṡ`, hence exactly zero there.

use crate::truth::Kinematics;
use fusion::earth::{self, Ellipsoid, Geodetic, WGS84};
use nalgebra::Vector3;

/// One point of a reference trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferencePoint {
    /// Time since the reference's first point, s.
    pub t_s: f64,
    /// Position, ECEF (WGS-84), m.
    pub r_e_m: Vector3<f64>,
}

/// Settings of the spline through a reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceSettings {
    /// Smallest chord length between two nodes of the path spline, m: the points closer to
    /// their predecessor node are smoothed onto the path instead of interpolated.
    pub path_node_spacing_m: f64,
    /// A moving point farther than this from the quadratic in time through its two
    /// neighbours on each side is an outlier of the reference and left out, m.
    pub outlier_threshold_m: f64,
}

impl Default for ReferenceSettings {
    /// 0.5 m node spacing; 0.3 m outlier threshold: the quadratic through ±2 points 0.2–0.3 s
    /// apart predicts a vehicle with jerk ≤ 3 m/s³ to j·τ³/6 ≤ 0.1 m over τ ≤ 0.6 s, so
    /// 0.3 m is three times the largest kinematic prediction error.
    fn default() -> Self {
        Self {
            path_node_spacing_m: 0.5,
            outlier_threshold_m: 0.3,
        }
    }
}

/// Why a reference trajectory could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReferenceError {
    /// Fewer than two points.
    #[error("a reference trajectory needs at least 2 points, got {0}")]
    TooFewPoints(usize),
    /// A time or coordinate is not finite.
    #[error("point {index}: time or position is not finite")]
    NotFinite {
        /// Index of the point.
        index: usize,
    },
    /// Times do not increase strictly.
    #[error("point {index}: time {t_s} s does not increase (previous {previous_s} s)")]
    TimeNotIncreasing {
        /// Index of the point.
        index: usize,
        /// Its time, s.
        t_s: f64,
        /// The previous point's time, s.
        previous_s: f64,
    },
    /// The first point's time is not zero.
    #[error("the first point's time is {0} s: times are counted from the first point")]
    FirstTimeNotZero(f64),
    /// The reference does not move far enough to define a direction.
    #[error(
        "the reference moves {moved_m:.3} m in all, less than the path node spacing {spacing_m} m"
    )]
    TooShort {
        /// Chord length of the whole reference, m.
        moved_m: f64,
        /// The node spacing, m.
        spacing_m: f64,
    },
    /// A standstill interval is empty or not finite.
    #[error("standstill interval {index} [{start_s}, {end_s}] s is empty or not finite")]
    BadStill {
        /// Index of the interval.
        index: usize,
        /// Its start, s.
        start_s: f64,
        /// Its end, s.
        end_s: f64,
    },
    /// A path node spacing or outlier threshold that is not a positive finite length.
    #[error("path_node_spacing_m and outlier_threshold_m must be positive and finite, got {0}")]
    BadSpacing(f64),
}

/// The origin of the local curvilinear coordinates and the conversions.
#[derive(Debug, Clone, Copy)]
struct LocalFrame {
    ell: Ellipsoid,
    origin: Geodetic,
    /// `R_N(φ₀) + h₀`, m.
    m0_m: f64,
    /// `(R_E(φ₀) + h₀)·cos φ₀`, m.
    n0_cos_m: f64,
}

impl LocalFrame {
    fn new(origin: Geodetic) -> Self {
        let ell = WGS84;
        let (r_n, r_e) = earth::radii_of_curvature(&ell, origin.lat_rad);
        Self {
            ell,
            origin,
            m0_m: r_n + origin.height_m,
            n0_cos_m: (r_e + origin.height_m) * origin.lat_rad.cos(),
        }
    }

    fn local_of(&self, r_e: &Vector3<f64>) -> Vector3<f64> {
        let g = earth::ecef_to_geodetic(&self.ell, r_e);
        let dlon = crate::truth::wrap_pi(g.lon_rad - self.origin.lon_rad);
        Vector3::new(
            (g.lat_rad - self.origin.lat_rad) * self.m0_m,
            dlon * self.n0_cos_m,
            g.height_m - self.origin.height_m,
        )
    }

    fn geodetic(&self, x: &Vector3<f64>) -> Geodetic {
        Geodetic {
            lat_rad: self.origin.lat_rad + x.x / self.m0_m,
            lon_rad: self.origin.lon_rad + x.y / self.n0_cos_m,
            height_m: self.origin.height_m + x.z,
        }
    }

    /// The NED scale factors `D_N, D_E` at local point `x` and their rates for local
    /// velocity `xd` (north, east, up m/s): `v_N = D_N·ẋ_N`, `v_E = D_E·ẋ_E`, `v_D = −ẋ_U`.
    fn scale(&self, x: &Vector3<f64>, xd: &Vector3<f64>) -> ([f64; 2], [f64; 2]) {
        let g = self.geodetic(x);
        let e2 = self.ell.e2();
        let (s, c) = g.lat_rad.sin_cos();
        let w2 = 1.0 - e2 * s * s;
        let w = w2.sqrt();
        let (r_n, r_e) = earth::radii_of_curvature(&self.ell, g.lat_rad);
        // dR_E/dφ = a e² sinφ cosφ / W³, dR_N/dφ = 3 a (1 − e²) e² sinφ cosφ / W⁵.
        let dr_e = self.ell.a_m * e2 * s * c / (w2 * w);
        let dr_n = 3.0 * self.ell.a_m * (1.0 - e2) * e2 * s * c / (w2 * w2 * w);
        let lat_dot = xd.x / self.m0_m;
        let h_dot = xd.z;
        let h = g.height_m;
        let d_n = (r_n + h) / self.m0_m;
        let d_e = (r_e + h) * c / self.n0_cos_m;
        let d_n_dot = (dr_n * lat_dot + h_dot) / self.m0_m;
        let d_e_dot = ((dr_e * lat_dot + h_dot) * c - (r_e + h) * s * lat_dot) / self.n0_cos_m;
        ([d_n, d_e], [d_n_dot, d_e_dot])
    }
}

/// Natural cubic spline of a 3-vector in one parameter.
#[derive(Debug, Clone)]
struct CubicSpline3 {
    s: Vec<f64>,
    x: Vec<Vector3<f64>>,
    /// Second derivatives at the nodes.
    m: Vec<Vector3<f64>>,
}

impl CubicSpline3 {
    /// Through `(s_i, x_i)`, `s` strictly increasing, at least two nodes; natural ends.
    fn new(s: Vec<f64>, x: Vec<Vector3<f64>>) -> Self {
        let n = s.len();
        let mut m = vec![Vector3::zeros(); n];
        if n > 2 {
            // Tridiagonal system for the interior second derivatives (Thomas algorithm).
            let mut c_prime = vec![0.0; n];
            let mut d_prime = vec![Vector3::zeros(); n];
            for i in 1..n - 1 {
                let h0 = s[i] - s[i - 1];
                let h1 = s[i + 1] - s[i];
                let a = h0 / 6.0;
                let b = (h0 + h1) / 3.0;
                let c = h1 / 6.0;
                let d = (x[i + 1] - x[i]) / h1 - (x[i] - x[i - 1]) / h0;
                let denom = b - a * c_prime[i - 1];
                c_prime[i] = c / denom;
                d_prime[i] = (d - d_prime[i - 1] * a) / denom;
            }
            for i in (1..n - 1).rev() {
                m[i] = d_prime[i] - m[i + 1] * c_prime[i];
            }
        }
        Self { s, x, m }
    }

    /// Value, first and second derivative at `s` (clamped to the nodes' range).
    fn eval(&self, s: f64) -> [Vector3<f64>; 3] {
        let n = self.s.len();
        let s = s.clamp(self.s[0], self.s[n - 1]);
        let i = self.s.partition_point(|&si| si <= s).clamp(1, n - 1) - 1;
        let h = self.s[i + 1] - self.s[i];
        let a = (self.s[i + 1] - s) / h;
        let b = (s - self.s[i]) / h;
        let (x0, x1, m0, m1) = (self.x[i], self.x[i + 1], self.m[i], self.m[i + 1]);
        let x = x0 * a + x1 * b + (m0 * (a * a * a - a) + m1 * (b * b * b - b)) * (h * h / 6.0);
        let xd = (x1 - x0) / h + (m1 * (3.0 * b * b - 1.0) - m0 * (3.0 * a * a - 1.0)) * (h / 6.0);
        let xdd = m0 * a + m1 * b;
        [x, xd, xdd]
    }
}

/// Quintic Hermite interpolation on one segment of length `h`: value, first and second
/// derivative at `u = τ/h` from the end values `p`, rates `v` and second derivatives `a`.
fn quintic(h: f64, u: f64, p: [f64; 2], v: [f64; 2], a: [f64; 2]) -> [f64; 3] {
    let (u2, u3) = (u * u, u * u * u);
    let (u4, u5) = (u3 * u, u3 * u2);
    // Basis functions (value, d/du, d²/du²).
    let h00 = [
        1.0 - 10.0 * u3 + 15.0 * u4 - 6.0 * u5,
        -30.0 * u2 + 60.0 * u3 - 30.0 * u4,
        -60.0 * u + 180.0 * u2 - 120.0 * u3,
    ];
    let h01 = [1.0 - h00[0], -h00[1], -h00[2]];
    let h10 = [
        u - 6.0 * u3 + 8.0 * u4 - 3.0 * u5,
        1.0 - 18.0 * u2 + 32.0 * u3 - 15.0 * u4,
        -36.0 * u + 96.0 * u2 - 60.0 * u3,
    ];
    let h11 = [
        -4.0 * u3 + 7.0 * u4 - 3.0 * u5,
        -12.0 * u2 + 28.0 * u3 - 15.0 * u4,
        -24.0 * u + 84.0 * u2 - 60.0 * u3,
    ];
    let h20 = [
        0.5 * u2 - 1.5 * u3 + 1.5 * u4 - 0.5 * u5,
        u - 4.5 * u2 + 6.0 * u3 - 2.5 * u4,
        1.0 - 9.0 * u + 18.0 * u2 - 10.0 * u3,
    ];
    let h21 = [
        0.5 * u3 - u4 + 0.5 * u5,
        1.5 * u2 - 4.0 * u3 + 2.5 * u4,
        3.0 * u - 12.0 * u2 + 10.0 * u3,
    ];
    let mut out = [0.0; 3];
    let scale = [1.0, 1.0 / h, 1.0 / (h * h)];
    for k in 0..3 {
        out[k] = (p[0] * h00[k]
            + p[1] * h01[k]
            + h * (v[0] * h10[k] + v[1] * h11[k])
            + h * h * (a[0] * h20[k] + a[1] * h21[k]))
            * scale[k];
    }
    out
}

/// A reference trajectory as a smooth spline (module documentation).
#[derive(Debug, Clone)]
pub struct ReferenceTrajectory {
    frame: LocalFrame,
    /// Times of the points left out as outliers, s.
    rejected: Vec<f64>,
    /// Node times of the time law, s.
    t_s: Vec<f64>,
    /// Chord length at the nodes, m.
    s_m: Vec<f64>,
    /// ṡ at the nodes, m/s.
    sd_m_s: Vec<f64>,
    /// s̈ at the nodes, m/s².
    sdd_m_s2: Vec<f64>,
    path: CubicSpline3,
}

impl ReferenceTrajectory {
    /// The spline through `points` (times from 0, strictly increasing), standing still inside
    /// each of `still_s` (`[start, end]` s since the first point).
    pub fn new(
        points: &[ReferencePoint],
        still_s: &[[f64; 2]],
        settings: &ReferenceSettings,
    ) -> Result<Self, ReferenceError> {
        let spacing = settings.path_node_spacing_m;
        for v in [spacing, settings.outlier_threshold_m] {
            if !(v.is_finite() && v > 0.0) {
                return Err(ReferenceError::BadSpacing(v));
            }
        }
        if points.len() < 2 {
            return Err(ReferenceError::TooFewPoints(points.len()));
        }
        for (i, p) in points.iter().enumerate() {
            if !(p.t_s.is_finite() && p.r_e_m.iter().all(|c| c.is_finite())) {
                return Err(ReferenceError::NotFinite { index: i });
            }
            if i > 0 && p.t_s <= points[i - 1].t_s {
                return Err(ReferenceError::TimeNotIncreasing {
                    index: i,
                    t_s: p.t_s,
                    previous_s: points[i - 1].t_s,
                });
            }
        }
        if points[0].t_s != 0.0 {
            return Err(ReferenceError::FirstTimeNotZero(points[0].t_s));
        }
        for (i, w) in still_s.iter().enumerate() {
            if !(w[0].is_finite() && w[1].is_finite() && w[1] > w[0]) {
                return Err(ReferenceError::BadStill {
                    index: i,
                    start_s: w[0],
                    end_s: w[1],
                });
            }
        }
        let frame = LocalFrame::new(earth::ecef_to_geodetic(&WGS84, &points[0].r_e_m));
        let mut t: Vec<f64> = points.iter().map(|p| p.t_s).collect();
        let mut x: Vec<Vector3<f64>> = points.iter().map(|p| frame.local_of(&p.r_e_m)).collect();
        let is_still = |ti: f64| still_s.iter().any(|w| ti >= w[0] && ti <= w[1]);
        let rejected = reject_outliers(&mut t, &mut x, &is_still, settings.outlier_threshold_m);
        let still: Vec<bool> = t.iter().map(|&ti| is_still(ti)).collect();
        // Each run of standing points collapses to its mean.
        let mut i = 0;
        while i < x.len() {
            if !still[i] {
                i += 1;
                continue;
            }
            let j = (i..x.len()).find(|&j| !still[j]).unwrap_or(x.len());
            let mean = x[i..j].iter().sum::<Vector3<f64>>() / (j - i) as f64;
            x[i..j].iter_mut().for_each(|xi| *xi = mean);
            i = j;
        }
        let mut s = vec![0.0; x.len()];
        for k in 1..x.len() {
            s[k] = s[k - 1] + (x[k] - x[k - 1]).norm();
        }
        let total = s[s.len() - 1];
        if total < spacing {
            return Err(ReferenceError::TooShort {
                moved_m: total,
                spacing_m: spacing,
            });
        }
        let (sd, sdd) = time_law_derivatives(&t, &s, &still);
        // Path nodes: the first point, then each point at least `spacing` past the last node;
        // the last point replaces a final node closer than `spacing`.
        let mut ns = vec![s[0]];
        let mut nx = vec![x[0]];
        for k in 1..x.len() {
            if s[k] - ns[ns.len() - 1] >= spacing {
                ns.push(s[k]);
                nx.push(x[k]);
            }
        }
        let last = x.len() - 1;
        if s[last] > ns[ns.len() - 1] {
            if ns.len() > 1 && s[last] - ns[ns.len() - 1] < spacing {
                ns.pop();
                nx.pop();
            }
            ns.push(s[last]);
            nx.push(x[last]);
        }
        Ok(Self {
            frame,
            rejected,
            t_s: t,
            s_m: s,
            sd_m_s: sd,
            sdd_m_s2: sdd,
            path: CubicSpline3::new(ns, nx),
        })
    }

    /// Geodetic position at t = 0 (the site the truth generator starts from).
    pub fn start(&self) -> Geodetic {
        let [x, _, _] = self.path.eval(self.s_m[0]);
        self.frame.geodetic(&x)
    }

    /// Times of the reference points left out as outliers (`outlier_threshold_m`), s.
    pub fn rejected_s(&self) -> &[f64] {
        &self.rejected
    }

    /// Time of the last point, s.
    pub fn end_s(&self) -> f64 {
        self.t_s[self.t_s.len() - 1]
    }

    /// Chord length travelled over the whole reference, m.
    pub fn length_m(&self) -> f64 {
        self.s_m[self.s_m.len() - 1]
    }

    /// `s, ṡ, s̈` at `t_s` (the first segment's before the first point; standing at the last
    /// point after it: a scenario must not run past the last point, [`Self::end_s`]).
    fn time_law(&self, t_s: f64) -> [f64; 3] {
        let n = self.t_s.len();
        if t_s > self.t_s[n - 1] {
            return [self.s_m[n - 1], 0.0, 0.0];
        }
        let t_s = t_s.max(self.t_s[0]);
        if t_s == self.t_s[n - 1] {
            return [self.s_m[n - 1], self.sd_m_s[n - 1], self.sdd_m_s2[n - 1]];
        }
        let i = self.t_s.partition_point(|&ti| ti <= t_s) - 1;
        let h = self.t_s[i + 1] - self.t_s[i];
        quintic(
            h,
            (t_s - self.t_s[i]) / h,
            [self.s_m[i], self.s_m[i + 1]],
            [self.sd_m_s[i], self.sd_m_s[i + 1]],
            [self.sdd_m_s2[i], self.sdd_m_s2[i + 1]],
        )
    }

    /// Geodetic position on the spline at `t_s` since the first point.
    pub fn geodetic(&self, t_s: f64) -> Geodetic {
        let [s, _, _] = self.time_law(t_s);
        let [x, _, _] = self.path.eval(s);
        self.frame.geodetic(&x)
    }

    /// ECEF position on the spline at `t_s`, m.
    pub fn position_ecef_m(&self, t_s: f64) -> Vector3<f64> {
        earth::geodetic_to_ecef(&self.frame.ell, &self.geodetic(t_s))
    }

    /// The body's kinematics at `t_s` (module documentation): speed along the tangent,
    /// heading and pitch of the tangent, no roll, with their exact time derivatives.
    pub fn kinematics(&self, t_s: f64) -> Kinematics {
        let [s, sd, sdd] = self.time_law(t_s);
        let [x, xp, xpp] = self.path.eval(s);
        let ([d_n, d_e], [d_n_dot, d_e_dot]) = self.frame.scale(&x, &(xp * sd));
        // NED tangent per metre of s and its time derivative.
        let tan = Vector3::new(d_n * xp.x, d_e * xp.y, -xp.z);
        let tan_dot = Vector3::new(
            d_n_dot * xp.x + d_n * xpp.x * sd,
            d_e_dot * xp.y + d_e * xpp.y * sd,
            -xpp.z * sd,
        );
        let hor2 = tan.x * tan.x + tan.y * tan.y;
        let hor = hor2.sqrt();
        let norm = tan.norm();
        let hor_dot = (tan.x * tan_dot.x + tan.y * tan_dot.y) / hor;
        Kinematics {
            speed_m_s: norm * sd,
            speed_rate_m_s2: tan.dot(&tan_dot) / norm * sd + norm * sdd,
            heading_rad: tan.y.atan2(tan.x),
            heading_rate_rad_s: (tan.x * tan_dot.y - tan.y * tan_dot.x) / hor2,
            pitch_rad: (-tan.z).atan2(hor),
            pitch_rate_rad_s: (hor * -tan_dot.z + tan.z * hor_dot) / (hor2 + tan.z * tan.z),
            roll_rad: 0.0,
            roll_rate_rad_s: 0.0,
            turntable_rad: 0.0,
        }
    }
}

/// Remove, worst first, every moving point farther than `threshold_m` from the least-squares
/// quadratic in time through its two neighbours on each side (the first and last two points
/// are kept). Returns the removed points' times.
fn reject_outliers(
    t: &mut Vec<f64>,
    x: &mut Vec<Vector3<f64>>,
    is_still: &dyn Fn(f64) -> bool,
    threshold_m: f64,
) -> Vec<f64> {
    let mut removed = Vec::new();
    loop {
        let n = t.len();
        let mut worst = (threshold_m, None);
        for k in 2..n.saturating_sub(2) {
            if is_still(t[k]) {
                continue;
            }
            let idx = [k - 2, k - 1, k + 1, k + 2];
            // Normal equations of x(τ) = c0 + c1 τ + c2 τ², τ = t − t_k.
            let mut a = nalgebra::Matrix3::<f64>::zeros();
            let mut b = nalgebra::Matrix3::<f64>::zeros();
            for &j in &idx {
                let tau = t[j] - t[k];
                let phi = Vector3::new(1.0, tau, tau * tau);
                a += phi * phi.transpose();
                b += phi * x[j].transpose();
            }
            let Some(c) = a.lu().solve(&b) else {
                continue;
            };
            let d = (x[k] - c.row(0).transpose()).norm();
            if d > worst.0 {
                worst = (d, Some(k));
            }
        }
        let Some(k) = worst.1 else {
            return removed;
        };
        removed.push(t.remove(k));
        x.remove(k);
    }
}

/// Node rates `ṡ` and second derivatives `s̈` of the time law through `(t_k, s_k)` (module
/// documentation), reduced until no segment's speed is negative.
fn time_law_derivatives(t: &[f64], s: &[f64], still: &[bool]) -> (Vec<f64>, Vec<f64>) {
    let n = t.len();
    let secant: Vec<f64> = (0..n - 1)
        .map(|k| (s[k + 1] - s[k]) / (t[k + 1] - t[k]))
        .collect();
    let mut sd = vec![0.0; n];
    sd[0] = secant[0];
    sd[n - 1] = secant[n - 2];
    for k in 1..n - 1 {
        let (d0, d1) = (secant[k - 1], secant[k]);
        if still[k] || d0 <= 0.0 || d1 <= 0.0 {
            continue;
        }
        // Fritsch–Butland / Brodlie weighted harmonic mean (Fritsch & Carlson 1980, eq. 13
        // of Fritsch & Butland 1984): monotone for a cubic, a good slope for the quintic.
        let (h0, h1) = (t[k] - t[k - 1], t[k + 1] - t[k]);
        let (w0, w1) = (2.0 * h1 + h0, h1 + 2.0 * h0);
        sd[k] = (w0 + w1) / (w0 / d0 + w1 / d1);
    }
    if still[0] {
        sd[0] = 0.0;
    }
    if still[n - 1] {
        sd[n - 1] = 0.0;
    }
    let mut sdd = vec![0.0; n];
    for k in 1..n - 1 {
        if sd[k] > 0.0 {
            sdd[k] = (sd[k + 1] - sd[k - 1]) / (t[k + 1] - t[k - 1]);
        }
    }
    // A segment whose speed dips below zero: first its end accelerations, then its end speeds
    // are reduced (halved) until it does not. Both only move the quintic towards the
    // zero-rate one, whose speed 30·u²(1−u)²·Δs/h is non-negative.
    const SAMPLES: usize = 64;
    for _ in 0..60 {
        let mut changed = false;
        for k in 0..n - 1 {
            let h = t[k + 1] - t[k];
            let min = (0..=SAMPLES)
                .map(|j| {
                    quintic(
                        h,
                        j as f64 / SAMPLES as f64,
                        [s[k], s[k + 1]],
                        [sd[k], sd[k + 1]],
                        [sdd[k], sdd[k + 1]],
                    )[1]
                })
                .fold(f64::INFINITY, f64::min);
            if min < 0.0 {
                changed = true;
                if sdd[k] != 0.0 || sdd[k + 1] != 0.0 {
                    sdd[k] = 0.0;
                    sdd[k + 1] = 0.0;
                } else {
                    sd[k] *= 0.5;
                    sd[k + 1] *= 0.5;
                }
            }
        }
        if !changed {
            break;
        }
    }
    (sd, sdd)
}

/// Why a reference-point text could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}: {reason}")]
pub struct PointsParseError {
    /// 1-based line number.
    pub line: usize,
    /// What is wrong.
    pub reason: String,
}

/// Parse reference points from text: one point per line, `t_s x_m y_m z_m` (ECEF), optionally
/// after one leading tag word (e.g. `point3`) and before further columns (ignored); blank
/// lines and `#` comments are skipped. Times are taken as written.
pub fn parse_points(text: &str) -> Result<Vec<ReferencePoint>, PointsParseError> {
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let mut words = line.split_whitespace().peekable();
        if words.peek().is_some_and(|w| w.parse::<f64>().is_err()) {
            words.next();
        }
        let mut v = [0.0; 4];
        for (k, slot) in v.iter_mut().enumerate() {
            let w = words.next().ok_or_else(|| PointsParseError {
                line: i + 1,
                reason: format!("expected 4 numbers (t_s x_m y_m z_m), found {k}"),
            })?;
            *slot = w.parse().map_err(|_| PointsParseError {
                line: i + 1,
                reason: format!("`{w}` is not a number"),
            })?;
        }
        out.push(ReferencePoint {
            t_s: v[0],
            r_e_m: Vector3::new(v[1], v[2], v[3]),
        });
    }
    Ok(out)
}

/// The spline of a scenario's `kind = "reference"` trajectory: the one already set, else
/// built from its `file` (relative to `scenario_file`), and stored in `spec`.
pub fn load_spec(
    spec: &mut crate::scenario::ReferenceTrajectorySpec,
    scenario_file: &std::path::Path,
) -> Result<std::sync::Arc<ReferenceTrajectory>, crate::SimError> {
    let invalid = |key: &str, reason: String| crate::SimError::Invalid {
        file: scenario_file.to_path_buf(),
        key: key.into(),
        reason,
    };
    if let Some(s) = &spec.spline {
        return Ok(s.clone());
    }
    let Some(name) = &spec.file else {
        return Err(invalid(
            "trajectory.file",
            "missing: a reference trajectory needs the file of its points".into(),
        ));
    };
    let path = scenario_file
        .parent()
        .unwrap_or(std::path::Path::new("."))
        .join(name);
    let text = std::fs::read_to_string(&path).map_err(|e| crate::SimError::Io {
        file: path.clone(),
        reason: e.to_string(),
    })?;
    let points = parse_points(&text)
        .map_err(|e| invalid("trajectory.file", format!("{}: {e}", path.display())))?;
    let settings = ReferenceSettings {
        path_node_spacing_m: spec.path_node_spacing_m,
        outlier_threshold_m: spec.outlier_threshold_m,
    };
    let spline = ReferenceTrajectory::new(&points, &spec.still_s, &settings)
        .map_err(|e| invalid("trajectory", format!("{}: {e}", path.display())))?;
    let spline = std::sync::Arc::new(spline);
    spec.spline = Some(spline.clone());
    Ok(spline)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Site;
    use crate::truth::{Profile, TruthGenerator};
    use fusion::strapdown::ImuIncrement;
    use nalgebra::Rotation3;
    use std::f64::consts::FRAC_PI_2;

    /// A synthetic drive (module of the test): 6 m/s north, braking to a 4 s stop, away again
    /// into a 90° right turn of radius 20 m and east, climbing 2 % all along. Arc length
    /// `σ(t)` from a raised-cosine speed profile; the path in local north/east/up about a
    /// Berlin origin. Returns the reference points at alternating 0.2/0.3 s spacing (the
    /// smartLoc reference's), the stop interval, and the exact path for comparison.
    struct Drive {
        origin: Geodetic,
    }

    impl Drive {
        /// Speed, m/s: 6 → 0 over 4–8 s, stand 8–12 s, 0 → 8 over 12–16 s, then 8.
        fn speed(t: f64) -> f64 {
            let ramp = |t: f64, t0: f64, dur: f64| {
                let x = ((t - t0) / dur).clamp(0.0, 1.0);
                x - (std::f64::consts::TAU * x).sin() / std::f64::consts::TAU
            };
            6.0 - 6.0 * ramp(t, 4.0, 4.0) + 8.0 * ramp(t, 12.0, 4.0)
        }

        /// Arc length at `t` by Simpson's rule on a 1 ms grid, m.
        fn arc(t: f64) -> f64 {
            let n = ((t / 1e-3).ceil() as usize).max(2) & !1;
            let h = t / n as f64;
            let mut sum = Self::speed(0.0) + Self::speed(t);
            for k in 1..n {
                sum += Self::speed(k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
            }
            sum * h / 3.0
        }

        /// Local (north, east, up) at arc length σ: 60 m north, a right quarter circle of 20 m,
        /// then east; up 2 % of σ.
        fn local(sigma: f64) -> Vector3<f64> {
            let (l1, r) = (60.0, 20.0);
            let quarter = FRAC_PI_2 * r;
            let ne = if sigma <= l1 {
                (sigma, 0.0)
            } else if sigma <= l1 + quarter {
                let a = (sigma - l1) / r;
                (l1 + r * a.sin(), r - r * a.cos())
            } else {
                (l1 + r, r + sigma - l1 - quarter)
            };
            Vector3::new(ne.0, ne.1, 0.02 * sigma)
        }

        fn ecef(&self, x: &Vector3<f64>) -> Vector3<f64> {
            earth::geodetic_to_ecef(&WGS84, &LocalFrame::new(self.origin).geodetic(x))
        }

        fn points(&self, end_s: f64) -> Vec<ReferencePoint> {
            let mut out = Vec::new();
            let (mut t, mut k) = (0.0f64, 0);
            while t <= end_s {
                out.push(ReferencePoint {
                    t_s: t,
                    r_e_m: self.ecef(&Self::local(Self::arc(t))),
                });
                t = ((t + if k % 3 == 2 { 0.3 } else { 0.2 }) * 1e3).round() / 1e3;
                k += 1;
            }
            out
        }
    }

    fn drive() -> (Drive, Vec<ReferencePoint>, ReferenceTrajectory) {
        let d = Drive {
            origin: Geodetic {
                lat_rad: 52.509_f64.to_radians(),
                lon_rad: 13.376_f64.to_radians(),
                height_m: 80.0,
            },
        };
        let pts = d.points(40.0);
        let spline = ReferenceTrajectory::new(&pts, &[[8.0, 12.0]], &ReferenceSettings::default())
            .expect("spline");
        (d, pts, spline)
    }

    /// The spline passes by every reference point. Its error is the time law's and the path's
    /// interpolation error: the quintic time law with Fritsch–Butland slopes errs by
    /// O(h³·|s⃛|) ≈ 0.3³ · 1.5 m/s³ / 24 ≈ 2 mm at the 0.3 s spacing and the drive's largest jerk
    /// (2π·6/4² m/s³); the natural cubic path through nodes 0.5 m apart by ≤ h²·Δκ/8 ≈ 1.6 mm
    /// where the curvature jumps by 1/20 m⁻¹ (line into arc); the chord length differs from
    /// the arc length by (κ·c)²/24 of the arc, c the chord: ≤ 6e-4 with chords of 2.4 m on the
    /// 20 m radius, i.e. ≤ 2 cm over the 31 m of arc. Bounds: 1 cm at the points, 3 cm on
    /// the length.
    #[test]
    fn spline_passes_by_the_points() {
        let (_, pts, spline) = drive();
        let worst = pts
            .iter()
            .map(|p| (spline.position_ecef_m(p.t_s) - p.r_e_m).norm())
            .fold(0.0, f64::max);
        assert!(worst < 0.01, "worst {worst} m");
        // σ is the horizontal arc length; the 2 % climb makes the path √(1 + 0.02²) longer.
        let dl = spline.length_m() - Drive::arc(pts.last().unwrap().t_s) * 1.0004f64.sqrt();
        assert!(dl.abs() < 0.03, "length off by {dl} m");
    }

    /// A point thrown 0.9 m sideways (a reference glitch) is left out, and the spline does not
    /// follow it: its heading rate stays that of the drive's turns, 8/20 = 0.4 rad/s, plus the
    /// cubic path's curvature overshoot where the line meets the arc (bound 0.5 rad/s; a path
    /// through the glitch would turn by ±2·atan(0.9/1.6) within 0.4 s, ≈ 5 rad/s).
    #[test]
    fn an_outlier_of_the_reference_is_left_out() {
        let (d, mut pts, _) = drive();
        let k = pts.iter().position(|p| p.t_s > 30.0).expect("point");
        let g = earth::ecef_to_geodetic(&WGS84, &pts[k].r_e_m);
        let east = earth::c_e_n(g.lat_rad, g.lon_rad).column(1).into_owned();
        pts[k].r_e_m += east * 0.9;
        let spline = ReferenceTrajectory::new(&pts, &[[8.0, 12.0]], &ReferenceSettings::default())
            .expect("spline");
        assert_eq!(spline.rejected_s(), &[pts[k].t_s]);
        let max_rate = (0..4000)
            .map(|i| spline.kinematics(i as f64 * 0.01).heading_rate_rad_s.abs())
            .fold(0.0, f64::max);
        let clean = ReferenceTrajectory::new(
            &d.points(40.0),
            &[[8.0, 12.0]],
            &ReferenceSettings::default(),
        )
        .expect("spline");
        assert!(clean.rejected_s().is_empty(), "{:?}", clean.rejected_s());
        let clean_max = (0..4000)
            .map(|i| clean.kinematics(i as f64 * 0.01).heading_rate_rad_s.abs())
            .fold(0.0, f64::max);
        eprintln!("max heading rate: clean {clean_max}, outlier left out {max_rate} rad/s");
        assert!(max_rate < 0.5, "{max_rate}");
    }

    /// Between the points inside the standstill interval the body does not move or turn at all, and its heading
    /// is the path's (north) — no jitter, no rate; outside it moves.
    #[test]
    fn standing_still_is_exactly_still() {
        let (_, _, spline) = drive();
        // The points inside [8, 12] s at the 0.2/0.3 s spacing span at least [8.3, 11.7] s.
        let r0 = spline.position_ecef_m(8.3);
        let k0 = spline.kinematics(8.3);
        for i in 0..=340 {
            let t = 8.3 + i as f64 * 0.01;
            let k = spline.kinematics(t);
            assert_eq!(k.speed_m_s, 0.0, "t {t}");
            assert_eq!(k.speed_rate_m_s2, 0.0, "t {t}");
            assert_eq!(k.heading_rate_rad_s, 0.0, "t {t}");
            assert_eq!(k.pitch_rate_rad_s, 0.0, "t {t}");
            assert_eq!(k.heading_rad, k0.heading_rad, "t {t}");
            assert_eq!(spline.position_ecef_m(t), r0, "t {t}");
        }
        // The path heads north there (within the path's smoothing of the 60 m straight).
        assert!(k0.heading_rad.abs() < 1e-3, "{}", k0.heading_rad);
        assert!(spline.kinematics(7.0).speed_m_s > 0.1);
        assert!(spline.kinematics(13.0).speed_m_s > 0.1);
    }

    /// Speed, heading and pitch rates are the time derivatives of speed, heading and pitch
    /// (central differences over ±1 ms: truncation error h²/6·|f⃛| < 1e-6 for these smooth
    /// curves, round-off 1e-16/1e-3 = 1e-13): so the truth generator's specific force and
    /// angular rate belong to the position.
    #[test]
    fn rates_are_the_derivatives() {
        let (_, _, spline) = drive();
        let h = 1e-3;
        for i in 1..380 {
            let t = i as f64 * 0.1 + 0.0137;
            let (a, k, b) = (
                spline.kinematics(t - h),
                spline.kinematics(t),
                spline.kinematics(t + h),
            );
            let d = |f: fn(&Kinematics) -> f64| (f(&b) - f(&a)) / (2.0 * h);
            let tol = 2e-3;
            assert!(
                (d(|k| k.speed_m_s) - k.speed_rate_m_s2).abs() < tol,
                "t {t}"
            );
            assert!(
                (d(|k| k.heading_rad) - k.heading_rate_rad_s).abs() < tol,
                "t {t}"
            );
            assert!(
                (d(|k| k.pitch_rad) - k.pitch_rate_rad_s).abs() < tol,
                "t {t}"
            );
        }
    }

    /// Mechanizing the truth's error-free IMU increments with `fusion::strapdown` (RK4,
    /// coning/sculling, 200 Hz) from the truth's first state stays on the spline over the
    /// 40 s drive, stop included.
    ///
    /// Error budget: the truth generator integrates position from the spline's own velocity
    /// (RK4, 1 ms: ~1e-12 m), so truth and spline agree to round-off; its trapezoid
    /// increments err by h²/12·|ȧ| per interval, telescoping to ~1e-7 m/s. The mechanization
    /// holds the specific force constant over each 5 ms interval with second-order rotation
    /// and sculling compensation: a third-order residual ~(ωT)²·|a|T/12 per interval, with
    /// ω ≤ 0.4 rad/s (8 m/s on 20 m) and |a| ≤ 3.2 m/s² (8²/20): 6e-9 m/s, over 8000
    /// intervals ≤ 5e-5 m/s, ≤ 2 mm of position in 40 s. The time law's jerk jumps at its
    /// nodes (C², not C³) add, per node, a residual of the order |Δs⃛|·T³/24 ≈ 5e-9 m/s
    /// (|Δs⃛| ≤ 10 m/s³): another ≤ 1e-6 m/s over the 200 nodes. Bound: 1 cm position,
    /// 1 mm/s velocity, 10 µrad attitude. The truth itself leaves the spline only by the
    /// round-off of its latitude sum (≤ half an ulp of 0.92 rad, 5.5e-17 rad, per 1 ms step,
    /// biased one way while the increment is steady): ≤ 3.5e-7 m/s, 1.4e-5 m in 40 s; bound
    /// 2e-5 m.
    #[test]
    fn strapdown_of_the_imu_truth_follows_the_spline() {
        let (_, _, spline) = drive();
        let spline = std::sync::Arc::new(spline);
        let g = spline.start();
        let site = Site {
            lat_deg: g.lat_rad.to_degrees(),
            lon_deg: g.lon_rad.to_degrees(),
            height_m: g.height_m,
        };
        let mut truth = TruthGenerator::from_profile(Profile::Reference(spline.clone()), site);
        let p0 = *truth.current();
        assert!((p0.r_e_m - spline.position_ecef_m(0.0)).norm() < 1e-6);
        let (mut state, mut sd) = p0.reference_ins();
        let period_ns = 5_000_000;
        let (mut max_pos, mut max_vel, mut max_att, mut max_truth) =
            (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let steps = (spline.end_s() / 5e-3).floor() as i64;
        for k in 1..=steps {
            let inc = truth.advance_to(k * period_ns);
            sd.step(
                &mut state,
                &ImuIncrement {
                    dt_s: inc.dt_s,
                    delta_angle_rad: inc.delta_angle_b_rad,
                    delta_velocity_m_s: inc.delta_velocity_b_m_s,
                },
            );
            let t = truth.current();
            let t_s = (k * period_ns) as f64 * 1e-9;
            max_truth = max_truth.max((t.r_e_m - spline.position_ecef_m(t_s)).norm());
            max_pos = max_pos.max((state.r_e - spline.position_ecef_m(t_s)).norm());
            max_vel = max_vel.max((state.v_e - t.v_e_m_s()).norm());
            let c_err =
                state.q_e_b.to_rotation_matrix().into_inner() * (t.c_e_n * t.c_n_b).transpose();
            max_att = max_att.max(Rotation3::from_matrix_unchecked(c_err).angle());
        }
        eprintln!(
            "reference drive, 40 s: truth vs spline {max_truth:.2e} m; strapdown vs spline \
             {max_pos:.2e} m, {max_vel:.2e} m/s, {max_att:.2e} rad"
        );
        assert!(max_truth < 2e-5, "truth off the spline by {max_truth} m");
        assert!(max_pos < 0.01, "position {max_pos} m");
        assert!(max_vel < 1e-3, "velocity {max_vel} m/s");
        assert!(max_att < 1e-5, "attitude {max_att} rad");
    }

    /// A scenario file with `kind = "reference"` reads its points file (relative to it),
    /// starts the truth at the first point, and refuses a duration past the last point or a
    /// missing file, naming the key.
    #[test]
    fn scenario_file_with_a_reference_trajectory() {
        let (d, pts, _) = drive();
        let dir = std::env::temp_dir().join(format!("sextant-reference-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let text: String = pts
            .iter()
            .map(|p| format!("{} {} {} {}\n", p.t_s, p.r_e_m.x, p.r_e_m.y, p.r_e_m.z))
            .collect();
        std::fs::write(dir.join("points.txt"), text).unwrap();
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let shipped =
            std::fs::read_to_string(root.join("config/scenarios/berlin_reference.toml")).unwrap();
        let sensors = root.join("config/sensors");
        // The shipped scenario without its own points file, standstills and duration (the
        // test gives its own).
        let base: String = shipped
            .lines()
            .filter(|l| {
                !(l.starts_with("file = ")
                    || l.starts_with("still_s = ")
                    || l.starts_with("duration_s = "))
            })
            .map(|l| format!("{l}\n"))
            .collect();
        let with = |extra: &str, duration: &str| {
            base.replace(
                "kind = \"reference\"",
                &format!("kind = \"reference\"\n{extra}"),
            )
            .replace("seed = 1", &format!("{duration}\nseed = 1"))
            .replace(
                "seed = 1",
                &format!(
                    "seed = 1\nsensors_dir = {:?}",
                    sensors.display().to_string()
                ),
            )
        };
        let path = dir.join("s.toml");
        let ok = with(
            "file = \"points.txt\"\nstill_s = [[8.0, 12.0]]",
            "duration_s = 30.0",
        );
        // On the matched world: the shipped bench's vibration would move the truth off the
        // spline by its (sub-millimetre) displacement.
        let scn = crate::matched::scenario(
            crate::scenario::Scenario::from_toml_str(&ok, &path).expect("valid"),
        );
        let r0 = TruthGenerator::new(&scn).current().r_e_m;
        assert!(
            (r0 - pts[0].r_e_m).norm() < 1e-6,
            "{}",
            (r0 - pts[0].r_e_m).norm()
        );
        let long = with("file = \"points.txt\"", "duration_s = 100.0");
        let e = crate::scenario::Scenario::from_toml_str(&long, &path).unwrap_err();
        assert!(e.to_string().contains("scenario.duration_s"), "{e}");
        let missing = with("", "duration_s = 30.0");
        let e = crate::scenario::Scenario::from_toml_str(&missing, &path).unwrap_err();
        assert!(e.to_string().contains("trajectory.file"), "{e}");
        let _ = d;
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn bad_input_is_named() {
        let p = |t: f64, x: f64| ReferencePoint {
            t_s: t,
            r_e_m: Vector3::new(3.785e6 + x, 9.0e5, 5.037e6),
        };
        let s = ReferenceSettings::default();
        assert_eq!(
            ReferenceTrajectory::new(
                &[p(0.0, 0.0), p(1.0, 5.0)],
                &[],
                &ReferenceSettings {
                    outlier_threshold_m: 0.0,
                    ..s
                }
            )
            .err(),
            Some(ReferenceError::BadSpacing(0.0))
        );
        assert_eq!(
            ReferenceTrajectory::new(&[p(0.0, 0.0)], &[], &s).err(),
            Some(ReferenceError::TooFewPoints(1))
        );
        assert!(matches!(
            ReferenceTrajectory::new(&[p(0.0, 0.0), p(0.0, 1.0)], &[], &s),
            Err(ReferenceError::TimeNotIncreasing { index: 1, .. })
        ));
        assert!(matches!(
            ReferenceTrajectory::new(&[p(1.0, 0.0), p(2.0, 1.0)], &[], &s),
            Err(ReferenceError::FirstTimeNotZero(_))
        ));
        assert!(matches!(
            ReferenceTrajectory::new(&[p(0.0, 0.0), p(1.0, 0.1)], &[], &s),
            Err(ReferenceError::TooShort { .. })
        ));
        assert!(matches!(
            ReferenceTrajectory::new(&[p(0.0, 0.0), p(1.0, 5.0)], &[[2.0, 1.0]], &s),
            Err(ReferenceError::BadStill { index: 0, .. })
        ));
        assert!(matches!(
            ReferenceTrajectory::new(&[p(0.0, f64::NAN), p(1.0, 5.0)], &[], &s),
            Err(ReferenceError::NotFinite { index: 0 })
        ));
        assert!(ReferenceTrajectory::new(&[p(0.0, 0.0), p(1.0, 5.0)], &[], &s).is_ok());
    }

    #[test]
    fn points_parse_with_and_without_a_tag() {
        let text = "# t x y z\npoint3 0 1 2 3 0 0 0\n0.5 4 5 6\n\n";
        let pts = parse_points(text).expect("parse");
        assert_eq!(pts.len(), 2);
        assert_eq!(pts[1].r_e_m, Vector3::new(4.0, 5.0, 6.0));
        let e = parse_points("point3 0 1 x 3").unwrap_err();
        assert_eq!(e.line, 1);
        assert!(parse_points("0 1 2").is_err());
    }

    proptest::proptest! {
        /// Any text: an error or points, never a panic.
        #[test]
        fn parse_points_never_panics(text in ".{0,200}") {
            let _ = parse_points(&text);
        }
    }
}
