"""The mems-odometry wire format for Python clients (ctypes), mirroring ipc-types/src/wire.rs.

Every struct has the same size, alignment and field offsets as the Rust type (checked by
ipc-types/tests/python_layout.rs) and a ``type_name()`` equal to the Rust ``#[type_name]``, so
that the iceoryx2 Python package (0.10) connects to the Rust services.

Units: times in ns of CLOCK_MONOTONIC; raw samples in g, deg/s, degC (sensor frame);
corrected samples in m/s^2 and rad/s (sensor frame); odometry in m and m/s (navigation frame,
z up), 1-sigma per axis.
"""

import ctypes
import time

SERVICE_RAW = "mems/imu/raw"
SERVICE_CORRECTED = "mems/imu/corrected"
SERVICE_ODOMETRY = "mems/odometry/state"
SERVICE_HINT = "mems/robot/hint"

RAW_GAP_BEFORE = 1 << 0
RAW_FIFO_OVERFLOW = 1 << 1
RAW_SATURATED = 1 << 2
RAW_REPAIRED = 1 << 3
RAW_GYRO_VALID = 1 << 4
RAW_TEMP_VALID = 1 << 5
RAW_RESUMED = 1 << 6
RAW_SATURATED_AXES = 0x3F << 7

CORRECTED_ZERO_STATE = 1 << 0
CORRECTED_DETECTOR_READY = 1 << 1
CORRECTED_BIAS_REFINED = 1 << 2
CORRECTED_PROVISIONAL = 1 << 3
CORRECTED_NEW_SESSION = 1 << 4
CORRECTED_HOLE_BEFORE = 1 << 5
CORRECTED_CLIPPED = 1 << 6
CORRECTED_IMPLAUSIBLE = 1 << 7
CORRECTED_GRAVITY_OFF = 1 << 8

ODOMETRY_ZERO_VELOCITY = 1 << 0
ODOMETRY_ALIGNED = 1 << 1
ODOMETRY_REVISION = 1 << 2
ODOMETRY_HINT_STATIONARY = 1 << 3
ODOMETRY_HINT_SPEED = 1 << 4
ODOMETRY_HINT_STALE = 1 << 5
ODOMETRY_HINT_DISAGREE = 1 << 6
ODOMETRY_NO_GYRO = 1 << 7
ODOMETRY_GAP_BEFORE = 1 << 8
ODOMETRY_UNTRUSTED_INPUT = 1 << 9
ODOMETRY_REST_VIBRATING = 1 << 11
ODOMETRY_NONHOLONOMIC_REJECTED = 1 << 12
ODOMETRY_REST_MOVING = 1 << 13
ODOMETRY_VIBRATING_STOP = 1 << 14

HINT_STATIONARY = 1 << 0
HINT_SOURCE_COMMANDED = 1 << 1
HINT_SOURCE_ENCODERS = 1 << 2
HINT_SPEED_VALID = 1 << 3
HINT_YAW_RATE_VALID = 1 << 4

# The lossless service settings of ipc-types/src/service.rs: whichever process creates a
# service sets them, and an opener may not ask for more, so every language uses the same.
SUBSCRIBER_BUFFER = 4096
MAX_PUBLISHERS = 2
MAX_SUBSCRIBERS = 16
MAX_NODES = 32
# The event service beside each data service (ipc_types::wake): publishers notify it after
# each send, subscribers sleep on it.
MAX_NOTIFIERS = 8

Vec3 = ctypes.c_double * 3


def service_name(base, namespace=""):
    """The full service name for ``base`` under ``namespace`` (as ipc_types::service::full_name)."""
    ns = namespace.strip("/")
    return f"{ns}/{base}" if ns else base


# How long opening a service keeps trying while iceoryx2 finds it half made or half removed by
# another process, s (ipc_types::service::OPEN_PATIENCE): iceoryx2 alone gives up after its 1 s
# creation_timeout, which a loaded machine's creator can outlast.
OPEN_PATIENCE_S = 30.0
# The open-or-create failures that say only that: the Python package raises them with the Rust
# error's Debug text (PublishSubscribeOpenError(HangsInCreation), ...) and no variant to test.
_IN_FLUX = ("SystemInFlux", "HangsInCreation", "IsMarkedForDestruction", "Interrupt")


def _patiently(open_or_create, error):
    """Calls ``open_or_create`` until it succeeds, raises something other than an ``error``
    whose text names a failure in ``_IN_FLUX``, or ``OPEN_PATIENCE_S`` has passed."""
    deadline = time.monotonic() + OPEN_PATIENCE_S
    while True:
        try:
            return open_or_create()
        except error as e:
            if not any(word in str(e) for word in _IN_FLUX) or time.monotonic() >= deadline:
                raise
            time.sleep(0.01)


def open_service(node, name, payload):
    """Opens (or creates) publish-subscribe service ``name`` carrying ``payload`` with the
    project's lossless settings (needs the iceoryx2 Python package); waits out another
    process's creation or removal of it as ipc_types::service::open does."""
    import iceoryx2 as iox2

    return _patiently(
        lambda: node.service_builder(iox2.ServiceName.new(name))
        .publish_subscribe(payload)
        .enable_safe_overflow(False)
        .subscriber_max_buffer_size(SUBSCRIBER_BUFFER)
        .history_size(0)
        .max_publishers(MAX_PUBLISHERS)
        .max_subscribers(MAX_SUBSCRIBERS)
        .max_nodes(MAX_NODES)
        .open_or_create(),
        iox2.PublishSubscribeOpenOrCreateError,
    )


def open_event(node, name):
    """Opens (or creates) the event service that goes with data service ``name``, with the
    settings of ipc_types::wake::open_event: its publishers notify it after each send."""
    import iceoryx2 as iox2

    return _patiently(
        lambda: node.service_builder(iox2.ServiceName.new(name))
        .event()
        .max_notifiers(MAX_NOTIFIERS)
        .max_listeners(MAX_SUBSCRIBERS)
        .max_nodes(MAX_NODES)
        .open_or_create(),
        iox2.EventOpenOrCreateError,
    )


class Stamps(ctypes.Structure):
    """Per-stage timestamps, ns of CLOCK_MONOTONIC (0 where a stage has not touched it)."""

    _fields_ = [
        ("sample_ns", ctypes.c_uint64),
        ("acquired_ns", ctypes.c_uint64),
        ("calibrated_ns", ctypes.c_uint64),
        ("odometry_ns", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name():
        return "mems::Stamps.v1"


class RawImuSample(ctypes.Structure):
    """One raw sample (service mems/imu/raw)."""

    _fields_ = [
        ("stamps", Stamps),
        ("seq", ctypes.c_uint64),
        ("accel_g", Vec3),
        ("gyro_dps", Vec3),
        ("temp_c", ctypes.c_double),
        ("accel_counts", ctypes.c_int16 * 3),
        ("gyro_counts", ctypes.c_int16 * 3),
        ("temp_counts", ctypes.c_int16),
        ("flags", ctypes.c_uint16),
        ("lost_before", ctypes.c_uint32),
        ("undelivered", ctypes.c_uint32),
    ]

    @staticmethod
    def type_name():
        return "mems::RawImuSample.v1"


class CorrectedImuSample(ctypes.Structure):
    """One calibrated sample (service mems/imu/corrected)."""

    _fields_ = [
        ("stamps", Stamps),
        ("seq", ctypes.c_uint64),
        ("accel_mps2", Vec3),
        ("gyro_rps", Vec3),
        ("temp_c", ctypes.c_double),
        ("zs_mean_mps2", Vec3),
        ("zs_std_mps2", Vec3),
        ("calib_id", ctypes.c_uint64),
        ("flags", ctypes.c_uint16),
        ("raw_flags", ctypes.c_uint16),
        ("settles", ctypes.c_uint32),
        ("refined_accel_mps2", Vec3),
        ("refined_gyro_rps", Vec3),
    ]

    @staticmethod
    def type_name():
        return "mems::CorrectedImuSample.v3"


class OdometryState(ctypes.Structure):
    """The odometry estimate (service mems/odometry/state)."""

    _fields_ = [
        ("stamps", Stamps),
        ("seq", ctypes.c_uint64),
        ("position_m", Vec3),
        ("position_sigma_m", Vec3),
        ("velocity_mps", Vec3),
        ("velocity_sigma_mps", Vec3),
        ("gravity_sensor_mps2", Vec3),
        ("attitude_wxyz", ctypes.c_double * 4),
        ("distance_m", ctypes.c_double),
        ("flags", ctypes.c_uint16),
        ("reserved16", ctypes.c_uint16),
        ("rest_count", ctypes.c_uint32),
        ("hints_applied", ctypes.c_uint32),
        ("hint_disagreements", ctypes.c_uint32),
    ]

    @staticmethod
    def type_name():
        return "mems::OdometryState.v2"


class RobotHint(ctypes.Structure):
    """A robot controller's hint (service mems/robot/hint). ``stamps.sample_ns``: the time it
    describes (CLOCK_MONOTONIC ns, the IMU samples' clock); ``stamps.acquired_ns``: when it was
    published. Body frame x forward, y left, z up."""

    _fields_ = [
        ("stamps", Stamps),
        ("seq", ctypes.c_uint64),
        ("forward_speed_mps", ctypes.c_double),
        ("forward_speed_sigma_mps", ctypes.c_double),
        ("yaw_rate_rps", ctypes.c_double),
        ("yaw_rate_sigma_rps", ctypes.c_double),
        ("flags", ctypes.c_uint16),
        ("reserved16", ctypes.c_uint16),
        ("reserved", ctypes.c_uint32),
    ]

    @staticmethod
    def type_name():
        return "mems::RobotHint.v1"


ALL_TYPES = [Stamps, RawImuSample, CorrectedImuSample, OdometryState, RobotHint]
