//! Smooth stationary random functions as sums of random-phase cosines (the spectral
//! representation of a stationary process: Shinozuka & Deodatis, "Simulation of stochastic
//! processes by spectral representation", Appl. Mech. Rev. 44(4), 1991).
//!
//! `x(u) = σ·√(2/N)·Σᵢ cos(ωᵢ u + φᵢ)` with `φᵢ` uniform on [0, 2π) and `ωᵢ` drawn from the
//! normalised power spectrum: over the ensemble of draws the mean is 0, the variance σ² and the
//! autocovariance `σ²·E[cos ω τ]` exactly, for any N. Unlike a Gauss–Markov state, every
//! derivative is analytic and every process evaluates the same value at the same argument
//! without stepping, so the truth's attitude, velocity and position stay exactly consistent
//! and every driver process agrees bit for bit.
//!
//! Spectra used: Gaussian (`ω ~ N(0, 1/L²)`, autocovariance `σ² e^{−τ²/2L²}`), narrow band
//! (`ω ~ N(ω₀, σ_ω²)`, `σ² cos(ω₀τ) e^{−σ_ω²τ²/2}`) and flat band (`ω ~ U(ω₁, ω₂)`,
//! `σ² (sin ω₂τ − sin ω₁τ)/((ω₂ − ω₁)τ)`).

use rand::Rng;
use rand_chacha::ChaCha20Rng;
use rand_distr::StandardNormal;
use std::f64::consts::TAU;

/// Number of cosines of every process: enough for a near-Gaussian amplitude distribution
/// (central limit), few enough to evaluate at every 1 ms truth step.
pub const TERMS: usize = 32;

/// `(sin x, cos x)` for the spectral sums: a Cody–Waite reduction by π/2 to |r| ≤ π/4 and
/// the Taylor series of sin (to r¹⁷) and cos (to r¹⁶), whose truncation there is below 10⁻¹⁷,
/// without a branch or a library call, so that the loops over the terms vectorise (the
/// library's `sin_cos` was two thirds of the simulator's time with the motion world on).
/// Within 4·10⁻¹⁶ of the library for |x| ≤ 10⁶; beyond, the reduction's error grows as
/// |x|·2⁻⁸⁶ and the argument `ω·u + φ` itself is only known to |x|·2⁻⁵³.
#[inline(always)]
pub(crate) fn sin_cos(x: f64) -> (f64, f64) {
    // π/2 in three parts (the leading ones with trailing zero bits, so k·part is exact).
    const PIO2_1: f64 = 1.570_796_326_734_125_6;
    const PIO2_2: f64 = 6.077_100_506_303_966e-11;
    const PIO2_3: f64 = 2.022_266_248_711_166_5e-21;
    // 1.5·2⁵²: adding it rounds to an integer held in the low mantissa bits.
    const ROUND: f64 = 6_755_399_441_055_744.0;
    let shifted = x * std::f64::consts::FRAC_2_PI + ROUND;
    let k = shifted - ROUND;
    let quadrant = shifted.to_bits() & 3;
    let r = ((x - k * PIO2_1) - k * PIO2_2) - k * PIO2_3;
    let r2 = r * r;
    // 1/n! from n = 17 (sin) and n = 16 (cos) down.
    let sin = r
        * (1.0
            + r2 * (-1.0 / 6.0
                + r2 * (1.0 / 120.0
                    + r2 * (-1.0 / 5_040.0
                        + r2 * (1.0 / 362_880.0
                            + r2 * (-1.0 / 39_916_800.0
                                + r2 * (1.0 / 6_227_020_800.0
                                    + r2 * (-1.0 / 1_307_674_368_000.0
                                        + r2 * (1.0 / 355_687_428_096_000.0)))))))));
    let cos = 1.0
        + r2 * (-0.5
            + r2 * (1.0 / 24.0
                + r2 * (-1.0 / 720.0
                    + r2 * (1.0 / 40_320.0
                        + r2 * (-1.0 / 3_628_800.0
                            + r2 * (1.0 / 479_001_600.0
                                + r2 * (-1.0 / 87_178_291_200.0
                                    + r2 * (1.0 / 20_922_789_888_000.0))))))));
    // sin(r + qπ/2), cos(r + qπ/2).
    let (s, c) = if quadrant & 1 == 1 {
        (cos, -sin)
    } else {
        (sin, cos)
    };
    if quadrant & 2 == 2 { (-s, -c) } else { (s, c) }
}

/// A stationary random function of one variable (time in s or distance in m).
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralProcess {
    amplitude: f64,
    // Fixed-size, so that the sums over the terms have a known length and vectorise.
    omega: [f64; TERMS],
    phase: [f64; TERMS],
    /// `1/ω` and `1/ω²` of each term (the double integral, without a division per term).
    inv_omega: [f64; TERMS],
    inv_omega2: [f64; TERMS],
}

impl SpectralProcess {
    fn from_omegas(sigma: f64, omega: [f64; TERMS], rng: &mut ChaCha20Rng) -> Self {
        let phase = std::array::from_fn(|_| rng.random::<f64>() * TAU);
        Self {
            amplitude: sigma * (2.0 / TERMS as f64).sqrt(),
            inv_omega: omega.map(|w| 1.0 / w),
            inv_omega2: omega.map(|w| 1.0 / (w * w)),
            omega,
            phase,
        }
    }

    /// Gaussian autocovariance `σ² e^{−τ²/2L²}`, correlation length `length` (argument units).
    pub fn gaussian(sigma: f64, length: f64, rng: &mut ChaCha20Rng) -> Self {
        let omega = std::array::from_fn(|_| rng.sample::<f64, _>(StandardNormal) / length);
        Self::from_omegas(sigma, omega, rng)
    }

    /// Narrow band around `f0_hz` with Gaussian spread `bandwidth_hz` (1-σ):
    /// autocovariance `σ² cos(2πf₀τ) e^{−(2π·bw·τ)²/2}`.
    pub fn narrow_band(sigma: f64, f0_hz: f64, bandwidth_hz: f64, rng: &mut ChaCha20Rng) -> Self {
        let omega = std::array::from_fn(|_| {
            TAU * (f0_hz + bandwidth_hz * rng.sample::<f64, _>(StandardNormal))
        });
        Self::from_omegas(sigma, omega, rng)
    }

    /// Flat power spectral density between `f_lo_hz` and `f_hi_hz`: PSD `σ²/(f_hi − f_lo)`.
    pub fn flat_band(sigma: f64, f_lo_hz: f64, f_hi_hz: f64, rng: &mut ChaCha20Rng) -> Self {
        let omega =
            std::array::from_fn(|_| TAU * (f_lo_hz + (f_hi_hz - f_lo_hz) * rng.random::<f64>()));
        Self::from_omegas(sigma, omega, rng)
    }

    /// The terms' unit phasors `(cos θᵢ, sin θᵢ)`, `θᵢ = ωᵢ u + φᵢ`, in closed form.
    fn phasors(&self, u: f64) -> ([f64; TERMS], [f64; TERMS]) {
        let (mut cos, mut sin) = ([0.0; TERMS], [0.0; TERMS]);
        for k in 0..TERMS {
            (sin[k], cos[k]) = sin_cos(self.omega[k] * u + self.phase[k]);
        }
        (cos, sin)
    }

    /// Value and first and second derivatives from the terms' phasors.
    fn derivatives(&self, cos: &[f64; TERMS], sin: &[f64; TERMS]) -> [f64; 3] {
        let mut out = [0.0; 3];
        for k in 0..TERMS {
            let w = self.omega[k];
            out[0] += cos[k];
            out[1] -= w * sin[k];
            out[2] -= w * w * cos[k];
        }
        out.map(|v| v * self.amplitude)
    }

    /// Displacement, velocity and acceleration of the double integral from the phasors.
    fn double_integral(&self, cos: &[f64; TERMS], sin: &[f64; TERMS]) -> [f64; 3] {
        let mut out = [0.0; 3];
        for k in 0..TERMS {
            out[0] -= cos[k] * self.inv_omega2[k];
            out[1] += sin[k] * self.inv_omega[k];
            out[2] += cos[k];
        }
        out.map(|v| v * self.amplitude)
    }

    /// Value and first and second derivatives at `u`.
    pub fn eval(&self, u: f64) -> [f64; 3] {
        let (cos, sin) = self.phasors(u);
        self.derivatives(&cos, &sin)
    }

    /// Displacement, velocity and acceleration of a process whose *second derivative* is this
    /// one (a vibration given as an acceleration): `x = −Σ a cos/ω²`, each term integrated
    /// exactly twice, so the velocity and position it implies carry no drift.
    pub fn eval_double_integral(&self, u: f64) -> [f64; 3] {
        let (cos, sin) = self.phasors(u);
        self.double_integral(&cos, &sin)
    }

    /// A [`Follower`] of this process at `u`; `grid_step` (argument units), when given, is the
    /// step of the grid it will mostly move on, whose rotation is then computed once.
    pub fn follower(&self, u: f64, grid_step: Option<f64>) -> Follower {
        let (cos, sin) = self.phasors(u);
        let omega_max = self.omega.iter().fold(0.0f64, |m, w| m.max(w.abs()));
        Follower {
            u,
            cos,
            sin,
            moves: 0,
            omega_max,
            grid: grid_step.map(|h| {
                let (mut c, mut s) = ([0.0; TERMS], [0.0; TERMS]);
                for k in 0..TERMS {
                    (s[k], c[k]) = (self.omega[k] * h).sin_cos();
                }
                (h, c, s)
            }),
        }
    }

    /// Move `f` (a follower of this process) to `u`: by the grid's rotation when `u` is one
    /// grid step on, by the small-angle rotation when every term turns by less than
    /// [`SMALL_TURN_RAD`], else (and every [`RESYNC_MOVES`] moves) in closed form.
    pub fn move_to(&self, f: &mut Follower, u: f64) {
        let du = u - f.u;
        f.u = u;
        f.moves += 1;
        if f.moves < RESYNC_MOVES {
            if let Some((h, c, s)) = &f.grid
                && (du - h).abs() <= GRID_MATCH * h
            {
                rotate(&mut f.cos, &mut f.sin, c, s);
                return;
            }
            if du.abs() * f.omega_max <= SMALL_TURN_RAD {
                let (c, s) = self.small_turns(du);
                rotate(&mut f.cos, &mut f.sin, &c, &s);
                return;
            }
        }
        (f.cos, f.sin) = self.phasors(u);
        f.moves = 0;
    }

    /// `(cos ωᵢδ, sin ωᵢδ)` by their Taylor series for `|ωᵢδ| ≤` [`SMALL_TURN_RAD`]
    /// (truncation below `x⁹/9! < 10⁻¹⁷`).
    fn small_turns(&self, du: f64) -> ([f64; TERMS], [f64; TERMS]) {
        let (mut c, mut s) = ([0.0; TERMS], [0.0; TERMS]);
        for k in 0..TERMS {
            let x = self.omega[k] * du;
            let x2 = x * x;
            c[k] = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 / 40_320.0)));
            s[k] = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 - x2 / 5_040.0)));
        }
        (c, s)
    }

    /// Value and first and second derivatives at the follower's argument.
    pub fn eval_followed(&self, f: &Follower) -> [f64; 3] {
        self.derivatives(&f.cos, &f.sin)
    }

    /// [`Self::eval_double_integral`] at the follower's argument.
    pub fn eval_double_integral_followed(&self, f: &Follower) -> [f64; 3] {
        self.double_integral(&f.cos, &f.sin)
    }

    /// The value at `u` near the follower's argument, without moving it (the stages of an
    /// integration step).
    pub fn value_near(&self, f: &Follower, u: f64) -> f64 {
        let du = u - f.u;
        if du.abs() * f.omega_max > SMALL_TURN_RAD {
            return self.eval(u)[0];
        }
        let (c, s) = self.small_turns(du);
        let mut sum = 0.0;
        for k in 0..TERMS {
            sum += f.cos[k] * c[k] - f.sin[k] * s[k];
        }
        sum * self.amplitude
    }
}

/// Largest turn of a term that a [`Follower`] takes by the small-angle series, rad.
pub const SMALL_TURN_RAD: f64 = 0.05;

/// A [`Follower`] is re-anchored in closed form after this many moves, so that the rounding of
/// its rotations (about 10⁻¹⁶ each) stays below 10⁻¹³ and the phasors remain the process's.
pub const RESYNC_MOVES: u32 = 1_000;

/// Relative tolerance on a move's length to count as one grid step (the grid's times are
/// `k·h` rounded, so consecutive differences vary in their last bits).
const GRID_MATCH: f64 = 1e-9;

/// `(c, s) ← (c, s)·e^{iδ}` per term.
#[inline(always)]
fn rotate(
    cos: &mut [f64; TERMS],
    sin: &mut [f64; TERMS],
    turn_cos: &[f64; TERMS],
    turn_sin: &[f64; TERMS],
) {
    for k in 0..TERMS {
        let (c, s) = (cos[k], sin[k]);
        cos[k] = c * turn_cos[k] - s * turn_sin[k];
        sin[k] = s * turn_cos[k] + c * turn_sin[k];
    }
}

/// A [`SpectralProcess`] followed along a sequence of nearby arguments (the truth's time grid,
/// the distance driven): its terms' phasors are rotated forward instead of evaluated, a
/// complex product per term in place of a sine and a cosine. A process moved the same way
/// from the same start holds the same bits in every driver process.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Follower {
    u: f64,
    cos: [f64; TERMS],
    sin: [f64; TERMS],
    moves: u32,
    omega_max: f64,
    /// The grid's step and its rotation per term.
    grid: Option<(f64, [f64; TERMS], [f64; TERMS])>,
}

impl Follower {
    /// The argument the follower stands at.
    pub fn at(&self) -> f64 {
        self.u
    }
}

/// A sinusoid of fixed frequency and random phase whose second derivative (an acceleration)
/// has rms `rms`: an engine order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Harmonic {
    amplitude: f64,
    omega: f64,
    phase: f64,
}

impl Harmonic {
    /// Acceleration `√2·rms·cos(2πf t + φ)`, φ uniform.
    pub fn new(rms: f64, f_hz: f64, rng: &mut ChaCha20Rng) -> Self {
        Self {
            amplitude: std::f64::consts::SQRT_2 * rms,
            omega: TAU * f_hz,
            phase: rng.random::<f64>() * TAU,
        }
    }

    /// Displacement, velocity and acceleration at `t_s`.
    pub fn eval(&self, t_s: f64) -> [f64; 3] {
        self.eval_phasor(self.phasor(t_s))
    }

    /// `(cos θ, sin θ)` of the phase `θ = ωt + φ` at `t_s`.
    pub fn phasor(&self, t_s: f64) -> (f64, f64) {
        let (s, c) = (self.omega * t_s + self.phase).sin_cos();
        (c, s)
    }

    /// `(cos ωh, sin ωh)`: the phasor's turn over a step `h_s`.
    pub fn turn(&self, h_s: f64) -> (f64, f64) {
        let (s, c) = (self.omega * h_s).sin_cos();
        (c, s)
    }

    /// Displacement, velocity and acceleration from the phasor `(cos θ, sin θ)`.
    pub fn eval_phasor(&self, (c, s): (f64, f64)) -> [f64; 3] {
        let a = self.amplitude;
        [
            -a * c / (self.omega * self.omega),
            a * s / self.omega,
            a * c,
        ]
    }
}

/// `z·w` for phasors `(cos, sin)`.
pub fn turn_phasor((c, s): (f64, f64), (tc, ts): (f64, f64)) -> (f64, f64) {
    (c * tc - s * ts, s * tc + c * ts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::gauss_markov::mean_and_standard_error;
    use rand::SeedableRng;

    /// Ensemble variance and autocovariance at `lag` of `make`'s processes against the closed
    /// forms, within 4 standard errors (see [`mean_and_standard_error`]).
    fn check(
        name: &str,
        runs: usize,
        lag: f64,
        sigma: f64,
        rho: f64,
        mut make: impl FnMut(&mut ChaCha20Rng) -> SpectralProcess,
    ) {
        let mut rng = ChaCha20Rng::seed_from_u64(7);
        let (mut sq, mut prod) = (Vec::new(), Vec::new());
        for _ in 0..runs {
            let p = make(&mut rng);
            // A random origin: the process is stationary, so any origin has the same statistics.
            let u0 = rng.random::<f64>() * 1e3;
            let (x0, x1) = (p.eval(u0)[0], p.eval(u0 + lag)[0]);
            sq.push(x0 * x0);
            prod.push(x0 * x1);
        }
        let (v, se_v) = mean_and_standard_error(&sq);
        let (c, se_c) = mean_and_standard_error(&prod);
        let s2 = sigma * sigma;
        assert!(
            (v - s2).abs() < 4.0 * se_v,
            "{name}: variance {v} vs {s2} (SE {se_v})"
        );
        assert!(
            (c - rho * s2).abs() < 4.0 * se_c,
            "{name}: autocovariance {c} vs {} (SE {se_c})",
            rho * s2
        );
        // The lag is informative: the model's correlation is resolved away from 0 and 1.
        assert!((rho * s2).abs() > 4.0 * se_c && s2 - rho * s2 > 4.0 * se_c);
    }

    #[test]
    fn gaussian_narrow_and_flat_band_spectra() {
        check("gaussian", 3000, 100.0, 2.0, (-0.5f64).exp(), |r| {
            SpectralProcess::gaussian(2.0, 100.0, r)
        });
        // Lag 0.1 s at 1.5 Hz ± 0.3 Hz: cos(0.3π)·e^{−(0.06π)²/2}.
        let rho = (TAU * 1.5 * 0.1).cos() * (-(TAU * 0.3 * 0.1f64).powi(2) / 2.0).exp();
        check("narrow", 3000, 0.1, 0.5, rho, |r| {
            SpectralProcess::narrow_band(0.5, 1.5, 0.3, r)
        });
        // Lag 2 ms in 20..120 Hz.
        let (w1, w2, tau) = (TAU * 20.0, TAU * 120.0, 2e-3);
        let rho = ((w2 * tau).sin() - (w1 * tau).sin()) / ((w2 - w1) * tau);
        check("flat", 3000, tau, 0.3, rho, |r| {
            SpectralProcess::flat_band(0.3, 20.0, 120.0, r)
        });
    }

    /// A follower moved along a 1 ms grid for 2 500 steps (past its re-anchoring) and along a
    /// distance with uneven small steps, with a jump beyond the small-angle series, agrees
    /// with the closed form to the rounding of its rotations.
    #[test]
    fn a_follower_holds_the_closed_form() {
        let mut rng = ChaCha20Rng::seed_from_u64(5);
        let vib = SpectralProcess::flat_band(0.2, 20.0, 200.0, &mut rng);
        let h = 1e-3;
        let mut f = vib.follower(0.0, Some(h));
        let mut worst = 0.0f64;
        for k in 1..=2_500 {
            let t = k as f64 * h;
            vib.move_to(&mut f, t);
            let (a, b) = (
                vib.eval_double_integral_followed(&f),
                vib.eval_double_integral(t),
            );
            let rel = [1e-5, 1e-3, 1.0];
            for i in 0..3 {
                worst = worst.max((a[i] - b[i]).abs() / rel[i]);
            }
        }
        assert!(worst < 1e-12, "grid: {worst}");
        let road = SpectralProcess::gaussian(0.03, 300.0, &mut rng);
        let mut g = road.follower(0.0, None);
        let (mut s, mut worst) = (0.0, 0.0f64);
        for k in 0..3_000 {
            // 0 to 40 m/s over 1 ms, and once a 500 m jump (closed form).
            s += if k == 1_500 {
                500.0
            } else {
                0.04 * rng.random::<f64>()
            };
            road.move_to(&mut g, s);
            let (a, b) = (road.eval_followed(&g), road.eval(s));
            for i in 0..3 {
                worst = worst.max((a[i] - b[i]).abs());
            }
            let ahead = s + 0.02;
            worst = worst.max((road.value_near(&g, ahead) - road.eval(ahead)[0]).abs());
        }
        assert!(worst < 1e-15, "distance: {worst}");
        assert_eq!(g.at(), s);
    }

    /// The branch-free `sin_cos` against the library's over every quadrant and the arguments
    /// the sums meet (ω·u up to 2π·200 Hz over a day, 10⁸ rad).
    #[test]
    fn sin_cos_agrees_with_the_library() {
        let mut rng = ChaCha20Rng::seed_from_u64(11);
        for scale in [1.0, 10.0, 1e3, 1e6, 1e8] {
            let mut worst = 0.0f64;
            for _ in 0..20_000 {
                let x = (rng.random::<f64>() * 2.0 - 1.0) * scale;
                let (s, c) = sin_cos(x);
                let (s0, c0) = x.sin_cos();
                worst = worst.max((s - s0).abs()).max((c - c0).abs());
            }
            // The argument x carries an ulp of |x|·2⁻⁵³ of its own.
            let bound = 4e-16 + scale * f64::EPSILON;
            assert!(worst <= bound, "|x| ≤ {scale}: {worst} > {bound}");
        }
        for k in -8..=8 {
            let x = k as f64 * std::f64::consts::FRAC_PI_4;
            let (s, c) = sin_cos(x);
            assert!(
                (s - x.sin()).abs() < 4e-16 && (c - x.cos()).abs() < 4e-16,
                "{x}"
            );
        }
    }

    #[test]
    fn derivatives_are_exact() {
        // Central differences with step h: truncation h²/6·max|x‴| (h²/12·max|x⁗| for the
        // second derivative), max|x⁽ⁿ⁾| ≤ σ√(2N)·ω_maxⁿ; round-off ε·max|x|/h.
        let mut rng = ChaCha20Rng::seed_from_u64(3);
        let fd = |f: &dyn Fn(f64) -> [f64; 3], h: f64, tol: f64| {
            let (a, b, c) = (f(0.3 - h), f(0.3), f(0.3 + h));
            assert!(((c[0] - a[0]) / (2.0 * h) - b[1]).abs() < tol, "first");
            assert!(((c[1] - a[1]) / (2.0 * h) - b[2]).abs() < tol, "second");
        };
        // ω ≤ 2π·(2 + 4·0.5) Hz: bounds ≈ 1e-8 and 3e-7 at h = 1e-6.
        let p = SpectralProcess::narrow_band(1.0, 2.0, 0.5, &mut rng);
        fd(&|u| p.eval(u), 1e-6, 1e-6);
        // 20..120 Hz as an acceleration: displacement and velocity are far smaller.
        let q = SpectralProcess::flat_band(1.0, 20.0, 120.0, &mut rng);
        fd(&|u| q.eval_double_integral(u), 1e-7, 1e-4);
        assert_eq!(q.eval_double_integral(0.3)[2], q.eval(0.3)[0]);
        // 80 Hz, rms 0.3: |x⁗| ≤ 0.42·503⁴ ≈ 2.7e10, h = 1e-7: 2e-5.
        let e = Harmonic::new(0.3, 80.0, &mut rng);
        fd(&|u| e.eval(u), 1e-7, 1e-4);
    }
}
