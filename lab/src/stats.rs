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

#[cfg(test)]
mod tests {
    use super::*;

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
