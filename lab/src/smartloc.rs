//! The smartLoc dataset's text format (TU Chemnitz; Reisdorf et al., "The Problem of
//! Comparable GNSS Results – An Approach for a Uniform Dataset with Low-Cost and Reference
//! Data", 2016): one measurement per line, a type tag first.
//!
//! * `pseudorange3 t ρ var x y z id system elevation cn0` — pseudorange (m, atmosphere and
//!   satellite clock already removed), its variance (m²), the satellite's ECEF position (m),
//!   its number, its system (1 GPS, 2 SBAS, 4 GLONASS, 8 Galileo, 16 QZSS, 32 BeiDou),
//!   elevation (°) and C/N0 (dB-Hz);
//! * `odom3 t vx vy vz wx wy wz var_vx var_vy var_vz var_wx var_wy var_wz` — vehicle speed
//!   (m/s) and turn rate (rad/s) in the vehicle axes, with variances;
//! * `point3 t x y z c11 … c33` — reference position, ECEF (m), with a 3×3 covariance.
//!
//! Times are seconds from the start of the drive, written from single-precision floats
//! (`0.29999995231628` for 0.3 s): they are rounded to the millisecond the data are sampled on.

/// One satellite's pseudorange of an epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pseudorange {
    /// Pseudorange, m (atmosphere and satellite clock removed).
    pub pseudorange_m: f64,
    /// Its variance, m².
    pub variance_m2: f64,
    /// Satellite position, ECEF, m.
    pub sat_pos_ecef_m: [f64; 3],
    /// Satellite number within its system.
    pub id: u32,
    /// System code (1 GPS, 2 SBAS, 4 GLONASS, 8 Galileo, 16 QZSS, 32 BeiDou).
    pub system: u32,
    /// Elevation, degrees.
    pub elevation_deg: f64,
    /// Carrier-to-noise density, dB-Hz.
    pub cn0_dbhz: f64,
}

/// The pseudoranges of one epoch.
#[derive(Debug, Clone, PartialEq)]
pub struct Epoch {
    /// Time from the start of the drive, ms.
    pub t_ms: i64,
    /// Its pseudoranges in file order.
    pub pseudoranges: Vec<Pseudorange>,
}

/// One odometry sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Odometry {
    /// Time from the start of the drive, ms.
    pub t_ms: i64,
    /// Forward speed, m/s.
    pub speed_m_s: f64,
    /// Variance of the forward speed, (m/s)².
    pub speed_variance_m2_s2: f64,
    /// Turn rate about the vertical axis, rad/s.
    pub yaw_rate_rad_s: f64,
}

/// One reference position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferencePosition {
    /// Time from the start of the drive, ms.
    pub t_ms: i64,
    /// Position, ECEF, m.
    pub r_e_m: [f64; 3],
}

/// The content of a smartLoc input file (pseudoranges and odometry) or ground-truth file.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SmartLoc {
    /// Pseudorange epochs in time order (lines of equal time grouped).
    pub epochs: Vec<Epoch>,
    /// Odometry in time order.
    pub odometry: Vec<Odometry>,
    /// Reference positions in time order.
    pub reference: Vec<ReferencePosition>,
}

/// Why a smartLoc file could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}: {reason}")]
pub struct SmartLocError {
    /// 1-based line number.
    pub line: usize,
    /// What is wrong.
    pub reason: String,
}

/// Parse smartLoc text (input or ground-truth file, or both concatenated). Lines of other
/// types and blank lines are skipped; each type's times must not decrease.
pub fn parse(text: &str) -> Result<SmartLoc, SmartLocError> {
    let mut out = SmartLoc::default();
    for (i, line) in text.lines().enumerate() {
        let err = |reason: String| SmartLocError {
            line: i + 1,
            reason,
        };
        let mut words = line.split_whitespace();
        let Some(tag) = words.next() else {
            continue;
        };
        let need = match tag {
            "pseudorange3" => 10,
            "odom3" => 13,
            "point3" => 4,
            _ => continue,
        };
        let mut v = Vec::with_capacity(need);
        for w in words.take(need) {
            let x: f64 = w
                .parse()
                .map_err(|_| err(format!("{tag}: `{w}` is not a number")))?;
            if !x.is_finite() {
                return Err(err(format!("{tag}: `{w}` is not finite")));
            }
            v.push(x);
        }
        if v.len() < need {
            return Err(err(format!(
                "{tag}: {} numbers, expected at least {need}",
                v.len()
            )));
        }
        if !(0.0..1e7).contains(&v[0]) {
            return Err(err(format!("{tag}: time {} s out of range", v[0])));
        }
        let t_ms = (v[0] * 1e3).round() as i64;
        let decreasing = |last: Option<i64>| {
            if last.is_some_and(|l| t_ms < l) {
                Err(err(format!("{tag}: time {} s goes backwards", v[0])))
            } else {
                Ok(())
            }
        };
        match tag {
            "pseudorange3" => {
                decreasing(out.epochs.last().map(|e| e.t_ms))?;
                if v[2] <= 0.0 {
                    return Err(err(format!(
                        "pseudorange3: variance {} is not positive",
                        v[2]
                    )));
                }
                let small = |x: f64, what: &str| {
                    if (0.0..4_294_967_296.0).contains(&x) && x.fract() == 0.0 {
                        Ok(x as u32)
                    } else {
                        Err(err(format!(
                            "pseudorange3: {what} {x} is not a whole number"
                        )))
                    }
                };
                let p = Pseudorange {
                    pseudorange_m: v[1],
                    variance_m2: v[2],
                    sat_pos_ecef_m: [v[3], v[4], v[5]],
                    id: small(v[6], "satellite id")?,
                    system: small(v[7], "system")?,
                    elevation_deg: v[8],
                    cn0_dbhz: v[9],
                };
                match out.epochs.last_mut() {
                    Some(e) if e.t_ms == t_ms => e.pseudoranges.push(p),
                    _ => out.epochs.push(Epoch {
                        t_ms,
                        pseudoranges: vec![p],
                    }),
                }
            }
            "odom3" => {
                decreasing(out.odometry.last().map(|o| o.t_ms))?;
                out.odometry.push(Odometry {
                    t_ms,
                    speed_m_s: v[1],
                    speed_variance_m2_s2: v[7],
                    yaw_rate_rad_s: v[6],
                });
            }
            _ => {
                decreasing(out.reference.last().map(|o| o.t_ms))?;
                out.reference.push(ReferencePosition {
                    t_ms,
                    r_e_m: [v[1], v[2], v[3]],
                });
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_three_line_types() {
        let text = "odom3 0 5.85 0 0 0 0 -0.0059 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06   \n\
                    pseudorange3 0 19949087.65 25 14567933.9 2809850.9 21875628.0 12 1 85.1 49\n\
                    pseudorange3 0 19713469.01 64 18145814.9 11532054.1 13684003.6 320 4 58.1 40\n\
                    pseudorange3 0.29999995231628 19949074.96 25 1.4e7 2.8e6 2.18e7 12 1 85.1 49\n\
                    point3 0.29999995231628 3785106.68 899901.70 5037235.49 0 0 0 0 0 0 0 0 0\n";
        let s = parse(text).expect("parse");
        assert_eq!(s.epochs.len(), 2);
        assert_eq!(s.epochs[0].pseudoranges.len(), 2);
        assert_eq!(s.epochs[1].t_ms, 300);
        assert_eq!(s.epochs[0].pseudoranges[1].system, 4);
        assert_eq!(s.epochs[0].pseudoranges[1].id, 320);
        assert_eq!(s.odometry[0].speed_m_s, 5.85);
        assert_eq!(s.odometry[0].speed_variance_m2_s2, 0.0025);
        assert_eq!(s.reference[0].t_ms, 300);
        assert_eq!(s.reference[0].r_e_m[0], 3785106.68);
    }

    #[test]
    fn bad_lines_are_named() {
        let e = parse("point3 0 1 2\n").unwrap_err();
        assert_eq!(e.line, 1);
        let e = parse("point3 1 1 2 3\npoint3 0.5 1 2 3\n").unwrap_err();
        assert!(e.reason.contains("backwards"), "{e}");
        let e = parse("pseudorange3 0 2e7 0 1 2 3 12 1 40 40\n").unwrap_err();
        assert!(e.reason.contains("variance"), "{e}");
        let e = parse("pseudorange3 0 2e7 4 1 2 3 1.5 1 40 40\n").unwrap_err();
        assert!(e.reason.contains("whole"), "{e}");
        assert!(parse("odom3 0 x 0 0 0 0 0 0 0 0 0 0 0\n").is_err());
        assert!(parse("other 1 2\n\n").expect("skipped").epochs.is_empty());
    }

    proptest::proptest! {
        /// Any text: an error or a result, never a panic.
        #[test]
        fn never_panics(text in "(pseudorange3|odom3|point3|[a-z]{0,3})( [-0-9.e]{0,8}){0,15}\n{0,2}") {
            let _ = parse(&text);
        }
    }
}
