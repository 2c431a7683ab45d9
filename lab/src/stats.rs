//! Summary statistics: RMS, maximum of absolute values, percentiles.

/// Root mean square; `None` for an empty slice.
pub fn rms(v: &[f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    Some((v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt())
}

/// Largest absolute value; `None` for an empty slice.
pub fn max_abs(v: &[f64]) -> Option<f64> {
    v.iter().map(|x| x.abs()).reduce(f64::max)
}

/// Percentile `p` (0..=100) by linear interpolation between the closest ranks; `None` for an
/// empty slice or `p` out of range. NaNs sort last.
pub fn percentile(v: &[f64], p: f64) -> Option<f64> {
    if v.is_empty() || !(0.0..=100.0).contains(&p) {
        return None;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let rank = p / 100.0 * (s.len() - 1) as f64;
    let lo = rank.floor() as usize;
    let hi = rank.ceil() as usize;
    let f = rank - lo as f64;
    Some(s[lo] + (s[hi] - s[lo]) * f)
}

/// RMS and largest absolute value of a stream, in constant memory.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RmsMax {
    sum_sq: f64,
    n: u64,
    max_abs: Option<f64>,
}

impl RmsMax {
    /// Take one value.
    pub fn push(&mut self, x: f64) {
        self.sum_sq += x * x;
        self.n += 1;
        self.max_abs = Some(self.max_abs.map_or(x.abs(), |m| m.max(x.abs())));
    }
    /// Take every value of another stream.
    pub fn merge(&mut self, o: &RmsMax) {
        self.sum_sq += o.sum_sq;
        self.n += o.n;
        self.max_abs = match (self.max_abs, o.max_abs) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
    }
    /// Root mean square; `None` before the first value.
    pub fn rms(&self) -> Option<f64> {
        (self.n > 0).then(|| (self.sum_sq / self.n as f64).sqrt())
    }
    /// Largest absolute value; `None` before the first value.
    pub fn max_abs(&self) -> Option<f64> {
        self.max_abs
    }
    /// Values taken.
    pub fn count(&self) -> u64 {
        self.n
    }
}

/// Percentiles of a stream of non-negative values in constant memory: a histogram, each bin
/// standing for the mean of the values that fell into it, and the values beyond its last bin
/// kept exactly. The k-th smallest value lies in the bin its rank falls into, and so does that
/// bin's mean: a percentile is off by at most one bin width from the exact one (interpolated
/// between the closest ranks as [`percentile`]), and exact when the bins it is read from each
/// hold one distinct value. Two layouts:
///
/// - [`StreamingPercentiles::new`]: `resolution`-wide bins up to `resolution × bins` (an
///   absolute bound);
/// - [`StreamingPercentiles::relative`]: bins `(1 + r)` times wider than the previous one from
///   `min` up to `max` (a relative bound, `r` of the value, for values of any magnitude in
///   ≈ ln(max/min)/r bins; below `min`, within `min`).
///
/// Memory is 12 bytes per bin plus 8 per value beyond the last bin: bounded when the range
/// covers the values.
#[derive(Debug, Clone)]
pub struct StreamingPercentiles {
    bins: Bins,
    counts: Vec<u32>,
    sums: Vec<f64>,
    beyond: Vec<f64>,
    n: u64,
    max: Option<f64>,
}

/// Where a value falls in a [`StreamingPercentiles`]' histogram.
#[derive(Debug, Clone, Copy)]
enum Bins {
    /// Bin k is `[k·resolution, (k+1)·resolution)`.
    Linear { resolution: f64 },
    /// Bin 0 is `[0, min)`, bin k ≥ 1 is `[min·(1+r)^(k−1), min·(1+r)^k)`; `ln_step` = ln(1+r).
    Geometric { min: f64, ln_step: f64 },
}

impl StreamingPercentiles {
    /// Bins of width `resolution` covering `[0, resolution × bins)`.
    pub fn new(resolution: f64, bins: usize) -> Self {
        Self::with_bins(Bins::Linear { resolution }, bins)
    }

    /// Bins of relative width `relative_resolution` covering `[min, max)`, and one bin for
    /// `[0, min)`: a percentile ≥ `min` is within `relative_resolution` of its value, one below
    /// `min` within `min`.
    pub fn relative(relative_resolution: f64, min: f64, max: f64) -> Self {
        let ln_step = relative_resolution.ln_1p();
        let bins = 1 + ((max / min).ln() / ln_step).ceil().max(0.0) as usize;
        Self::with_bins(Bins::Geometric { min, ln_step }, bins)
    }

    fn with_bins(bins: Bins, n_bins: usize) -> Self {
        Self {
            bins,
            counts: vec![0; n_bins],
            sums: vec![0.0; n_bins],
            beyond: Vec::new(),
            n: 0,
            max: None,
        }
    }

    /// Take one value (negative values count as 0; NaN is ignored).
    pub fn push(&mut self, x: f64) {
        if x.is_nan() {
            return;
        }
        let x = x.max(0.0);
        self.n += 1;
        self.max = Some(self.max.map_or(x, |m| m.max(x)));
        let k = match self.bins {
            Bins::Linear { resolution } => (x / resolution) as usize,
            Bins::Geometric { min, .. } if x < min => 0,
            Bins::Geometric { min, ln_step } => 1 + ((x / min).ln() / ln_step) as usize,
        };
        if k < self.counts.len() {
            self.counts[k] += 1;
            self.sums[k] += x;
        } else {
            self.beyond.push(x);
        }
    }
    /// The `k`-th smallest value (from 0), as its bin's mean.
    fn nth(&self, k: u64) -> f64 {
        let mut left = k;
        for (c, s) in self.counts.iter().zip(&self.sums) {
            if left < u64::from(*c) {
                return s / f64::from(*c);
            }
            left -= u64::from(*c);
        }
        self.beyond[left as usize]
    }
    /// Percentile `p` (0..=100) by linear interpolation between the closest ranks, as
    /// [`percentile`]; `None` when empty or `p` out of range.
    pub fn percentile(&mut self, p: f64) -> Option<f64> {
        if self.n == 0 || !(0.0..=100.0).contains(&p) {
            return None;
        }
        self.beyond.sort_by(|a, b| a.total_cmp(b));
        let rank = p / 100.0 * (self.n - 1) as f64;
        let (lo, hi) = (rank.floor() as u64, rank.ceil() as u64);
        let (a, b) = (self.nth(lo), self.nth(hi));
        Some(a + (b - a) * (rank - lo as f64))
    }
    /// Largest value.
    pub fn max(&self) -> Option<f64> {
        self.max
    }
    /// Values taken.
    pub fn count(&self) -> u64 {
        self.n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streaming_statistics_agree_with_the_slice_ones() {
        let v: Vec<f64> = (0..10_000)
            .map(|k| ((k * 7919) % 10_007) as f64 * 0.37)
            .collect();
        let mut a = RmsMax::default();
        let mut q = StreamingPercentiles::new(1.0, 2000);
        for &x in &v {
            a.push(x);
            q.push(x);
        }
        assert!((a.rms().unwrap() - rms(&v).unwrap()).abs() < 1e-9 * rms(&v).unwrap());
        assert_eq!(a.max_abs(), max_abs(&v));
        assert_eq!(q.max(), max_abs(&v));
        // Within one bin width of the exact percentile, values above the bins exact.
        for p in [0.0, 5.0, 50.0, 95.0, 99.0, 100.0] {
            let exact = percentile(&v, p).unwrap();
            let got = q.percentile(p).unwrap();
            assert!((got - exact).abs() <= 1.0, "p{p}: {got} vs {exact}");
        }
        let mut same = StreamingPercentiles::new(1.0, 10);
        for _ in 0..5 {
            same.push(2.5);
        }
        assert_eq!(same.percentile(50.0), Some(2.5));
        assert_eq!(StreamingPercentiles::new(1.0, 10).percentile(50.0), None);
    }

    #[test]
    fn relative_bins_bound_the_error_by_a_fraction_of_the_value() {
        // Values over nine decades: every percentile within 1e-3 of its value.
        let v: Vec<f64> = (0..20_000)
            .map(|k| 1e-4 * 10f64.powf(((k * 7919) % 20_011) as f64 / 20_011.0 * 9.0))
            .collect();
        let mut q = StreamingPercentiles::relative(1e-3, 1e-6, 1e6);
        for &x in &v {
            q.push(x);
        }
        for p in [0.0, 1.0, 50.0, 95.0, 99.9, 100.0] {
            let exact = percentile(&v, p).unwrap();
            let got = q.percentile(p).unwrap();
            assert!(
                (got - exact).abs() <= 1e-3 * exact,
                "p{p}: {got} vs {exact}"
            );
        }
        // Below `min`: within `min`; beyond `max`: exact; one distinct value per bin: exact.
        let mut small = StreamingPercentiles::relative(1e-3, 1e-6, 1.0);
        for x in [1e-9, 3e-7, 5.0, 7.0] {
            small.push(x);
        }
        assert!(small.percentile(0.0).unwrap() < 1e-6);
        assert_eq!(small.percentile(100.0), Some(7.0));
        let mut same = StreamingPercentiles::relative(1e-3, 1e-6, 1e6);
        for _ in 0..7 {
            same.push(0.25);
        }
        assert_eq!(same.percentile(50.0), Some(0.25));
        // About ln(1e12)/1e-3 bins: a third of a megabyte.
        assert!(StreamingPercentiles::relative(1e-3, 1e-6, 1e6).counts.len() < 28_000);
    }

    #[test]
    fn rms_and_max() {
        assert_eq!(rms(&[]), None);
        assert!((rms(&[3.0, -4.0]).unwrap() - (12.5f64).sqrt()).abs() < 1e-12);
        assert_eq!(max_abs(&[1.0, -7.0, 3.0]), Some(7.0));
        assert_eq!(max_abs(&[]), None);
    }

    #[test]
    fn percentiles() {
        let v: Vec<f64> = (1..=101).map(f64::from).collect();
        assert_eq!(percentile(&v, 50.0), Some(51.0));
        assert_eq!(percentile(&v, 0.0), Some(1.0));
        assert_eq!(percentile(&v, 100.0), Some(101.0));
        assert!((percentile(&v, 99.0).unwrap() - 100.0).abs() < 1e-12);
        assert_eq!(percentile(&[5.0, 1.0], 50.0), Some(3.0));
        assert_eq!(percentile(&[], 50.0), None);
        assert_eq!(percentile(&[1.0], 101.0), None);
    }
}
