/*
 * mems_ipc.h: the wire format of mems-odometry for C and C++ clients.
 *
 * Mirrors ipc-types/src/wire.rs byte for byte (ipc-types/tests/c_layout.rs compiles a program
 * against this header with gcc and checks every size, alignment and offset against Rust).
 * Conventions: times are nanoseconds of CLOCK_MONOTONIC; raw samples use the sensor's units
 * (g, deg/s, degC); corrected samples and odometry use SI units (m/s^2, rad/s, m, m/s).
 * The iceoryx2 type names below must be used when opening the services from another language.
 */
#ifndef MEMS_IPC_H
#define MEMS_IPC_H

#include <stdint.h>

#define MEMS_SERVICE_RAW "mems/imu/raw"
#define MEMS_SERVICE_CORRECTED "mems/imu/corrected"
#define MEMS_SERVICE_ODOMETRY "mems/odometry/state"
#define MEMS_SERVICE_HINT "mems/robot/hint"

#define MEMS_TYPE_NAME_RAW "mems::RawImuSample.v1"
#define MEMS_TYPE_NAME_CORRECTED "mems::CorrectedImuSample.v3"
#define MEMS_TYPE_NAME_ODOMETRY "mems::OdometryState.v2"
#define MEMS_TYPE_NAME_HINT "mems::RobotHint.v1"

/* RawImuSample.flags */
#define MEMS_RAW_GAP_BEFORE (1u << 0)
#define MEMS_RAW_FIFO_OVERFLOW (1u << 1)
#define MEMS_RAW_SATURATED (1u << 2)
#define MEMS_RAW_REPAIRED (1u << 3)
#define MEMS_RAW_GYRO_VALID (1u << 4)
#define MEMS_RAW_TEMP_VALID (1u << 5)
#define MEMS_RAW_RESUMED (1u << 6)
#define MEMS_RAW_SATURATED_AXES (0x3fu << 7)

/* CorrectedImuSample.flags */
#define MEMS_CORRECTED_ZERO_STATE (1u << 0)
#define MEMS_CORRECTED_DETECTOR_READY (1u << 1)
#define MEMS_CORRECTED_BIAS_REFINED (1u << 2)
#define MEMS_CORRECTED_PROVISIONAL (1u << 3)
#define MEMS_CORRECTED_NEW_SESSION (1u << 4)
#define MEMS_CORRECTED_HOLE_BEFORE (1u << 5)
#define MEMS_CORRECTED_CLIPPED (1u << 6)
#define MEMS_CORRECTED_IMPLAUSIBLE (1u << 7)
#define MEMS_CORRECTED_GRAVITY_OFF (1u << 8)

/* OdometryState.flags */
#define MEMS_ODOMETRY_ZERO_VELOCITY (1u << 0)
#define MEMS_ODOMETRY_ALIGNED (1u << 1)
#define MEMS_ODOMETRY_REVISION (1u << 2)
#define MEMS_ODOMETRY_HINT_STATIONARY (1u << 3)
#define MEMS_ODOMETRY_HINT_SPEED (1u << 4)
#define MEMS_ODOMETRY_HINT_STALE (1u << 5)
#define MEMS_ODOMETRY_HINT_DISAGREE (1u << 6)
#define MEMS_ODOMETRY_NO_GYRO (1u << 7)
#define MEMS_ODOMETRY_GAP_BEFORE (1u << 8)
#define MEMS_ODOMETRY_UNTRUSTED_INPUT (1u << 9)
#define MEMS_ODOMETRY_REST_VIBRATING (1u << 11)
#define MEMS_ODOMETRY_NONHOLONOMIC_REJECTED (1u << 12)
#define MEMS_ODOMETRY_REST_MOVING (1u << 13)
#define MEMS_ODOMETRY_VIBRATING_STOP (1u << 14)

/* RobotHint.flags */
#define MEMS_HINT_STATIONARY (1u << 0)
#define MEMS_HINT_SOURCE_COMMANDED (1u << 1)
#define MEMS_HINT_SOURCE_ENCODERS (1u << 2)
#define MEMS_HINT_SPEED_VALID (1u << 3)
#define MEMS_HINT_YAW_RATE_VALID (1u << 4)

/* Per-stage timestamps (ns, CLOCK_MONOTONIC); 0 where a stage has not touched the message. */
typedef struct mems_stamps {
    uint64_t sample_ns;
    uint64_t acquired_ns;
    uint64_t calibrated_ns;
    uint64_t odometry_ns;
} mems_stamps;

/* One raw sample, sensor frame, sensor units. */
typedef struct mems_raw_imu_sample {
    mems_stamps stamps;
    uint64_t seq;
    double accel_g[3];
    double gyro_dps[3];
    double temp_c;
    int16_t accel_counts[3];
    int16_t gyro_counts[3];
    int16_t temp_counts;
    uint16_t flags;
    uint32_t lost_before;
    uint32_t undelivered; /* samples given up for stalled subscribers so far */
} mems_raw_imu_sample;

/* One calibrated sample, sensor frame, SI units. */
typedef struct mems_corrected_imu_sample {
    mems_stamps stamps;
    uint64_t seq;
    double accel_mps2[3];
    double gyro_rps[3];
    double temp_c;
    double zs_mean_mps2[3];
    double zs_std_mps2[3];
    uint64_t calib_id;
    uint16_t flags;
    uint16_t raw_flags;
    uint32_t settles; /* provisional samples before this one that it settles */
    double refined_accel_mps2[3]; /* offset the stage's bias refinement subtracts, m/s^2 */
    double refined_gyro_rps[3]; /* gyroscope bias the same refinement subtracts, rad/s */
} mems_corrected_imu_sample;

/* Odometry state, navigation frame (z up), 1-sigma per axis. */
typedef struct mems_odometry_state {
    mems_stamps stamps;
    uint64_t seq;
    double position_m[3];
    double position_sigma_m[3];
    double velocity_mps[3];
    double velocity_sigma_mps[3];
    double gravity_sensor_mps2[3];
    double attitude_wxyz[4];
    double distance_m;
    uint16_t flags;
    uint16_t reserved16;
    uint32_t rest_count;
    uint32_t hints_applied;
    uint32_t hint_disagreements;
} mems_odometry_state;

/* A robot controller's hint. stamps.sample_ns: the time it describes (CLOCK_MONOTONIC);
 * stamps.acquired_ns: when it was published. Body frame x forward, y left, z up. */
typedef struct mems_robot_hint {
    mems_stamps stamps;
    uint64_t seq;
    double forward_speed_mps;
    double forward_speed_sigma_mps;
    double yaw_rate_rps;
    double yaw_rate_sigma_rps;
    uint16_t flags;
    uint16_t reserved16;
    uint32_t reserved;
} mems_robot_hint;

#endif /* MEMS_IPC_H */
