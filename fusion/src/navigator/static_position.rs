//! The static alignment's position from GNSS (paper 003's alignment needs a latitude and a
//! starting position; [`super::align`]): the mean of the fixes of the static window, chosen by
//! time of validity, with the covariance the receiver's error model gives that mean.
//!
//! # Which fixes
//! Every fix whose time of validity lies in the window and is at least `buffer_window_s`
//! older than the IMU epoch at which the alignment ends. The navigator accepts aiding up to
//! that window late, so every fix of the mean has arrived by then whatever the order in
//! which the drivers' messages met: a live run, its replay and an offline run of the same
//! data start from the same position. A fresher fix adds nothing for a static vehicle.
//!
//! # Why the mean
//! The vehicle does not move during the window, so every fix measures the same point. The
//! receiver's white errors (code noise) average out; its slow ones (ionosphere, orbit,
//! multipath; first-order Gauss–Markov with correlation time `τ`, the filter's
//! `gnss.error_correlation_time_s`) do not. With `ρ_ij = exp(−|t_i − t_j|/τ)` and `C̄` the
//! mean of the fixes' covariances, the mean of `N` fixes has the covariance
//! ```text
//!   C = C̄ · S / N²,   S = Σ_i Σ_j ρ_ij
//! ```
//! (`C̄/N` for white errors, `τ = 0`; `C̄` for errors constant over the window). `S` is kept
//! as the fixes come with `B_n = Σ_{j≤n} ρ_nj = ρ_{n,n−1} B_{n−1} + 1` and
//! `S_n = S_{n−1} + 2 ρ_{n,n−1} B_{n−1} + 1`, so nothing is stored per fix.
//!
//! In tight mode the clock starts from the latest least-squares fix of the mean. Its bias is
//! correlated with that fix's position (`cov_r_clock_m2`, the common clock column of the
//! geometry); with the mean position it is `cov_r_clock_m2 · B_N / N` (each fix's position
//! error correlated with the last one's clock like its own, by `ρ_iN`).

use super::*;
use crate::ekf::correlated::lag_correlation;
use crate::gnss_ls::GnssFix;

/// One GNSS epoch of the alignment window, waiting until it is old enough to be averaged.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct WindowFix {
    /// The least-squares fix of the raw pseudoranges, when they gave one.
    ls: Option<GnssFix>,
    /// The receiver's own fix (antenna, ECEF m; covariance m²), when it sent one.
    receiver: Option<(Vector3<f64>, Matrix3<f64>)>,
}

/// Running mean of fixes of one point with Gauss–Markov errors (module docs). Allocates
/// nothing.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct FixMean {
    n: u32,
    sum_r_e_m: Vector3<f64>,
    sum_cov_m2: Matrix3<f64>,
    last_t: Option<GpsTime>,
    /// `B_N`: the last fix's error correlation summed over all fixes (itself included).
    b: f64,
    /// `S_N`: the correlations summed over all pairs.
    s: f64,
}

impl FixMean {
    /// Add a fix of time of validity `t` (after every earlier one): antenna position `r_e_m`
    /// (ECEF, m) and its covariance (m²); `tau_s` the errors' correlation time.
    pub(super) fn add(
        &mut self,
        t: GpsTime,
        r_e_m: &Vector3<f64>,
        cov_m2: &Matrix3<f64>,
        tau_s: f64,
    ) {
        let rho = match self.last_t {
            Some(prev) => lag_correlation((t - prev).seconds_f64(), tau_s),
            None => 0.0,
        };
        self.s += 2.0 * rho * self.b + 1.0;
        self.b = rho * self.b + 1.0;
        self.n += 1;
        self.sum_r_e_m += r_e_m;
        self.sum_cov_m2 += cov_m2;
        self.last_t = Some(t);
    }

    /// The mean position (ECEF, m) and its covariance (m²); None before the first fix.
    pub(super) fn mean(&self) -> Option<(Vector3<f64>, Matrix3<f64>)> {
        if self.n == 0 {
            return None;
        }
        let n = f64::from(self.n);
        Some((self.sum_r_e_m / n, self.sum_cov_m2 / n * (self.s / (n * n))))
    }

    /// `B_N / N`: the last fix's error correlation with the mean's, relative to its own.
    fn last_share(&self) -> f64 {
        if self.n == 0 {
            0.0
        } else {
            self.b / f64::from(self.n)
        }
    }
}

/// The static window's GNSS position: fixes waiting to be old enough, and the means of those
/// that are (least-squares fixes of the raw pseudoranges preferred to the receiver's own).
#[derive(Debug, Clone)]
pub(super) struct StaticPosition {
    /// Start of the static window (time of validity of the first IMU step's start).
    since: Option<GpsTime>,
    pending: Box<TimeQueue<WindowFix, GNSS_CAP>>,
    ls: FixMean,
    receiver: FixMean,
    /// The latest least-squares fix averaged, and its time of validity (the tight-mode clock).
    latest_ls: Option<(GpsTime, GnssFix)>,
}

impl Default for StaticPosition {
    fn default() -> Self {
        Self {
            since: None,
            pending: Box::new(TimeQueue::new()),
            ls: FixMean::default(),
            receiver: FixMean::default(),
            latest_ls: None,
        }
    }
}

impl StaticPosition {
    /// Forget everything and start a new static window at `since`.
    pub(super) fn restart(&mut self, since: GpsTime) {
        self.pending.clear();
        self.ls = FixMean::default();
        self.receiver = FixMean::default();
        self.latest_ls = None;
        self.since = Some(since);
    }

    /// Queue the fixes of the GNSS epoch valid at `ts`; those before the window are ignored.
    pub(super) fn push(
        &mut self,
        ts: GpsTime,
        ls: Option<GnssFix>,
        receiver: Option<(Vector3<f64>, Matrix3<f64>)>,
        tau_s: f64,
    ) {
        if self.since.is_none_or(|s| ts < s) || (ls.is_none() && receiver.is_none()) {
            return;
        }
        // More epochs than the queue holds within the window (a receiver faster than
        // GNSS_CAP / buffer_window_s): the oldest is averaged early rather than lost.
        if let Some((t, f, _)) = self.pending.insert(ts, WindowFix { ls, receiver }) {
            self.fold(t, &f, tau_s);
        }
    }

    /// Average every queued fix valid at or before `until`.
    pub(super) fn settle(&mut self, until: GpsTime, tau_s: f64) {
        while let Some((t, f, _)) = self.pending.pop_due(until) {
            self.fold(t, &f, tau_s);
        }
    }

    fn fold(&mut self, t: GpsTime, f: &WindowFix, tau_s: f64) {
        if let Some(ls) = &f.ls {
            self.ls
                .add(t, &ls.position.r_e_m, &ls.position.cov_r_e_m2, tau_s);
            self.latest_ls = Some((t, *ls));
        }
        if let Some((r, c)) = &f.receiver {
            self.receiver.add(t, r, c, tau_s);
        }
    }

    /// The antenna position (ECEF, m) and its covariance (m²): the mean of the least-squares
    /// fixes, else of the receiver's; None before any fix is old enough.
    pub(super) fn position(&self) -> Option<(Vector3<f64>, Matrix3<f64>)> {
        self.ls.mean().or_else(|| self.receiver.mean())
    }

    /// The latest least-squares fix averaged, for the tight-mode clock: with its position and
    /// the clock's cross-covariance taken to the mean's when `to_mean` (module docs).
    pub(super) fn clock_fix(&self, to_mean: bool) -> Option<(GpsTime, GnssFix)> {
        let (t, mut fix) = self.latest_ls?;
        if to_mean && let Some((r, c)) = self.ls.mean() {
            fix.position.r_e_m = r;
            fix.position.cov_r_e_m2 = c;
            fix.position.cov_r_clock_m2 *= self.ls.last_share();
        }
        Some((t, fix))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(s: f64) -> GpsTime {
        GpsTime::from_ns(1_000_000_000_000 + (s * 1e9).round() as i64)
    }

    fn mean_of(times: &[f64], tau_s: f64) -> (Vector3<f64>, Matrix3<f64>, f64) {
        let mut m = FixMean::default();
        for (k, &s) in times.iter().enumerate() {
            let r = Vector3::new(k as f64, 0.0, 0.0);
            m.add(t(s), &r, &(Matrix3::identity() * 4.0), tau_s);
        }
        let (r, c) = m.mean().unwrap();
        (r, c, m.last_share())
    }

    #[test]
    fn white_errors_average_as_one_over_n() {
        let times: Vec<f64> = (0..100).map(f64::from).collect();
        let (r, c, share) = mean_of(&times, 0.0);
        assert!((r.x - 49.5).abs() < 1e-12);
        assert!((c[(0, 0)] - 4.0 / 100.0).abs() < 1e-15);
        assert!((share - 0.01).abs() < 1e-15);
    }

    #[test]
    fn the_correlated_covariance_is_the_double_sum_of_the_kernel() {
        // Irregular epochs: the closed form (1/N²) Σ_ij exp(−|t_i − t_j|/τ), summed directly.
        let times = [0.0, 1.0, 2.5, 3.0, 7.0, 7.2, 20.0];
        let tau = 5.0;
        let (_, c, share) = mean_of(&times, tau);
        let n = times.len() as f64;
        let s: f64 = times
            .iter()
            .flat_map(|a| times.iter().map(move |b| (-(a - b).abs() / tau).exp()))
            .sum();
        assert!((c[(1, 1)] - 4.0 * s / (n * n)).abs() < 1e-12, "{c}");
        let last = times[times.len() - 1];
        let b: f64 = times.iter().map(|a| (-(last - a) / tau).exp()).sum();
        assert!((share - b / n).abs() < 1e-12);
    }

    #[test]
    fn errors_constant_over_the_window_do_not_average() {
        let times: Vec<f64> = (0..100).map(f64::from).collect();
        let (_, c, _) = mean_of(&times, 1e12);
        assert!((c[(2, 2)] - 4.0).abs() < 1e-6, "{c}");
    }

    #[test]
    fn only_fixes_old_enough_and_inside_the_window_count() {
        let mut p = StaticPosition::default();
        let cov = Matrix3::identity();
        // Before the window starts: never counted.
        p.restart(t(10.0));
        p.push(
            t(9.0),
            None,
            Some((Vector3::new(100.0, 0.0, 0.0), cov)),
            0.0,
        );
        for k in 10..=20 {
            p.push(
                t(f64::from(k)),
                None,
                Some((Vector3::new(f64::from(k), 0.0, 0.0), cov)),
                0.0,
            );
        }
        assert_eq!(p.position(), None);
        // Settled up to 19 s: the fixes of 10…19 s, whatever arrived after.
        p.settle(t(19.0), 0.0);
        let (r, c) = p.position().unwrap();
        assert!((r.x - 14.5).abs() < 1e-12, "{r}");
        assert!((c[(0, 0)] - 0.1).abs() < 1e-15);
        // A restart forgets.
        p.restart(t(30.0));
        assert_eq!(p.position(), None);
    }
}
