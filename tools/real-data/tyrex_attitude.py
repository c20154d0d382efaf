"""Tyrex attitude benchmark (tyrex-team/benchmarks-attitude-smartphones): an Android phone's
IMU logs as samples and the Qualisys motion capture of its handler as the truth.

Per session, datasets/android/SESSION/ holds space-separated text logs, one event per line, the
first column the time in s from the start of the record (datasets/ios/SESSION/ alike, with times
from the phone's boot, description.txt's BootTime, and the accelerometer in g of acceleration,
-1 on the axis pointing up at rest, which is negated here; its gyroscope.txt is t, x, y, z):
  accelerometer.txt   t, x, y, z: specific force in m/s^2 (Android: +9.8 on the axis pointing up
                      at rest), the phone's axes (x right, y up the screen, z out of it);
  gyroscope.txt       t, x, y, z, and the driver's drift estimate x, y, z: the uncalibrated
                      angular rate in rad/s (Android's TYPE_GYROSCOPE_UNCALIBRATED), its first
                      three values taken as the part's output;
  timeAlignment.txt   one number, d in s: Qualisys time = phone time + d (the authors'
                      findTimeDiffBetweenQualisysAndSmartphone.m, fitted on the acceleration
                      norms).
The accelerometer and the gyro are not sampled together: each accelerometer event is a sample,
with the gyro interpolated linearly to its time (events outside the gyro's span are dropped and
counted). datasets/qualisys/SESSION.mat is the QTM export (a level-5 MAT-file holding a struct):
FrameRate (Hz), RigidBodies.Positions (1 x 3 x N, mm) and RigidBodies.Rotations (1 x 9 x N: the
handler's frame, column-major, turning the phone's axes into the room's, z up), NaN where the
markers were not seen. Python standard library only.
"""

import math

from containers import ConvertError, room_track_truth

G0 = 9.80665  # m/s^2 per g
DEG = 180.0 / math.pi
MOCAP_TRACK_MIN_STEP_M = 0.1
# Longest interval between two gyro events the samples are interpolated across, s: the phones
# log their gyros at 100-200 Hz, so a longer one is events lost, not a slow sensor. The Nexus
# 5's Guillaume_Nexus5_NoDist_AR gyroscope.txt stops for 23.7 s (67.1-90.8 s) and 11.9 s;
# interpolated across, the phone's turns in them vanished from the gyro while its gravity
# turned by 90 degrees.
MAX_GYRO_GAP_S = 0.5


def _rows(text, where, width):
    """Numeric rows of a space-separated log, each with at least `width` values."""
    rows = []
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        fields = line.split()
        if len(fields) < width:
            raise ConvertError(where, n, None, f"{len(fields)} values, expected {width}")
        try:
            row = [float(v) for v in fields[:width]]
        except ValueError:
            raise ConvertError(where, n, None, f"not a number in {line.strip()!r}") from None
        if not all(math.isfinite(v) for v in row):
            raise ConvertError(where, n, None, "a value is not finite")
        if rows and row[0] < rows[-1][0]:
            raise ConvertError(where, n, "t", f"time {row[0]} s runs backwards from {rows[-1][0]} s")
        rows.append(row)
    if len(rows) < 2:
        raise ConvertError(where, None, None, "fewer than two events")
    return rows


# Accelerometer units to g of specific force: Android logs m/s^2 of specific force (+9.8 up);
# iOS (CoreMotion) logs g of acceleration with gravity's sign (-1 on the axis pointing up), which
# the authors' loadiOSDataset.m negates.
ACCEL_TO_G = {"android": 1.0 / G0, "ios": -1.0}


def boot_time(text, where):
    """description.txt of an iOS session ("[Time]", "BootTime = s"): the boot time its log
    times count from (the authors' loadiOSDataset.m subtracts it)."""
    for n, line in enumerate(text.splitlines(), 1):
        key, sep, value = line.partition("=")
        if sep and key.strip() == "BootTime":
            try:
                return float(value)
            except ValueError:
                raise ConvertError(where, n, "BootTime", f"not a number: {value.strip()!r}") from None
    raise ConvertError(where, None, "BootTime", "missing")


def samples_from_logs(acc_text, gyro_text, wheres, os_name, time_zero=0.0):
    """Samples (t_s, ax_g, ay_g, az_g, gx_dps, gy_dps, gz_dps) at the accelerometer's events,
    t_s from the first kept one, the gyro interpolated linearly; the logs' times count from
    `time_zero` (an iOS session's boot time). Returns (samples, phone time of the first sample,
    notes)."""
    to_g = ACCEL_TO_G[os_name]
    acc = [[r[0] - time_zero, *r[1:]] for r in _rows(acc_text, wheres[0], 4)]
    gyr = [[r[0] - time_zero, *r[1:]] for r in _rows(gyro_text, wheres[1], 4)]
    kept, j, gap, outside = [], 0, None, 0
    for t, ax, ay, az in acc:
        if t < gyr[0][0] or t > gyr[-1][0]:
            outside += 1
            continue
        while gyr[j + 1][0] < t:
            j += 1
        (t0, *w0), (t1, *w1) = gyr[j], gyr[j + 1]
        if t1 - t0 > MAX_GYRO_GAP_S:
            # The samples end at the gyro log's first gap: the turns in it are unknown.
            gap = (t0, t1)
            break
        f = (t - t0) / (t1 - t0) if t1 > t0 else 0.0
        w = [(a + f * (b - a)) * DEG for a, b in zip(w0, w1)]
        kept.append((t, ax * to_g, ay * to_g, az * to_g, *w))
    if not kept:
        raise ConvertError(wheres[0], None, "t", "no accelerometer event within the gyro's span")
    start = kept[0][0]
    unit = "m/s^2 -> g (/9.80665)" if os_name == "android" else "g of acceleration -> g of specific force (negated)"
    notes = [f"accelerometer {unit}, gyroscope (first three values) rad/s -> deg/s; one sample per accelerometer event, "
             f"the gyro interpolated linearly to it ({outside} accelerometer events outside the gyro's span dropped); "
             f"t_s = phone time (log time minus {time_zero} s) minus the first kept event's"]
    if gap is not None:
        notes.append(f"{wheres[1]}: no gyro event for {gap[1] - gap[0]:.1f} s from phone time {gap[0]:.1f} s "
                     f"(longer than {MAX_GYRO_GAP_S} s: events lost); the samples end there, at "
                     f"{gap[0] - start:.1f} s, and the truth with them")
    return [(t - start, *rest) for t, *rest in kept], start, notes


def time_offset(text, where):
    """timeAlignment.txt: the one number d (s) with Qualisys time = phone time + d."""
    fields = text.split()
    try:
        if len(fields) != 1:
            raise ValueError
        d = float(fields[0])
    except ValueError:
        raise ConvertError(where, 1, None, f"expected one number, got {text.strip()[:40]!r}") from None
    if not math.isfinite(d):
        raise ConvertError(where, 1, None, "the offset is not finite")
    return d


def _frame(values, k, width):
    return values[k * width : (k + 1) * width]


def _aligned_heading(c):
    """Heading (rad, counter-clockwise from the room's x) of the frame the odometry aligns to
    when the phone's axes turn into the room's by the column-major 3 x 3 `c`: eskf::align turns
    the measured up onto z by the smallest rotation, so its x axis is the phone's after that
    rotation; the turn from that level frame to the room is a yaw alone."""
    col = [[c[r + 3 * k] for r in range(3)] for k in range(3)]  # the phone's axes in the room
    up = [col[k][2] for k in range(3)]  # the room's z in the phone's axes
    # Smallest rotation taking `up` onto the phone's z: about axis up x z, by acos(up_z).
    ax, ay = up[1], -up[0]
    s, cz = math.hypot(ax, ay), up[2]
    if s < 1e-9:
        x_level = [1.0, 0.0, 0.0]
    else:
        kx, ky = ax / s, ay / s
        # Rodrigues on e_x with axis (kx, ky, 0), cos cz, sin s: the level frame's x in the
        # phone's axes is the inverse rotation of e_x.
        x_level = [cz + kx * kx * (1 - cz), kx * ky * (1 - cz), ky * s]
    east = sum(col[k][0] * x_level[k] for k in range(3))
    north = sum(col[k][1] * x_level[k] for k in range(3))
    return math.atan2(north, east)


def mocap_track_truth(arrays, offset_s, start_s, duration_s, where):
    """The handler's Qualisys track [t_s, x, y, heading] on the samples' clock (Qualisys time -
    offset_s - start_s), frames with markers seen and within the recording, x and y in m in the
    room, heading as _aligned_heading; the last kept position's distance from the first and the
    track's length over steps of at least 0.1 m."""
    def field(suffix):
        names = [k for k in arrays if k.endswith(suffix)]
        if len(names) != 1 or arrays[names[0]][1] is None:
            raise ConvertError(where, None, suffix.lstrip("."), "missing from the QTM export")
        return arrays[names[0]]

    rate = field(".FrameRate")[1][0]
    dims, pos = field(".RigidBodies.Positions")
    rot = field(".RigidBodies.Rotations")[1]
    frames = len(pos) // 3
    if dims[:2] != (1, 3) or len(rot) != 9 * frames or rate <= 0:
        raise ConvertError(where, None, "RigidBodies", f"positions {dims}, {len(rot)} rotation values, frame rate {rate}")
    track, hidden = [], 0
    for k in range(frames):
        t = k / rate - offset_s - start_s
        if t < 0 or t > duration_s:
            continue
        p, c = _frame(pos, k, 3), _frame(rot, k, 9)
        if not all(math.isfinite(v) for v in (*p, *c)):
            hidden += 1
            continue
        track.append([round(t, 6), round(p[0] / 1000, 5), round(p[1] / 1000, 5), round(_aligned_heading(c), 6)])
    if len(track) < 2:
        raise ConvertError(where, None, "RigidBodies.Positions", "fewer than two seen positions within the recording")
    return room_track_truth(
        track, MOCAP_TRACK_MIN_STEP_M,
        "Qualisys rigid body of the phone's handler (mm -> m, room frame, z up) on the samples' clock by timeAlignment.txt, with the heading "
        "the odometry's alignment would give the phone there: bench.py counts from the pose at the odometry's alignment and turns the truth into its frame",
        poses_hidden=hidden)


def self_test():
    """Two accelerometer events between three gyro events; a phone lying flat with its x axis
    along the room's y (heading pi/2), and one tilted 90 degrees about its x axis; a log line
    that runs backwards names the file, line and field."""
    acc = "0.10 0 0 9.80665\n0.20 0 4.903325 0\n0.50 1 1 1\n"
    gyr = "0.05 0 0 0 9 9 9\n0.15 0 0 0.2 9 9 9\n0.25 0 0 0.4 9 9 9\n"
    samples, start, _ = samples_from_logs(acc, gyr, ["a.txt", "g.txt"], "android")
    assert start == 0.1 and len(samples) == 2 and samples[0][:4] == (0.0, 0.0, 0.0, 1.0), samples
    assert abs(samples[0][6] - 0.1 * DEG) < 1e-9 and abs(samples[1][6] - 0.3 * DEG) < 1e-9 and abs(samples[1][2] - 0.5) < 1e-12, samples
    # A gyro log that stops for 1 s: the samples end at its start, and a note names it.
    gapped, _, gap_notes = samples_from_logs(acc + "1.2 0 0 1\n", gyr + "1.25 0 0 0 9 9 9\n", ["a.txt", "g.txt"], "android")
    assert len(gapped) == 2 and "g.txt: no gyro event for 1.0 s" in gap_notes[-1], (gapped, gap_notes)
    try:
        samples_from_logs(acc, gyr.replace("0.15", "0.01"), ["a.txt", "g.txt"], "android")
        raise AssertionError("a gyro time running backwards was taken")
    except ConvertError as e:
        assert "g.txt" in str(e) and "line 2" in str(e) and "'t'" in str(e), e
    # iOS: g with gravity's sign, times from boot.
    ios, start, _ = samples_from_logs("100.10 0 0 -1\n100.12 0.5 0 -1\n", "100.05 0 0 0\n100.15 0 0 0\n", ["a.txt", "g.txt"], "ios",
                                      boot_time("[Time]\nBootTime = 100.0", "d.txt"))
    assert ios[0][1:4] == (-0.0, -0.0, 1.0) and ios[1][1] == -0.5 and abs(start - 0.1) < 1e-9, (ios, start)
    assert time_offset("  -2.35e+00\n", "o.txt") == -2.35
    try:
        time_offset("1 2", "o.txt")
        raise AssertionError("two offsets were taken")
    except ConvertError as e:
        assert "o.txt: line 1" in str(e), e
    flat_y = [0, 1, 0, -1, 0, 0, 0, 0, 1]  # columns: phone x -> room y, phone y -> room -x, z -> z
    assert abs(_aligned_heading(flat_y) - math.pi / 2) < 1e-9
    # Tilted about x by 90 degrees (screen facing the room's -y): x stays the room's x.
    assert abs(_aligned_heading([1, 0, 0, 0, 0, 1, 0, -1, 0])) < 1e-9
    nan = float("nan")
    arrays = {"s.FrameRate": ((1, 1), (10.0,)),
              "s.RigidBodies.Positions": ((1, 3, 3), (0.0, 0.0, 1000.0, 3000.0, 4000.0, 1000.0, nan, 0.0, 0.0)),
              "s.RigidBodies.Rotations": ((1, 9, 3), tuple(flat_y * 3))}
    # Qualisys time = phone time - 0.1 s, the first sample at phone time 0.1 s: frame k at k/10 s.
    truth, walked = mocap_track_truth(arrays, -0.1, 0.1, 1.0, "q.mat")
    assert truth["track"][0] == [0.0, 0.0, 0.0, round(math.pi / 2, 6)] and truth["track"][1][:3] == [0.1, 3.0, 4.0], truth
    assert truth["poses_hidden"] == 1, truth
    assert abs(truth["end_distance_m"] - 5.0) < 1e-9 and abs(walked - 5.0) < 1e-9, (truth, walked)
    return "tyrex android + QTM"
