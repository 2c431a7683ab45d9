//! The paper-000 static stand (`config/scenarios/astro_stand.toml`): the filter configuration
//! of the navigator's online boresight estimate on it, shared by the astro-calibration
//! experiment and the stand's tests.

use crate::scenario::Scenario;
use fusion::navigator::NavigatorConfig;

/// The default filter tuning with the boresight angles κ1..κ3 as states (1° prior, since the
/// default 0.1° would make the stand's 0.57° misalignment a 5σ outlier for the innovation
/// gate) and the IMU error priors of the stand's grade in `scn`.
///
/// The filter is told the stand's accelerometer grade (the default tuning is for the 50 µg
/// navigation grade; this stand's accelerometers are 250 µg). The simulated bias at the start
/// is the turn-on bias plus the temperature term `c·(T₀ − T_ref)` with a per-axis coefficient
/// c of σ `temp_coeff` ([`crate::imu`]): 10 µg/°C · 5 °C = 50 µg here, so the filter's initial
/// σ is the root sum of squares of the two (255 µg); the gyro bias σ likewise. The later drift
/// of the temperature term (5 µg/h) is inside the bias random walk.
pub fn boresight_filter_config(scn: &Scenario) -> NavigatorConfig {
    let mut config = NavigatorConfig::default();
    config.states.boresight = true;
    config.aiding.boresight_sigma_deg = 1.0;
    let a = &scn.imu.accel;
    let dtemp_c = scn.spec.imu.temperature.initial_c - scn.imu.reference_temperature_c;
    config.imu.accel_bias_ug = a.bias_ug.hypot(a.temp_coeff_ug_per_c * dtemp_c);
    let gy = &scn.imu.gyro;
    config.imu.gyro_bias_deg_h = gy.bias_deg_h.hypot(gy.temp_coeff_deg_h_per_c * dtemp_c);
    config.imu.vrw_ug_sqrt_hz = a.vrw_ug_per_rt_hz;
    config.imu.accel_bias_rw_ug_sqrt_h = a.bias_rw_ug_per_rt_h;
    config
}
