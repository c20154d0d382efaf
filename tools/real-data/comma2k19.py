"""comma2k19 (commaai/comma2k19): one segment's processed logs as samples, CAN speeds and a truth.

A segment directory holds NumPy arrays (read by containers.read_npy), each a timestamp array
`t` (s on the device's boot clock) beside a `value` array (README.md, "Log Format"):
  processed_log/IMU/accelerometer      specific force, m/s^2, axes [forward, right, down] of the
                                       device (-9.8 on down at rest): right-handed, z down;
  processed_log/IMU/gyro               angular rate, rad/s, same axes, with Android's gyro bias
                                       removed (gyro_uncalibrated minus gyro_bias, a constant
                                       the phone learnt before the segment: the segment is one
                                       minute cut from a drive, and a live odometry would have
                                       learnt its bias by then too);
  processed_log/CAN/speed              the car's speed from its CAN bus, m/s;
  global_pose/frame_times, frame_positions
                                       the camera's position at each video frame (20 Hz) from
                                       the authors' tightly coupled INS/GNSS/vision optimizer,
                                       in ECEF (m).

The truth is the position track in east/north metres about the first pose, so that bench.py can
count from the pose where the odometry aligned. Only distances are a truth: the device's z axis
points down, so the odometry's alignment (the smallest turn of the measured up onto z, a turn of
nearly 180 degrees) takes its x axis about a horizontal axis set by the small residual tilt, and
its heading at alignment follows no axis of the car that the poses could give. Python standard
library only.
"""

import math

from containers import ConvertError, path_length

G0 = 9.80665  # m/s^2 per g
DEG = 180.0 / math.pi
WGS84_A = 6378137.0
WGS84_E2 = 6.69437999014e-3
POSE_TRACK_MIN_STEP_M = 0.1


def _column(rows, where, width):
    """Rows of a .npy array checked to have `width` values each."""
    for i, row in enumerate(rows):
        if len(row) != width:
            raise ConvertError(where, None, "shape", f"row {i} has {len(row)} values, expected {width}")
    return rows


def _times(rows, where, n):
    """A timestamp array of n rows as a list of floats (s)."""
    if len(rows) != n:
        raise ConvertError(where, None, "shape", f"{len(rows)} timestamps for {n} values")
    return [r[0] for r in _column(rows, where, 1)]


def segment(arrays, wheres):
    """arrays, wheres: accelerometer t, value, gyro t, value, CAN speed t, value.
    Returns (samples, speeds, t0, notes): samples (t_s, ax_g, ay_g, az_g, gx_dps, gy_dps,
    gz_dps) with t_s from the first accelerometer sample (boot clock t0), speeds (t_s, m/s) on
    the same clock."""
    acc = _column(arrays[1], wheres[1], 3)
    gyr = _column(arrays[3], wheres[3], 3)
    ta = _times(arrays[0], wheres[0], len(acc))
    tg = _times(arrays[2], wheres[2], len(gyr))
    if not ta:
        raise ConvertError(wheres[0], None, None, "no samples")
    if len(tg) != len(ta):
        raise ConvertError(wheres[2], None, "shape", f"{len(tg)} gyro samples against {len(ta)} accelerometer samples")
    for i, (a, g) in enumerate(zip(ta, tg)):
        if a != g:
            raise ConvertError(wheres[2], None, "t", f"sample {i} at {g} s, the accelerometer's at {a} s: not one IMU sample")
    speed = _column(arrays[5], wheres[5], 1)
    ts = _times(arrays[4], wheres[4], len(speed))
    t0 = ta[0]
    samples = [(t - t0, a[0] / G0, a[1] / G0, a[2] / G0, w[0] * DEG, w[1] * DEG, w[2] * DEG)
               for t, a, w in zip(ta, acc, gyr)]
    speeds = [(t - t0, v[0]) for t, v in zip(ts, speed)]
    notes = ["IMU accelerometer m/s^2 -> g (/9.80665), gyro (Android's bias removed) rad/s -> deg/s, axes [forward, right, down] passed through; "
             "t_s = boot-clock time minus the first accelerometer sample's"]
    return samples, speeds, t0, notes


def _ecef_latitude(x, y, z):
    """Geodetic latitude (rad) of an ECEF point (m) on WGS-84 (fixed-point iteration on the
    height; converged to far below a microradian in five steps near the surface)."""
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1 - WGS84_E2))
    for _ in range(5):
        n = WGS84_A / math.sqrt(1 - WGS84_E2 * math.sin(lat) ** 2)
        h = p / math.cos(lat) - n
        lat = math.atan2(z, p * (1 - WGS84_E2 * n / (n + h)))
    return lat


def _enu_axes(origin):
    """East and north unit vectors (ECEF) at an ECEF point."""
    lat, lon = _ecef_latitude(*origin), math.atan2(origin[1], origin[0])
    east = (-math.sin(lon), math.cos(lon), 0.0)
    north = (-math.sin(lat) * math.cos(lon), -math.sin(lat) * math.sin(lon), math.cos(lat))
    return east, north


def _dot(a, b):
    return sum(u * v for u, v in zip(a, b))


def pose_track_truth(times, positions, t0, wheres):
    """The global poses (frame_times, frame_positions; wheres alike) as a track [t_s, east,
    north] about the first pose, t_s on the samples' clock (boot time minus t0), the last
    pose's distance from the first, and the track's length over steps of at least 0.1 m."""
    pos = _column(positions, wheres[1], 3)
    ts = _times(times, wheres[0], len(pos))
    if len(pos) < 2:
        raise ConvertError(wheres[1], None, "shape", f"{len(pos)} positions (two or more needed)")
    east, north = _enu_axes(pos[0])
    track = []
    for t, p in zip(ts, pos):
        d = [p[k] - pos[0][k] for k in range(3)]
        track.append([round(t - t0, 6), round(_dot(east, d), 4), round(_dot(north, d), 4)])
    walked = path_length([row[1:3] for row in track], POSE_TRACK_MIN_STEP_M)
    return {
        "kind": "pose_track",
        "frame": "unknown_heading",
        "end_displacement_m": None,
        "end_distance_m": math.hypot(*track[-1][1:3]),
        "end_displacement_enu_m": track[-1][1:3],
        "poses": len(track),
        "track": track,
        "track_min_step_m": POSE_TRACK_MIN_STEP_M,
        "source": "global_pose (the authors' INS/GNSS/vision optimizer, ECEF) in east/north about the first pose: bench.py measures from the pose at the "
                  "odometry's alignment; the odometry's heading follows no axis of the car (z-down device), so only distances are a truth",
    }, walked


def self_test():
    """A two-sample segment, a gyro time that is not the accelerometer's (names the file and
    field), and two poses at latitude 0, longitude 0."""
    from containers import npy_bytes, read_npy

    def arr(rows):
        return read_npy(npy_bytes(rows), "a.npy")

    imu_t = arr([[100.0], [100.01]])
    arrays = [imu_t, arr([[0.0, 0.0, -G0], [1.0, 0.0, -G0]]), imu_t, arr([[0.0, 0.0, math.pi], [0.0, 0.0, 0.0]]),
              arr([[100.005]]), arr([[12.5]])]
    wheres = ["at", "av", "gt", "gv", "st", "sv"]
    samples, speeds, t0, _ = segment(arrays, wheres)
    assert samples[0] == (0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 180.0) and abs(samples[1][1] - 1.0 / G0) < 1e-12, samples
    assert t0 == 100.0 and abs(speeds[0][0] - 0.005) < 1e-9 and speeds[0][1] == 12.5, speeds
    bad = list(arrays)
    bad[2] = arr([[100.0], [100.02]])
    try:
        segment(bad, wheres)
        raise AssertionError("a gyro time off the accelerometer's was taken")
    except ConvertError as e:
        assert "gt" in str(e) and "'t'" in str(e), e
    # ECEF (a, 0, 0) is latitude 0, longitude 0: east is +y, north +z.
    truth, walked = pose_track_truth(arr([[100.0], [101.0]]), arr([[WGS84_A, 0.0, 0.0], [WGS84_A, 3.0, 4.0]]), 100.0, ["ft", "fp"])
    assert truth["track"] == [[0.0, 0.0, 0.0], [1.0, 3.0, 4.0]] and abs(walked - 5.0) < 1e-9, (truth, walked)
    return "comma2k19 npy"
