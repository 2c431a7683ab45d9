//! Chi-square distribution (regularized incomplete gamma function, Numerical Recipes §6.2)
//! and the innovation gates derived from it.

use super::MAX_MEAS_DIM;

/// Chi-square gate thresholds for dimensions 1..=[`MAX_MEAS_DIM`] at one probability,
/// computed once (construction allocates nothing either).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateTable {
    thresholds: [f64; MAX_MEAS_DIM + 1],
    /// Probability the gates were computed for.
    pub probability: f64,
}

impl GateTable {
    /// Gates at `probability` (0 < p < 1); `p >= 1` disables gating (infinite thresholds).
    pub fn new(probability: f64) -> Self {
        let mut thresholds = [f64::INFINITY; MAX_MEAS_DIM + 1];
        if probability < 1.0 {
            for (k, t) in thresholds.iter_mut().enumerate().skip(1) {
                *t = chi2_quantile(k as u32, probability);
            }
        }
        Self {
            thresholds,
            probability,
        }
    }
    /// Threshold for measurement dimension `m` (1..=MAX_MEAS_DIM).
    pub fn threshold(&self, m: usize) -> f64 {
        self.thresholds[m.min(MAX_MEAS_DIM)]
    }
}

/// `ln Γ(x)` for x > 0 (Lanczos, g = 7, n = 9; ~1e-15 relative).
fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Regularized lower incomplete gamma `P(a, x)` (Numerical Recipes `gammp`).
fn gamma_p(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    let gln = ln_gamma(a);
    if x < a + 1.0 {
        let mut ap = a;
        let mut sum = 1.0 / a;
        let mut del = sum;
        for _ in 0..500 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        sum * (-x + a * x.ln() - gln).exp()
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..500 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-16 {
                break;
            }
        }
        1.0 - (-x + a * x.ln() - gln).exp() * h
    }
}

/// Chi-square cumulative distribution with `k` degrees of freedom at `x`.
pub fn chi2_cdf(x: f64, k: u32) -> f64 {
    gamma_p(0.5 * k as f64, 0.5 * x)
}

/// Chi-square quantile: the `x` with `chi2_cdf(x, k) = p` (bisection, ~1e-12 relative).
pub fn chi2_quantile(k: u32, p: f64) -> f64 {
    if p <= 0.0 {
        return 0.0;
    }
    if p >= 1.0 {
        return f64::INFINITY;
    }
    let mut lo = 0.0;
    let mut hi = k as f64 + 10.0;
    while chi2_cdf(hi, k) < p {
        lo = hi;
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if chi2_cdf(mid, k) < p {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-12 * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi2_quantiles_match_tables() {
        assert!((chi2_quantile(1, 0.99) - 6.634_897).abs() < 1e-5);
        assert!((chi2_quantile(3, 0.95) - 7.814_728).abs() < 1e-5);
        assert!((chi2_quantile(2, 0.999) - 13.815_511).abs() < 1e-5);
        assert!((chi2_quantile(6, 0.9973) - 20.062).abs() < 1e-2);
        assert!((chi2_cdf(7.814_728, 3) - 0.95).abs() < 1e-7);
    }
}
