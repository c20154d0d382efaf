"""The TUM VI benchmark's room sequences (Schubert et al., "The TUM VI Benchmark for Evaluating
Visual-Inertial Odometry", IROS 2018) as BahMoh/TUMVI-IMU-only-Dataset-room1-to-room6 keeps
them: a hand-held stereo-camera rig with a Bosch BMI160 IMU, walked through a room under motion
capture, its IMU and motion-capture topics exported from the data set's calibrated 512_16 bags
to CSV.

Per sequence N:
  dataset-roomN_512_16.csv     `Time,angular_velocity.x,angular_velocity.y,angular_velocity.z,
                               linear_acceleration.x,linear_acceleration.y,linear_acceleration.z`:
                               the bag's stamp in s, the angular rate in rad/s and the specific
                               force in m/s^2 (+9.81 on the axis pointing up at rest), in the
                               IMU's frame, 200 Hz;
  dataset-roomN_512_16_gt.csv  `Time,transform.translation.x,.y,.z,transform.rotation.x,.y,.z,.w`:
                               the motion-capture pose of the rig's marker body in the room (m,
                               z up; unit quaternion), 120 Hz, with gaps where the markers were
                               hidden.

Both files carry the bag's stamps, which the authors align between the IMU and the motion
capture. That is checked, not assumed: the magnitude of the rig's angular rate from successive
motion-capture attitudes, against the gyro's magnitude (a rotation does not change it, so no
frame is needed), over BIN_S bins and lags within MAX_LAG_S, must correlate at r >= MIN_R with
a lag within MAX_OFFSET_S and a slope in SLOPE_RANGE (deg/s against deg/s); the samples and the
track are then kept on the stamps as they are. Python standard library only.
"""

import math

import navego
from containers import ConvertError, room_track_truth

G0 = 9.80665  # m/s^2 per g
DEG = 180.0 / math.pi
IMU_COLUMNS = ("Time", "angular_velocity.x", "angular_velocity.y", "angular_velocity.z",
               "linear_acceleration.x", "linear_acceleration.y", "linear_acceleration.z")
POSE_COLUMNS = ("Time", "transform.translation.x", "transform.translation.y", "transform.translation.z",
                "transform.rotation.x", "transform.rotation.y", "transform.rotation.z", "transform.rotation.w")
MAX_POSE_STEP_S = 0.05  # attitude differences across a longer gap (hidden markers) give no rate
BIN_S = 0.1
LAG_STEP_S = 0.01
MAX_LAG_S = 0.5
MAX_OFFSET_S = 0.05
MIN_R = 0.75
SLOPE_RANGE = (0.7, 1.3)
TRACK_MIN_STEP_M = 0.1  # the track's length counts steps of at least this much (motion-capture noise at rest adds none)


def read_rows(text, where, columns):
    """The numeric rows of a CSV whose header is exactly `columns`, times increasing."""
    lines = [ln for ln in text.replace("\r\n", "\n").split("\n") if ln.strip()]
    if not lines or tuple(c.strip() for c in lines[0].split(",")) != columns:
        raise ConvertError(where, 1, None, f"header {lines[0][:120] if lines else ''!r}, expected {','.join(columns)}")
    rows = []
    for i, line in enumerate(lines[1:], start=2):
        cells = line.split(",")
        if len(cells) != len(columns):
            raise ConvertError(where, i, None, f"{len(cells)} fields, expected {len(columns)}")
        row = []
        for name, cell in zip(columns, cells):
            try:
                v = float(cell)
            except ValueError:
                raise ConvertError(where, i, name, f"{cell.strip()!r} is not a number") from None
            if not math.isfinite(v):
                raise ConvertError(where, i, name, f"{cell.strip()!r} is not finite")
            row.append(v)
        if rows and row[0] <= rows[-1][0]:
            raise ConvertError(where, i, "Time", f"{row[0]!r} does not follow {rows[-1][0]!r}")
        rows.append(row)
    if len(rows) < 2:
        raise ConvertError(where, None, None, f"{len(rows)} data rows")
    return rows


def samples(rows):
    """Canonical samples (t_s from the first row, specific force g, angular rate deg/s)."""
    t0 = rows[0][0]
    return [(r[0] - t0, r[4] / G0, r[5] / G0, r[6] / G0, r[1] * DEG, r[2] * DEG, r[3] * DEG) for r in rows]


def pose_rates(poses, t0):
    """(times, angular rate magnitudes deg/s) between successive motion-capture attitudes no
    more than MAX_POSE_STEP_S apart, times from t0 at the midpoints."""
    times, rates = [], []
    for a, b in zip(poses, poses[1:]):
        dt = b[0] - a[0]
        if dt > MAX_POSE_STEP_S:
            continue
        # q_a^-1 q_b: its vector part's length and scalar part give the turn between the two.
        ax, ay, az, aw = -a[4], -a[5], -a[6], a[7]
        bx, by, bz, bw = b[4:8]
        vx = aw * bx + ax * bw + ay * bz - az * by
        vy = aw * by - ax * bz + ay * bw + az * bx
        vz = aw * bz + ax * by - ay * bx + az * bw
        w = aw * bw - ax * bx - ay * by - az * bz
        times.append((a[0] + b[0]) / 2 - t0)
        rates.append(2 * math.atan2(math.sqrt(vx * vx + vy * vy + vz * vz), abs(w)) / dt * DEG)
    return times, rates


def recording(texts, wheres):
    """(samples, notes, truth, distance) of one sequence from its IMU and pose CSVs."""
    imu = read_rows(texts[0], wheres[0], IMU_COLUMNS)
    poses = read_rows(texts[1], wheres[1], POSE_COLUMNS)
    out = samples(imu)
    t0 = imu[0][0]
    gyro = [math.sqrt(s[4] ** 2 + s[5] ** 2 + s[6] ** 2) for s in out]
    lag, r, slope = navego.rate_lag([s[0] for s in out], gyro, *pose_rates(poses, t0), BIN_S, LAG_STEP_S, MAX_LAG_S)
    if r is None or r < MIN_R or abs(lag) > MAX_OFFSET_S or not SLOPE_RANGE[0] <= slope <= SLOPE_RANGE[1]:
        raise ConvertError(wheres[1], None, "Time", f"the motion capture's rotation rate does not follow the gyro's "
                           f"(lag {lag}, r {r}, slope {slope}): not on the IMU's clock, or the gyro is not in rad/s")
    track = [[round(p[0] - t0, 6), p[1], p[2]] for p in poses if 0.0 <= p[0] - t0 <= out[-1][0]]
    truth, walked = room_track_truth(
        track, TRACK_MIN_STEP_M,
        "the rig's motion-capture positions (the data set's pose topic, m, z up) on the IMU's clock (the bag's "
        "stamps; the rotation rates' lag is checked near 0): bench.py measures from the pose at the odometry's "
        "alignment to the last; the room's heading is not ours, so only distances are a truth",
        rate_check_lag_s=lag, rate_check_r=round(r, 4), rate_check_slope=round(slope, 4))
    notes = [f"Time s from {t0:.6f}; angular_velocity rad/s -> deg/s, linear_acceleration m/s^2 -> g (/9.80665)",
             f"motion capture on the IMU's stamps: rotation-rate magnitudes agree at lag {lag:+.2f} s, r = {r:.3f}, "
             f"gyro / motion capture {slope:.3f}"]
    return out, notes, truth, walked


def self_test():
    """A rig turning about a tilted axis at a varying rate while walking a circle: units, the
    rate check, the track; a pose log on another clock, or a gyro in deg/s, is refused;
    malformed input names the line and field."""
    def angle(t):
        return 0.8 * math.sin(0.9 * t) + 0.5 * math.sin(2.3 * t)

    axis = (0.6, 0.0, 0.8)
    imu = [",".join(IMU_COLUMNS)]
    for k in range(200 * 30):
        t = 100.0 + k / 200
        w = 0.8 * 0.9 * math.cos(0.9 * (t - 100)) + 0.5 * 2.3 * math.cos(2.3 * (t - 100))
        imu.append(f"{t:.6f},{w * axis[0]:.9f},0,{w * axis[2]:.9f},0,0,9.81")
    poses = [",".join(POSE_COLUMNS)]
    for k in range(120 * 30):
        t = 100.0 + k / 120
        h = angle(t - 100) / 2
        if 700 <= k < 760:  # markers hidden for half a second
            continue
        poses.append(f"{t:.6f},{math.cos(0.2 * (t - 100)):.6f},{math.sin(0.2 * (t - 100)):.6f},1.25,"
                     f"{axis[0] * math.sin(h):.9f},0,{axis[2] * math.sin(h):.9f},{math.cos(h):.9f}")
    out, notes, truth, walked = recording(["\n".join(imu), "\n".join(poses)], ["i.csv", "g.csv"])
    assert abs(out[0][3] - 9.81 / G0) < 1e-12 and abs(out[200][4] - float(imu[201].split(",")[1]) * DEG) < 1e-9, out[200]
    assert abs(truth["rate_check_lag_s"]) <= 0.01 and truth["rate_check_r"] > 0.99, truth
    assert abs(truth["rate_check_slope"] - 1.0) < 0.02 and abs(walked - 0.2 * out[-1][0]) < 0.1, (truth, walked)
    late = [poses[0]] + [",".join([f"{float(p.split(',')[0]) + 0.3:.6f}"] + p.split(",")[1:]) for p in poses[1:]]
    in_degrees = [imu[0]] + [",".join(line.split(",")[:1] + [f"{float(v) * DEG:.6f}" for v in line.split(",")[1:4]]
                                      + line.split(",")[4:]) for line in imu[1:]]
    for texts, needle in (([imu, late], "lag -0.3"), ([in_degrees, poses], "slope"),
                          ([imu[:5] + ["100.1,0,0,x,0,0,9.81"] + imu[5:], poses], "field 'angular_velocity.z'")):
        try:
            recording(["\n".join(texts[0]), "\n".join(texts[1])], ["b.csv", "g.csv"])
        except ConvertError as err:
            assert needle in str(err), str(err)
        else:
            raise AssertionError(f"no error for {needle}")
    return "tumvi_room_csv"
