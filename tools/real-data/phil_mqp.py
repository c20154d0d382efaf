"""PHIL's TurtleBot runs under motion capture (PHIL-MQP/phil, `recorded_sensor_data/
turtlebot_mocap_3_17/trial_N/`; Worcester Polytechnic Institute, "Position Hallucination and
Indoor Localization", 2018): a TurtleBot 2 (Kobuki base) carrying a Kauai Labs navX-MXP read by
a RoboRIO, driven under a Vicon system.

Files, per trial:
- `rio-data-*.csv`: the RoboRIO's log, a header row then one row per read (about 50 Hz).
  `raw_accel_x..z` are the navX's raw accelerometer in g (+1.01 g on z at rest: specific
  force, z up) and `raw_gyro_x..z` its raw gyroscope in deg/s (steps of 2000/32768 deg/s, the
  +-2000 deg/s range); `fpga time` is the RoboRIO's clock in s. The encoder and motor columns
  are zeros on the TurtleBot (its wheels are the Kobuki's, logged apart on another clock).
- `turtlebot_mocap_3_17 N.csv`: the Vicon export: `Objects`, the rate (100 Hz), the object
  names (`Global Angle NAME:NAME`, six columns each), the header `Frame,Sub Frame,RX,RY,RZ,
  TX,TY,TZ,...` and the units (rad, mm), then one row per frame. RX..RZ are the object's
  orientation as a rotation vector (axis times angle, rad); TX..TZ its position in mm. A frame
  where the object was not seen has empty cells and is skipped.

- `kobuki_data_*.csv`: the Kobuki's 16-bit wheel encoder counts (`left_ticks`, `right_ticks`)
  with `time_s`, `time_ns` on the Kobuki computer's Unix clock, about 42 Hz.

The three logs are cut to about the same span but stamped on three clocks. Each offset is
measured, as navego.py does for the rovers: the lag (within MAX_LAG_S, LAG_STEP_S steps) that
best correlates the IMU's yaw rate about its start-up up axis with the Vicon object's yaw rate
(its rotation vector's heading, differenced over +-DIFF_S) or the wheels' (their differential
speed over the wheel base), averaged over BIN_S bins. A best correlation below MIN_R refuses
the run. The same fit's slope (gyro over Vicon) checks the gyroscope's units and sign: on the
five runs taken it is 0.994-1.004 at r >= 0.998 (trial 6, which turns 9 degrees in all,
correlates at r = 0.88 and is refused). The samples pass through unchanged.

The Vicon object is the markers' frame, neither the base's nor the navX's. The base's heading is
the object's plus a constant (corpus.json's `body_yaw_on_vicon_object_deg`: the direction of
travel against the object's heading where the wheels say the base drives straight,
`travel_yaw_on_object`, which the conversion's notes give per run), and the navX's yaw on the
base (`sensor_yaw_on_body_deg`) turns that into our heading at the alignment (bench.py).
"""

import math

import navego
from containers import ConvertError

BIN_S = 0.25  # yaw-rate bins for the clock offset, s (the Vicon heading is smooth at 100 Hz)
DIFF_S = 0.05  # the Vicon yaw rate is the heading's central difference over +-DIFF_S, s
LAG_STEP_S = 0.05  # step of the offsets searched, s
MAX_LAG_S = 5.0  # the offsets searched, s
MIN_R = 0.9  # the correlation below which no offset is taken
TRACK_MIN_STEP_M = 0.01  # the truth's track length counts steps of at least this much (Vicon noise at rest: under 0.1 mm)
SPEED_WINDOW_S = 0.2  # the wheel speeds are tick differences over this much time, s
METRES_PER_TICK = 0.002436916871363930187454 * 0.035  # Kobuki wheel: rad per tick times radius, m
WHEEL_BASE_M = 0.23  # Kobuki wheel to wheel, m
RIO_COLUMNS = ("raw_accel_x", "raw_accel_y", "raw_accel_z", "raw_gyro_x", "raw_gyro_y", "raw_gyro_z", "fpga time")


def _number(cell, where, line, field):
    try:
        v = float(cell)
    except ValueError:
        raise ConvertError(where, line, field, f"not a number: {cell!r}") from None
    if not math.isfinite(v):
        raise ConvertError(where, line, field, f"not finite: {cell!r}")
    return v


def rio_samples(text, where):
    """(samples, notes): (t_s from the first row, accel g, gyro deg/s) from the RoboRIO log."""
    lines = text.splitlines()
    if not lines:
        raise ConvertError(where, 1, None, "empty file")
    header = [h.strip() for h in lines[0].split(",")]
    missing = [c for c in RIO_COLUMNS if c not in header]
    if missing:
        raise ConvertError(where, 1, missing[0], "column missing from the header")
    idx = [header.index(c) for c in RIO_COLUMNS]
    samples, t0 = [], None
    for n, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        cells = line.split(",")
        if len(cells) != len(header):
            raise ConvertError(where, n, None, f"{len(cells)} cells, the header has {len(header)}")
        v = [_number(cells[i], where, n, c) for i, c in zip(idx, RIO_COLUMNS)]
        t0 = v[6] if t0 is None else t0
        samples.append((v[6] - t0, *v[:6]))
    if len(samples) < 2:
        raise ConvertError(where, None, None, "fewer than two rows")
    return samples, [f"{where}: navX raw accelerometer (g) and gyroscope (deg/s), time 'fpga time' (s) from its first row"]


def yaw_of_rotation_vector(rx, ry, rz):
    """Heading (rad, counter-clockwise about z) of the body x axis turned by the rotation vector
    (axis times angle, rad): atan2(R[1][0], R[0][0]) of the Rodrigues matrix."""
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-12:
        return 0.0
    x, y, z = rx / angle, ry / angle, rz / angle
    c, s = math.cos(angle), math.sin(angle)
    return math.atan2(y * x * (1 - c) + z * s, c + x * x * (1 - c))


def vicon_track(text, where, name):
    """[(t_s from the first frame, x m, y m, heading rad unwrapped)] of object `name`."""
    lines = text.splitlines()
    if len(lines) < 6 or lines[0].strip().rstrip(",") != "Objects":
        raise ConvertError(where, 1, None, "not a Vicon object export (first line 'Objects')")
    rate = _number(lines[1].split(",")[0], where, 2, "rate")
    names = lines[2].split(",")
    col = next((i for i, c in enumerate(names) if c.strip().endswith(f"{name}:{name}")), None)
    if col is None:
        raise ConvertError(where, 3, name, "object not among the export's objects")
    if [c.strip() for c in lines[3].split(",")[col:col + 6]] != ["RX", "RY", "RZ", "TX", "TY", "TZ"]:
        raise ConvertError(where, 4, name, "expected the columns RX,RY,RZ,TX,TY,TZ")
    track, first, missing = [], None, 0
    for n, line in enumerate(lines[5:], start=6):
        cells = line.split(",")
        if not line.strip():
            continue
        if len(cells) < col + 6:
            raise ConvertError(where, n, name, f"{len(cells)} cells, the object's columns end at {col + 6}")
        if any(not c.strip() for c in cells[col:col + 6]):
            missing += 1
            continue
        frame = _number(cells[0], where, n, "Frame")
        first = frame if first is None else first
        rx, ry, rz, tx, ty, _ = (_number(c, where, n, h) for c, h in zip(cells[col:col + 6], ("RX", "RY", "RZ", "TX", "TY", "TZ")))
        heading = yaw_of_rotation_vector(rx, ry, rz)
        if track:
            heading = track[-1][3] + math.remainder(heading - track[-1][3], 2 * math.pi)
        track.append(((frame - first) / rate, tx / 1000.0, ty / 1000.0, heading))
    if len(track) < 2:
        raise ConvertError(where, None, name, "fewer than two frames with the object seen")
    return track, missing


def vicon_yaw_rate(track):
    """(times, rad/s): the Vicon heading's central difference over +-DIFF_S."""
    times, rates, j = [], [], 0
    for i, q in enumerate(track):
        while track[j][0] < q[0] - DIFF_S:
            j += 1
        k = next((k for k in range(i, len(track)) if track[k][0] >= q[0] + DIFF_S), None)
        if k is None:
            break
        times.append(q[0])
        rates.append((track[k][3] - track[j][3]) / (track[k][0] - track[j][0]))
    return times, rates


def clock_offset(samples, yaw_rates, where, field):
    """(offset s, r, slope): IMU time = other time + offset, the lag where the binned yaw rates
    (`yaw_rates`: (times, rad/s) on the other clock, the Vicon's or the Kobuki's) correlate
    best with the IMU's (r), and that fit's slope, gyro over other. A ConvertError naming
    `field` below MIN_R."""
    vt, vr = yaw_rates
    t_end = max(samples[-1][0], vt[-1]) + MAX_LAG_S
    it, ir = navego.imu_yaw_rate(samples)
    imu = navego._binned(ir, it, t_end, BIN_S)
    best = navego.best_lag(imu, vt, vr, t_end, MAX_LAG_S, LAG_STEP_S, BIN_S)
    if best is None or best[1] < MIN_R:
        raise ConvertError(where, None, field, f"no clock offset within {MAX_LAG_S} s correlates the yaw rates "
                                              f"(best r {None if best is None else round(best[1], 3)})")
    pairs = [(x, y) for x, y in zip(imu, best[2]) if x is not None and y is not None]
    mx, my = sum(p[0] for p in pairs) / len(pairs), sum(p[1] for p in pairs) / len(pairs)
    slope = sum((x - mx) * (y - my) for x, y in pairs) / sum((y - my) ** 2 for _, y in pairs)
    return round(best[0], 6), best[1], slope


def kobuki_ticks(text, where):
    """[(t_s from the first row, left ticks, right ticks)] of kobuki_data_*.csv (header
    left_ticks,right_ticks,time_s,time_ns; the Kobuki's 16-bit wheel encoder counts, logged
    on the Kobuki computer's Unix clock), the counts unwrapped."""
    lines = text.splitlines()
    if not lines or [h.strip() for h in lines[0].split(",")] != ["left_ticks", "right_ticks", "time_s", "time_ns"]:
        raise ConvertError(where, 1, None, "expected the header left_ticks,right_ticks,time_s,time_ns")
    rows, t0 = [], None
    for n, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        cells = line.split(",")
        if len(cells) != 4:
            raise ConvertError(where, n, None, f"{len(cells)} cells, expected 4")
        v = [_number(c, where, n, h) for c, h in zip(cells, ("left_ticks", "right_ticks", "time_s", "time_ns"))]
        if not all(0 <= x < 65536 for x in v[:2]):
            raise ConvertError(where, n, "left_ticks" if not 0 <= v[0] < 65536 else "right_ticks", "not a 16-bit count")
        t = v[2] + v[3] * 1e-9
        t0 = t if t0 is None else t0
        if rows:
            v[0] = rows[-1][1] + (v[0] - rows[-1][1] + 32768) % 65536 - 32768
            v[1] = rows[-1][2] + (v[1] - rows[-1][2] + 32768) % 65536 - 32768
            if t <= t0 + rows[-1][0]:
                raise ConvertError(where, n, "time_ns", "time does not increase")
        rows.append((t - t0, v[0], v[1]))
    if len(rows) < 2:
        raise ConvertError(where, None, None, "fewer than two rows")
    return rows


def kobuki_odometry(ticks):
    """[(t_s, forward speed m/s, yaw rate rad/s)] of the base from the wheel ticks, each the
    difference over the last SPEED_WINDOW_S (the log repeats counts between the base's
    updates), timed at the window's middle. Differential drive: v = (dl + dr) / 2,
    w = (dr - dl) / WHEEL_BASE_M, with METRES_PER_TICK and WHEEL_BASE_M from the Kobuki's
    driver (kobuki-base/kobuki_core@dd80596db8f60adc529f58f209a144587e5a0e6e,
    src/driver/diff_drive.cpp: tick_to_rad 0.002436916871363930187454, wheel radius 0.035 m,
    bias 0.23 m)."""
    rows, j = [], 0
    for t, left, right in ticks:
        while ticks[j + 1][0] <= t - SPEED_WINDOW_S:
            j += 1
        t_a, l_a, r_a = ticks[j]
        if t - t_a < SPEED_WINDOW_S:
            continue
        dl, dr = (left - l_a) * METRES_PER_TICK, (right - r_a) * METRES_PER_TICK
        rows.append(((t + t_a) / 2, (dl + dr) / 2 / (t - t_a), (dr - dl) / WHEEL_BASE_M / (t - t_a)))
    return rows


def travel_yaw_on_object(track, odom, min_speed=0.1, max_yaw_rate=0.05):
    """(median deg, count): the direction of travel (the Vicon track's chord over +-0.1 s)
    minus the object's heading, where the wheels (`odom` on the Vicon's clock) say the base
    drives straight ahead (faster than `min_speed` m/s, turning slower than `max_yaw_rate`
    rad/s); None without such a stretch. It checks the body heading the truth uses."""
    yaws, j = [], 0
    for i in range(10, len(track) - 10, 5):
        t = track[i][0]
        while j + 1 < len(odom) and odom[j + 1][0] <= t:
            j += 1
        _, v, w = odom[j]
        (_, x0, y0, _), (_, x1, y1, _) = track[i - 10], track[i + 10]
        if v > min_speed and abs(w) < max_yaw_rate and math.hypot(x1 - x0, y1 - y0) > 0.02:
            yaws.append(math.degrees(math.remainder(math.atan2(y1 - y0, x1 - x0) - track[i][3], 2 * math.pi)))
    if not yaws:
        return None
    yaws.sort()
    return yaws[len(yaws) // 2], len(yaws)


def track_truth(track, offset, r, slope, body_yaw_deg):
    """The truth: the Vicon track on the IMU's clock (`track`: [t_s, x, y, the base's heading:
    the object's plus `body_yaw_deg`]) and the last pose's distance from the first."""
    end = [track[-1][1] - track[0][1], track[-1][2] - track[0][2]]
    return {
        "kind": "mocap_track",
        "frame": "unknown_heading",
        "end_displacement_m": None,
        "end_distance_m": math.hypot(*end),
        "end_displacement_vicon_m": end,
        "poses": len(track),
        "clock_offset_s": offset,
        "clock_offset_r": round(r, 4),
        "gyro_over_vicon_yaw_rate": round(slope, 4),
        "body_yaw_on_vicon_object_deg": body_yaw_deg,
        "track": [[round(t + offset, 4), round(x, 5), round(y, 5), round(h + math.radians(body_yaw_deg), 5)]
                  for t, x, y, h in track],
        "track_min_step_m": TRACK_MIN_STEP_M,
        "source": "the Vicon export's phil_turtlebot object (TX, TY in mm) on the IMU's clock shifted by clock_offset_s "
                  "(measured from the yaw rates, phil_mqp.py), with the base's heading (the object's plus "
                  "body_yaw_on_vicon_object_deg); bench.py measures from the pose at the odometry's alignment to the last "
                  "and turns it into our frame by the base's heading there plus the navX's yaw on the base",
    }


def recording(texts, wheres, source):
    """(samples, notes, truth, Vicon track, wheel odometry rows on the IMU's clock) of one run
    from its RoboRIO log, Vicon export and Kobuki log (`texts`, named by `wheres`); `source` is
    its corpus.json source (the Vicon object's name, the base's yaw on it, the navX's on the base)."""
    samples, notes = rio_samples(texts[0], wheres[0])
    track, missing = vicon_track(texts[1], wheres[1], source["vicon_object"])
    offset, r, slope = clock_offset(samples, vicon_yaw_rate(track), wheres[1], "RZ")
    notes.append(f"Vicon clock offset {offset:+.2f} s (yaw-rate correlation r = {r:.4f}, gyro/Vicon slope {slope:.3f}); "
                 f"{missing} frames without the object skipped")
    odom = kobuki_odometry(kobuki_ticks(texts[2], wheres[2]))
    k_off, k_r, k_slope = clock_offset(samples, ([q[0] for q in odom], [q[2] for q in odom]), wheres[2], "time_ns")
    notes.append(f"wheel speeds from the Kobuki's ticks ({SPEED_WINDOW_S} s differences), clock offset {k_off:+.2f} s "
                 f"(yaw-rate correlation r = {k_r:.4f}, gyro/wheels slope {k_slope:.3f})")
    travel = travel_yaw_on_object(track, [(t + k_off - offset, v, w) for t, v, w in odom])
    notes.append("direction of travel minus the Vicon object's heading while driving straight: " +
                 ("no straight stretch" if travel is None else f"{travel[0]:.1f} deg (median of {travel[1]})"))
    truth = track_truth(track, offset, r, slope, source["body_yaw_on_vicon_object_deg"])
    truth["sensor_yaw_on_body_deg"] = source["sensor_yaw_on_body_deg"]
    return samples, notes, truth, track, [(t + k_off, v, w) for t, v, w in odom if t + k_off >= 0.0]


def _vicon_text(frames, name="phil_turtlebot"):
    head = ["Objects", "100", ",,Global Angle tag:tag,,,,,,Global Angle %s:%s,,,,," % (name, name),
            "Frame,Sub Frame" + ",RX,RY,RZ,TX,TY,TZ" * 2, ",," + "rad,rad,rad,mm,mm,mm," * 2]
    return "\n".join(head + frames) + "\n"


def self_test():
    """A robot circling counter-clockwise at 30 deg/s with the Vicon log starting 0.4 s after
    the IMU's: units, the offset and slope, the truth; malformed input names the line."""
    def heading(t):
        return math.radians(30.0) * max(0.0, t - 2.0)

    rio = ["raw_accel_x,raw_accel_y,raw_accel_z,raw_gyro_x,raw_gyro_y,raw_gyro_z,yaw,fpga time,navx time"]
    for i in range(50 * 30):
        t = i / 50
        rate = (30.0 + 10.0 * math.sin(t)) if t >= 2.0 else 0.0
        rio.append(f"0,0,1,0,0,{rate},0,{100.0 + t},{i}")
    samples, _ = rio_samples("\n".join(rio), "r.csv")
    assert samples[0][0] == 0.0 and abs(samples[100][6] - (30.0 + 10.0 * math.sin(2.0))) < 1e-9, samples[100]
    frames, h = [], 0.0
    for i in range(100 * 28):
        t = 0.4 + i / 100  # the Vicon clock: 0 at IMU time 0.4 s
        h += math.radians(30.0 + 10.0 * math.sin(t)) / 100 if t >= 2.0 else 0.0
        x, y = 0.5 * math.sin(h), 0.5 - 0.5 * math.cos(h)
        cells = ["", "", "", "", "", ""] if i == 7 else [0, 0, math.remainder(h, 2 * math.pi), 1000 * x, 1000 * y, 100]
        frames.append(",".join(str(c) for c in [i + 1, 0, 0, 0, 0, 1, 2, 3] + cells))
    track, missing = vicon_track(_vicon_text(frames), "v.csv", "phil_turtlebot")
    assert missing == 1 and len(track) == 100 * 28 - 1, (missing, len(track))
    assert abs(yaw_of_rotation_vector(0.0, 0.0, 2.5) - 2.5) < 1e-12
    assert abs(yaw_of_rotation_vector(0.0, 0.0, -3.5) - math.remainder(-3.5, 2 * math.pi)) < 1e-12
    assert abs(yaw_of_rotation_vector(math.pi, 0.0, 0.0)) < 1e-12  # upside down about x: x still ahead
    offset, r, slope = clock_offset(samples, vicon_yaw_rate(track), "v.csv", "RZ")
    assert abs(offset - 0.4) < 1e-9 and r > 0.99 and abs(slope - 1.0) < 0.02, (offset, r, slope)
    truth = track_truth(track, offset, r, slope, 90.0)
    assert abs(truth["track"][500][3] - track[500][3] - math.pi / 2) < 1e-4, truth["track"][500]
    # Driving straight along +x with the markers' x axis 30 degrees left of the travel: -30.
    line = [(i / 100, 0.005 * i, 0.0, math.radians(30.0)) for i in range(300)]
    yaw, n = travel_yaw_on_object(line, [(0.0, 0.5, 0.0)])
    assert abs(yaw + 30.0) < 1e-9 and n == 56, (yaw, n)
    assert travel_yaw_on_object(line, [(0.0, 0.5, 0.2)]) is None
    assert truth["track"][0][0] == 0.4 and abs(truth["end_distance_m"] - math.hypot(*truth["end_displacement_vicon_m"])) < 1e-12
    # The Kobuki turning on the spot at 0.1 rad/s, its left count wrapping below 0.
    step = 0.1 * WHEEL_BASE_M / 2 / 50 / METRES_PER_TICK  # ticks per 20 ms row on each wheel
    kob = ["left_ticks,right_ticks,time_s,time_ns"]
    for i in range(200):
        t_ns = 1521299413_000000000 + 20_000_000 * i
        kob.append(f"{int(round(300 - step * i)) % 65536},{int(round(100 + step * i))},{t_ns // 10**9},{t_ns % 10**9}")
    ticks = kobuki_ticks("\n".join(kob), "k.csv")
    assert ticks[-1][1] < 0 and abs(ticks[-1][0] - 3.98) < 1e-6, ticks[-1]
    odom = kobuki_odometry(ticks)
    assert abs(odom[0][0] - 0.1) < 1e-6 and all(abs(v) < 0.005 and abs(w - 0.1) < 0.005 for _, v, w in odom), odom[:3]
    try:
        kobuki_ticks("\n".join(kob[:5] + [kob[5].replace(",", ",7000", 1)]), "k.csv")
    except ConvertError as e:
        assert "k.csv" in str(e) and "line 6" in str(e) and "right_ticks" in str(e), str(e)
    else:
        raise AssertionError("no error for a count over 16 bits")
    bad = list(frames)
    bad[3] = bad[3].replace(",100", ",1O0", 1)
    try:
        vicon_track(_vicon_text(bad), "b.csv", "phil_turtlebot")
    except ConvertError as e:
        assert "b.csv" in str(e) and "line 9" in str(e) and "TZ" in str(e), str(e)
    else:
        raise AssertionError("no error for a malformed cell")
    try:
        rio_samples(rio[0].replace("raw_gyro_z", "gz") + "\n1,2,3,4,5,6,7,8,9", "h.csv")
    except ConvertError as e:
        assert "h.csv" in str(e) and "raw_gyro_z" in str(e), str(e)
    else:
        raise AssertionError("no error for a missing column")
    return "phil_turtlebot_vicon"
