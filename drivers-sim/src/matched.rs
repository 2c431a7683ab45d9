//! The matched world: the simulator without its `[world]`, the filter without the installation
//! of the shipped car — a fixture for the filter's algebra, not a test of navigation.
//!
//! Without a `[world]` every simulated error is exactly one the filter models (white GNSS
//! errors with the covariance the receiver reports, the antenna and the odometer at the IMU,
//! no time-tag latency), so a filter that is also told so must reproduce its own covariance:
//! the checks of mechanization, update and replay algebra use this pair. Navigation figures
//! come from the shipped scenarios, whose world the filter does not know.

use crate::scenario::Scenario;
use crate::world::WorldSection;
use fusion::navigator::NavigatorConfig;

/// `scn` with its world removed: every sensor error is the filter's own model.
pub fn scenario(mut scn: Scenario) -> Scenario {
    scn.spec.world = None;
    scn
}

/// `cfg` told the matched world (`NavigatorConfig::idealised`): the GNSS antenna and the
/// odometer wheel at the IMU, every sample stamped at its time of validity, the receiver's and
/// the star tracker's errors white, the barometer in the standard atmosphere. The rest of the
/// tuning (IMU class, gates, switches) is left as it is.
pub fn filter(cfg: NavigatorConfig) -> NavigatorConfig {
    cfg.idealised()
}

/// `cfg` (a tuning) installed like the car `car` (`config/filter.toml`) for a world that has
/// only some of the car's effects: the antenna's lever arm and time tag where the world has the
/// antenna, the receiver's error correlation where it has pseudorange errors, the wheel's lever
/// arm where it has the car, the odometer's time tag where it has the host's time-stamping,
/// the star tracker's time tag, low-frequency error and roll bias where it has
/// the star tracker's world, the weather's drift where it has the barometer's air, the
/// region's gravity class where it has a gravity disturbance, the oscillator's class where it
/// has a real receiver clock; the matched
/// filter ([`filter`]) for the rest. What the filter is told is always the
/// car's file, never the world's values.
pub fn installed_for(
    world: Option<&WorldSection>,
    cfg: NavigatorConfig,
    car: &NavigatorConfig,
) -> NavigatorConfig {
    let mut cfg = filter(cfg);
    let Some(w) = world else { return cfg };
    if w.antenna().is_some() {
        cfg.gnss.lever_arm_b_m = car.gnss.lever_arm_b_m;
        cfg.latency.gnss_s = car.latency.gnss_s;
    }
    if w.gnss_errors_on() {
        cfg.gnss.error_correlation_time_s = car.gnss.error_correlation_time_s;
    }
    if w.vehicle().is_some() {
        cfg.vehicle.wheel_lever_arm_b_m = car.vehicle.wheel_lever_arm_b_m;
    }
    if w.time_tags().is_some() {
        cfg.latency.odometer_s = car.latency.odometer_s;
    }
    if w.star_tracker().is_some() {
        cfg.latency.star_tracker_s = car.latency.star_tracker_s;
        cfg.aiding.star_low_frequency_sigma_arcsec = car.aiding.star_low_frequency_sigma_arcsec;
        cfg.aiding.star_low_frequency_correlation_time_s =
            car.aiding.star_low_frequency_correlation_time_s;
        cfg.aiding.star_roll_bias_sigma_arcsec = car.aiding.star_roll_bias_sigma_arcsec;
    }
    if w.baro().is_some() {
        cfg.aiding.baro_bias_rw_m_sqrt_s = car.aiding.baro_bias_rw_m_sqrt_s;
        cfg.aiding.baro_scale_sigma = car.aiding.baro_scale_sigma;
    }
    if w.gravity().is_some() {
        cfg.gravity_disturbance = car.gravity_disturbance;
    }
    if w.receiver_clock().is_some() {
        cfg.aiding.clock_bias_psd_m2_s = car.aiding.clock_bias_psd_m2_s;
        cfg.aiding.clock_drift_psd_m2_s3 = car.aiding.clock_drift_psd_m2_s3;
    }
    cfg
}

#[cfg(test)]
mod tests {
    use super::*;
    use fusion::navigator::{GnssInstallation, Latency};

    #[test]
    fn the_matched_pair_has_no_world_and_the_car_is_installed_per_effect() {
        let root = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../config"));
        let shipped = Scenario::load(&root.join("scenarios/vehicle.toml")).unwrap();
        let shipped_star = shipped.star_tracker;
        let world = shipped.spec.world.expect("the car's world is described");
        assert!(scenario(shipped).spec.world.is_none());
        let text = std::fs::read_to_string(root.join("filter.toml")).unwrap();
        let car: NavigatorConfig = toml::from_str(&text).unwrap();
        assert_ne!(
            car.gnss.lever_arm_b_m, [0.0; 3],
            "the car's antenna is surveyed"
        );
        let m = filter(car.clone());
        assert_eq!(m.gnss, GnssInstallation::default());
        assert_eq!(m.latency, Latency::default());
        assert_eq!(m.vehicle.wheel_lever_arm_b_m, [0.0; 3]);
        assert_eq!(m.aiding.star_low_frequency_sigma_arcsec, 0.0);
        assert_eq!(m.aiding.star_roll_bias_sigma_arcsec, 0.0);
        assert_eq!(
            car.aiding.star_roll_bias_sigma_arcsec, shipped_star.roll_bias_arcsec,
            "the filter's star roll bias is the class's data sheet"
        );
        assert_eq!(m.gravity_disturbance, Default::default());
        m.validate().unwrap();
        let all = world.only(&crate::world::EFFECTS).unwrap();
        assert_eq!(
            all.effects_on(),
            crate::world::EFFECTS,
            "every table of the car's"
        );
        let mut one_off = all;
        one_off.gravity.as_mut().unwrap().enabled = false;
        assert!(one_off.effects_present().contains(&"gravity"));
        assert!(!one_off.effects_on().contains(&"gravity"));
        assert_eq!(one_off.effects_on().len(), crate::world::EFFECTS.len() - 1);
        assert_eq!(
            installed_for(Some(&all), m.clone(), &car),
            car,
            "the whole world"
        );
        assert_eq!(installed_for(None, car.clone(), &car), m);
        let antenna = world.only(&["gnss_antenna"]).unwrap();
        let a = installed_for(Some(&antenna), m.clone(), &car);
        assert_eq!(a.gnss.lever_arm_b_m, car.gnss.lever_arm_b_m);
        assert_eq!(a.latency.gnss_s, car.latency.gnss_s);
        assert_eq!(
            a.gnss.error_correlation_time_s, 0.0,
            "white without pseudorange errors"
        );
        assert_eq!(a.vehicle.wheel_lever_arm_b_m, [0.0; 3]);
        assert_eq!(a.gravity_disturbance, Default::default());
        let gravity = world.only(&["gravity"]).unwrap();
        let g = installed_for(Some(&gravity), m.clone(), &car);
        assert_eq!(g.gravity_disturbance, car.gravity_disturbance);
        assert_ne!(
            g.gravity_disturbance,
            Default::default(),
            "the car's region has a class"
        );
    }
}
