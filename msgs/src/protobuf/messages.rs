//! The protobuf form of every Sextant message: field numbers, pinned by
//! `msgs/tests/protobuf_fields.txt` (a number is never reused; a new field takes a new one).

use crate::{
    BaroSample, GnssSample, GnssSatellite, Header, ImuSample, NavSolution, OdometerSample,
    SensorAliveEvent, SensorHealth, StarTrackerSample, Status, TruthSample,
};

crate::proto_message!(Header = "sextant.Header" {
    1 => time_ns, 2 => seq, 3 => status, 4 => reserved, 5 => send_mono_ns,
});
crate::proto_message!(ImuSample = "sextant.ImuSample" {
    1 => header, 2 => dt_s, 3 => delta_angle_rad, 4 => delta_velocity_m_s, 5 => n_channels,
    6 => reserved, 7 => channel_axis, 8 => channel_delta_angle_rad,
    9 => channel_delta_velocity_m_s, 10 => channel_temperature_c, 11 => turntable_angle_rad,
});
crate::proto_message!(StarTrackerSample = "sextant.StarTrackerSample" {
    1 => header, 2 => q_sensor_icrf, 3 => sigma_cross_rad, 4 => sigma_roll_rad, 5 => n_stars,
    6 => valid,
});
crate::proto_message!(GnssSatellite = "sextant.GnssSatellite" {
    1 => prn, 2 => flags, 3 => pseudorange_m, 4 => range_rate_m_s, 5 => cn0_dbhz,
    6 => sigma_pseudorange_m, 7 => sigma_range_rate_m_s, 8 => sat_pos_ecef_m,
    9 => sat_vel_ecef_m_s, 10 => baseline_phase_cycles, 11 => phase_lock_time_s,
});
crate::proto_message!(GnssSample = "sextant.GnssSample" {
    1 => header, 2 => fix_valid, 3 => n_satellites, 4 => pos_ecef_m, 5 => vel_ecef_m_s,
    6 => pos_cov_ecef_m2, 7 => vel_cov_ecef_m2_s2, 8 => pdop, 9 => baseline_length_m,
    10 => wavelength_m, 11 => satellites,
});
crate::proto_message!(OdometerSample = "sextant.OdometerSample" {
    1 => header, 2 => dt_s, 3 => distance_m, 4 => speed_m_s,
});
crate::proto_message!(BaroSample = "sextant.BaroSample" {
    1 => header, 2 => pressure_pa, 3 => temperature_c,
});
crate::proto_message!(TruthSample = "sextant.TruthSample" {
    1 => header, 2 => lat_rad, 3 => lon_rad, 4 => height_m, 5 => pos_ecef_m,
    6 => vel_ned_m_s, 7 => q_ned_body, 8 => roll_pitch_heading_rad, 9 => gyro_bias_rad_s,
    10 => accel_bias_m_s2,
});
crate::proto_message!(NavSolution = "sextant.NavSolution" {
    1 => header, 2 => mode, 3 => aiding_mask, 4 => lat_rad, 5 => lon_rad, 6 => height_m,
    7 => pos_ecef_m, 8 => vel_ned_m_s, 9 => q_ned_body, 10 => roll_pitch_heading_rad,
    11 => pos_sigma_ned_m, 12 => vel_sigma_ned_m_s, 13 => att_sigma_ned_rad,
    14 => gyro_bias_rad_s, 15 => accel_bias_m_s2, 16 => imu_send_mono_ns,
    17 => gyro_bias_sigma_rad_s, 18 => accel_bias_sigma_m_s2, 19 => gyro_scale_ppm,
    20 => accel_scale_ppm, 21 => boresight_rad, 22 => boresight_sigma_rad,
    23 => clock_bias_m, 24 => clock_drift_m_s, 25 => baro_bias_m, 26 => odometer_scale,
    27 => stale, 28 => pos_cov_ned_m2,
});
crate::proto_message!(SensorHealth = "sextant.SensorHealth" {
    1 => received, 2 => fused, 3 => rejected_gate, 4 => rejected_invalid, 5 => dropped_late,
    6 => last_time_ns, 7 => alive, 8 => deadline_misses, 9 => last_nis, 10 => nis_sum,
    11 => nis_count, 12 => nis_dof_sum, 13 => seq_gaps,
});
crate::proto_message!(Status = "sextant.Status" {
    1 => header, 2 => mode, 3 => alive_mask, 4 => solutions_published, 5 => records_written,
    6 => records_dropped, 7 => sensors, 8 => imu_channels_excluded_mask,
    9 => imu_channels_suspect_mask, 10 => imu_faults_detected, 11 => recorder_errors,
    12 => gnss_ls_checks, 13 => gnss_ls_disagreements, 14 => gnss_ls_last_nis,
    15 => gnss_ls_pdop, 16 => reinitializations, 17 => zupt_fused, 18 => zupt_rejected_gate,
    19 => nhc_fused, 20 => nhc_rejected_gate, 21 => nhc_nis_sum, 22 => solutions_stale,
    23 => motion_alignments, 24 => gnss_heading_alignments, 25 => warm_starts,
    26 => imu_held_at_time_jump, 27 => latency_count, 28 => latency_p50_us,
    29 => latency_p99_us, 30 => latency_max_us,
});
crate::proto_message!(SensorAliveEvent = "sextant.SensorAliveEvent" {
    1 => header, 2 => sensor, 3 => alive,
});
