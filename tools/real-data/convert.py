#!/usr/bin/env python3
"""Converts the real-data corpus (corpus.json) to the canonical CSV plus a sidecar JSON.

Each source is a public GitHub repository fetched as a bare git snapshot (the search tool's
`fetch`, or `git clone --bare`); files are read with `git show COMMIT:PATH`, so the working
copy does not matter and the commit named in corpus.json is the one converted.

Output, per recording, in the output directory (default $MEMS_REAL_DATA or /work/real-data):
  ID.csv   canonical CSV (tools/recording/src/csv.rs): t_s, ax_g, ay_g, az_g (specific force, g,
           sensor frame), gx_dps, gy_dps, gz_dps (angular rate, deg/s, sensor frame);
  ID.json  sidecar: source, licence, IMU, platform, truth, distance, the authors' result, the
           benchmark's extra arguments, and what the conversion saw (repeated rows, gaps, ...).

Rows are converted as published: repeated rows, equal or irregular timestamps are kept (the
odometry must cope with them) and counted in the sidecar. Only rows that are not samples are
dropped (an Xsens DOT export's all-zero placeholder before the first packet), and the sidecar
says so. Python standard library only (MAT-files, .npy arrays and ROS bags are read by the small
readers of containers.py, because numpy/scipy/rosbag are not dependencies of this repository).

Usage:
  convert.py [--git-dir SOURCE=DIR ...] [--mirrors DIR] [--out DIR] [--only ID ...]
  convert.py --self-test
"""

import argparse
import json
import math
import os
import statistics
import struct
import subprocess
import sys
from pathlib import Path

import comma2k19
import containers
import navego
import phil_mqp
import rtklib_logs
import tumvi
import tyrex_attitude
from containers import (HINT_TOPIC, MCAP_T0_NS, RAW_TOPIC, ConvertError, bag_bytes, bag_messages, decode_imu,
                        decode_navsatfix, decode_odometry, imu_message, mat_bytes, mat_matrix, mcap_bytes,
                        mcap_messages, navsatfix_message, npy_bytes, odometry_message, read_mat, read_mcap_records,
                        read_npy)

G0 = 9.80665  # standard gravity, m/s^2 per g (the canonical CSV's g)
DEG = 180.0 / math.pi
HERE = Path(__file__).resolve().parent
WGS84_A = 6378137.0
WGS84_E2 = 6.69437999014e-3


def number(text, where, line, field):
    """A finite float from a CSV cell, or a ConvertError naming the cell."""
    try:
        value = float(text)
    except ValueError:
        raise ConvertError(where, line, field, f"{text.strip()!r} is not a number") from None
    if not math.isfinite(value):
        raise ConvertError(where, line, field, f"{text.strip()!r} is not finite")
    return value


# ---------------------------------------------------------------------------------------------
# Source formats. Each parser takes (text or bytes, where) and returns (samples, notes) with
# samples as (t_s, ax_g, ay_g, az_g, gx_dps, gy_dps, gz_dps) in file order.


def _lines(text):
    return text.replace("\r\n", "\n").replace("\r", "\n").split("\n")


def _header_index(header, wanted, where, line):
    index = {}
    for key, name in wanted.items():
        found = [i for i, h in enumerate(header) if h.strip() == name or h.strip().endswith(":" + name)]
        if len(found) != 1:
            raise ConvertError(where, line, name, f"column {'missing' if not found else 'repeated'} in the header")
        index[key] = found[0]
    return index


def _rows(lines, first, where, width):
    """(line number, cells) of the data rows from index `first`; a short row is an error."""
    for i in range(first, len(lines)):
        if not lines[i].strip():
            continue
        cells = lines[i].split(",")
        if len(cells) < width:
            raise ConvertError(where, i + 1, None, f"{len(cells)} fields, expected at least {width}")
        yield i + 1, cells


def _named_rows(text, where, names):
    """The rows of a CSV whose first line is its header, as {key: number} for `names` (key ->
    column name)."""
    lines = _lines(text)
    header = lines[0].split(",")
    idx = _header_index(header, names, where, 1)
    for ln, cells in _rows(lines, 1, where, len(header)):
        yield {k: number(cells[i], where, ln, names[k]) for k, i in idx.items()}


def parse_xio_csv(text, where):
    """x-io NGIMU CSV: time s, gyroscope deg/s, accelerometer g (already our units)."""
    names = {
        "t": "Time (s)",
        "gx": "Gyroscope X (deg/s)", "gy": "Gyroscope Y (deg/s)", "gz": "Gyroscope Z (deg/s)",
        "ax": "Accelerometer X (g)", "ay": "Accelerometer Y (g)", "az": "Accelerometer Z (g)",
    }
    out = [(v["t"], v["ax"], v["ay"], v["az"], v["gx"], v["gy"], v["gz"])
           for v in _named_rows(text, where, names)]
    return out, ["units as published: g and deg/s; time column as published"]


def parse_openshoe_txt(text, where, rate_hz):
    """OpenShoe: f x,y,z m/s^2 then omega x,y,z rad/s per line, no time (t = i / rate)."""
    out = []
    n = 0
    for i, line in enumerate(_lines(text)):
        if not line.strip():
            continue
        cells = line.split(",")
        if len(cells) != 6:
            raise ConvertError(where, i + 1, None, f"{len(cells)} fields, expected 6")
        f = [number(c, where, i + 1, f"column {k + 1}") for k, c in enumerate(cells)]
        out.append((n / rate_hz, f[0] / G0, f[1] / G0, f[2] / G0, f[3] * DEG, f[4] * DEG, f[5] * DEG))
        n += 1
    return out, [f"no time column: t_s = sample index / {rate_hz} Hz (the authors' Ts)",
                 "m/s^2 -> g (/9.80665), rad/s -> deg/s"]


def parse_sensorconnect_csv(text, where):
    """MicroStrain SensorConnect CSV: Time s, scaledAccel g, scaledGyro rad/s."""
    names = {
        "t": "Time",
        "ax": "scaledAccelX", "ay": "scaledAccelY", "az": "scaledAccelZ",
        "gx": "scaledGyroX", "gy": "scaledGyroY", "gz": "scaledGyroZ",
    }
    out = [(v["t"], v["ax"], v["ay"], v["az"], v["gx"] * DEG, v["gy"] * DEG, v["gz"] * DEG)
           for v in _named_rows(text, where, names)]
    return out, ["scaledAccel already in g; scaledGyro rad/s -> deg/s; time column as published"]


def parse_xsens_dot_csv(text, where):
    """Xsens DOT export: SampleTimeFine us (u32), Acc m/s^2, Gyr deg/s."""
    lines = _lines(text)
    first = 1 if lines and lines[0].strip().startswith("sep=") else 0
    header = [h.strip() for h in lines[first].split(",")]
    names = {
        "n": "PacketCounter", "t": "SampleTimeFine",
        "ax": "Acc_X", "ay": "Acc_Y", "az": "Acc_Z", "gx": "Gyr_X", "gy": "Gyr_Y", "gz": "Gyr_Z",
    }
    idx = _header_index(header, names, where, first + 1)
    width = max(idx.values()) + 1
    out, notes = [], ["Acc m/s^2 -> g (/9.80665); Gyr already deg/s; t_s from SampleTimeFine (us, 32-bit, unwrapped)"]
    t0 = prev = None
    wraps = 0
    for ln, cells in _rows(lines, first + 1, where, width):
        v = {k: number(cells[i], where, ln, names[k]) for k, i in idx.items()}
        values = [v[k] for k in ("ax", "ay", "az", "gx", "gy", "gz")]
        if not out and t0 is None and all(x == 0.0 for x in values):
            notes.append(f"dropped line {ln}: all-zero placeholder row (PacketCounter {int(v['n'])}) before the first packet")
            continue
        stamp = int(v["t"])
        if prev is not None and stamp < prev and prev - stamp > 2**31:
            wraps += 1
        prev = stamp
        stamp += wraps * 2**32
        if t0 is None:
            t0 = stamp
        out.append(((stamp - t0) * 1e-6, v["ax"] / G0, v["ay"] / G0, v["az"] / G0, v["gx"], v["gy"], v["gz"]))
    if wraps:
        notes.append(f"SampleTimeFine wrapped {wraps} time(s)")
    return out, notes


def parse_broad_mat(buf, where):
    """BROAD trial (MAT v5): imu_acc m/s^2, imu_gyr rad/s at `sampling_rate` Hz, no time column
    (t = i / rate); the optical reference `opt_pos` (m, NaN where the markers were not seen).
    Returns (samples, notes, arrays) so that the truth is taken from the same file."""
    arrays = read_mat(buf, where)
    acc = mat_matrix(arrays, "imu_acc", where)
    gyr = mat_matrix(arrays, "imu_gyr", where)
    rate = mat_matrix(arrays, "sampling_rate", where)[0][0]
    if len(acc) != len(gyr) or not acc or len(acc[0]) != 3 or len(gyr[0]) != 3:
        raise ConvertError(where, None, "imu_acc", f"expected two N x 3 arrays, got {len(acc)} and {len(gyr)} rows")
    if not (rate > 0 and math.isfinite(rate)):
        raise ConvertError(where, None, "sampling_rate", f"{rate} is not a rate")
    out = []
    for i, (a, w) in enumerate(zip(acc, gyr)):
        values = list(a) + list(w)
        if not all(math.isfinite(v) for v in values):
            raise ConvertError(where, None, "imu_acc" if not all(math.isfinite(v) for v in a) else "imu_gyr",
                               f"sample {i} (0-based) is not finite")
        out.append((i / rate, a[0] / G0, a[1] / G0, a[2] / G0, w[0] * DEG, w[1] * DEG, w[2] * DEG))
    return out, [f"no time column: t_s = sample index / sampling_rate ({rate:.6g} Hz)",
                 "imu_acc m/s^2 -> g (/9.80665), imu_gyr rad/s -> deg/s"], arrays


def _stamped_rows(text, where, names):
    """Rows of a FrictionMaps stateLogger CSV (first column a pandas index, then `s` and `ns`):
    (t in s as a float of s + ns * 1e-9, {key: number}) with the integer stamp kept exact."""
    wanted = {"s": "s", "ns": "ns", **names}
    for v in _named_rows(text, where, wanted):
        if v["ns"] < 0 or v["ns"] >= 1e9 or v["s"] != int(v["s"]) or v["ns"] != int(v["ns"]):
            raise ConvertError(where, None, "ns", f"stamp {v['s']} s {v['ns']} ns is not a ROS time")
        yield int(v["s"]) * 1_000_000_000 + int(v["ns"]), v


# Hints from the VESC's odometry (forward speed from the motor's electrical RPM): the robot is
# called stationary only after this long at exactly zero speed, as the simulated encoder
# controller of docs/hints.md does (no tick for 0.1 s).
VESC_STATIONARY_AFTER_S = 0.1
VESC_SPEED_SIGMA_MPS = 0.05
HINT_STATIONARY, HINT_SOURCE_ENCODERS, HINT_SPEED_VALID = 1, 4, 8


def parse_vesc_f1tenth(imu_text, odom_text, where_imu, where_odom):
    """FrictionMaps stateLogger: imuData.csv (the VESC's IMU: ax..az in g, wx..wz in deg/s
    whatever the dataset README says, see corpus.json) and odomData.csv (vx, m/s, from the
    VESC's motor speed) -> samples and robot hints on the same clock (ROS time, s + ns).
    Times are made relative to the first IMU sample."""
    names = {"ax": "ax", "ay": "ay", "az": "az", "wx": "wx", "wy": "wy", "wz": "wz"}
    rows = list(_stamped_rows(imu_text, where_imu, names))
    if not rows:
        raise ConvertError(where_imu, None, None, "no samples")
    t0 = rows[0][0]
    samples = [((ns - t0) * 1e-9, v["ax"], v["ay"], v["az"], v["wx"], v["wy"], v["wz"]) for ns, v in rows]
    hints = []
    zero_since = None
    for ns, v in _stamped_rows(odom_text, where_odom, {"vx": "vx"}):
        t = (ns - t0) * 1e-9
        if v["vx"] == 0.0:
            zero_since = t if zero_since is None else zero_since
        else:
            zero_since = None
        # The source bit on every hint, moving or not: the encoders say whether the car moves
        # (ipc_types::hint_flags), so a moving hint overrules an IMU rest flag.
        flags = HINT_SPEED_VALID | HINT_SOURCE_ENCODERS
        if zero_since is not None and t - zero_since >= VESC_STATIONARY_AFTER_S:
            flags |= HINT_STATIONARY
        hints.append({"t_s": t, "forward_speed_mps": v["vx"], "forward_speed_sigma_mps": VESC_SPEED_SIGMA_MPS,
                      "flags": flags})
    notes = ["imuData ax..az already g (+1 g on z at rest), wx..wz already deg/s; t_s = ROS stamp (s + ns) minus the first IMU sample's",
             f"robot hints from odomData vx (m/s): speed valid, 1-sigma {VESC_SPEED_SIGMA_MPS} m/s; stationary (encoders) after "
             f"{VESC_STATIONARY_AFTER_S} s at exactly 0 m/s; published at their own stamp (no latency known)"]
    return samples, notes, hints


# Hints from a ROS robot's wheel odometry (nav_msgs/Odometry of its velocity controller): the
# forward speed of the base from the wheel encoders, stationary (encoders) once the base has
# been at rest for 0.1 s, as the simulated encoder controller of docs/hints.md calls it. At
# rest the controller reports round-off (1e-15 m/s), hence a threshold far below one count.
ODOM_STILL_MPS, ODOM_STILL_RPS = 1e-3, 1e-3
ODOM_STATIONARY_AFTER_S = 0.1
ODOM_SPEED_SIGMA_MPS = 0.05


def odometry_hints(rows):
    """Robot hints from (t_s, forward speed m/s, yaw rate rad/s) wheel-odometry rows."""
    hints, still_since = [], None
    for t, speed, yaw_rate in rows:
        if abs(speed) < ODOM_STILL_MPS and abs(yaw_rate) < ODOM_STILL_RPS:
            still_since = t if still_since is None else still_since
        else:
            still_since = None
        flags = HINT_SPEED_VALID | HINT_SOURCE_ENCODERS
        if still_since is not None and t - still_since >= ODOM_STATIONARY_AFTER_S:
            flags |= HINT_STATIONARY
        hints.append({"t_s": t, "forward_speed_mps": speed, "forward_speed_sigma_mps": ODOM_SPEED_SIGMA_MPS, "flags": flags})
    return hints


def parse_ros_robot_bag(buf, where, topics):
    """A ROS 1 bag of a wheeled robot: `topics` {"imu", "odom", "fix"} name its sensor_msgs/Imu
    (rad/s, m/s^2, REP 103), nav_msgs/Odometry (wheel odometry) and sensor_msgs/NavSatFix
    topics. Times are the messages' header stamps minus the first IMU sample's. Returns
    (samples, notes, hints, fixes) with fixes as (t_s, latitude deg, longitude deg, east-east
    covariance m^2), those without a fix (status < 0) left out."""
    imu, odom, fixes, no_fix = [], [], [], 0
    for topic, kind, data in bag_messages(buf, where, set(topics.values())):
        if topic == topics["imu"]:
            imu.append(decode_imu(data, where, topic))
        elif topic == topics["odom"]:
            odom.append(decode_odometry(data, where, topic))
        else:
            stamp, status, lat, lon, cov = decode_navsatfix(data, where, topic)
            if status < 0:
                no_fix += 1
                continue
            fixes.append((stamp, lat, lon, cov))
    for key, rows in (("imu", imu), ("odom", odom), ("fix", fixes)):
        if not rows:
            raise ConvertError(where, None, topics[key], "no messages on this topic")
    t0 = imu[0][0]
    samples = [((s - t0) * 1e-9, a[0] / G0, a[1] / G0, a[2] / G0, w[0] * DEG, w[1] * DEG, w[2] * DEG) for s, w, a in imu]
    hints = odometry_hints([((s - t0) * 1e-9, v, wz) for s, v, wz in odom])
    notes = [f"{topics['imu']}: linear_acceleration m/s^2 -> g (/9.80665), angular_velocity rad/s -> deg/s; t_s = header stamp minus the first IMU sample's",
             f"robot hints from {topics['odom']} twist.linear.x (m/s, wheel encoders): speed valid, 1-sigma {ODOM_SPEED_SIGMA_MPS} m/s; "
             f"stationary (encoders) after {ODOM_STATIONARY_AFTER_S} s below {ODOM_STILL_MPS} m/s and {ODOM_STILL_RPS} rad/s",
             f"{topics['fix']}: {len(fixes)} fixes, {no_fix} without a fix left out"]
    return samples, notes, hints, [((s - t0) * 1e-9, lat, lon, cov) for s, lat, lon, cov in fixes]


# ---------------------------------------------------------------------------------------------
# Truth.


def gcp_truth(buf, where):
    """Footprint ground control points: end distance from the start and the walked length."""
    arrays = read_mat(buf, where)
    ok = mat_matrix(arrays, "GCP_exist_and_correct", where)[0][0]
    if not ok:
        raise ConvertError(where, None, "GCP_exist_and_correct", "the authors mark these GCP as missing or wrong")
    gcp = mat_matrix(arrays, "GCP_meters", where)
    if len(gcp) < 2 or len(gcp[0]) != 2:
        raise ConvertError(where, None, "GCP_meters", f"expected N x 2 with N >= 2, got {len(gcp)} x {len(gcp[0]) if gcp else 0}")
    walked = sum(math.dist(a, b) for a, b in zip(gcp, gcp[1:]))
    end = [gcp[-1][0] - gcp[0][0], gcp[-1][1] - gcp[0][1]]
    footprints = [[x - gcp[0][0], y - gcp[0][1]] for x, y in gcp]
    return {
        "kind": "gcp",
        "frame": "unknown_heading",
        "end_displacement_m": None,
        "end_distance_m": math.hypot(*end),
        "end_displacement_gcp_frame_m": end,
        "footprints": len(gcp),
        "footprints_m": footprints,
        "tile_edge_m": mat_matrix(arrays, "tile_edge_length", where)[0][0],
        "source": "GCP_meters: every footprint relative to the first (footprints_m) and the last one (end_*); the GCP frame's heading is not the odometry's: bench.py turns it onto ours at the third footprint, as the authors do (own_data.py, strideAlign = 3), or uses only the end's distance. The GCP y axis is the authors' flipped one (own_data.py negates it to match their z-down INS frame), which makes it a proper rotation of our z-up frame",
    }, walked


def local_east_north(fixes):
    """(east, north) in m of every (latitude, longitude) fix in degrees, relative to the
    first: a local tangent plane with the meridian and prime-vertical radii of curvature of
    WGS-84 at the first fix, exact to well under 1 cm over the few hundred metres here."""
    lat0 = math.radians(fixes[0][0])
    s2 = math.sin(lat0) ** 2
    r_n = WGS84_A * (1 - WGS84_E2) / (1 - WGS84_E2 * s2) ** 1.5
    r_e = WGS84_A / math.sqrt(1 - WGS84_E2 * s2)
    return [(math.radians(lon - fixes[0][1]) * r_e * math.cos(lat0), math.radians(lat - fixes[0][0]) * r_n)
            for lat, lon in fixes]


# The WID GNSS log's rows come at 100 Hz (its `Timestamp` steps 0.1 per row): the MRU-P's own
# gyro rows correlate best with the car's IMU at 100.0-100.1 Hz of 99-101 Hz searched.
GNSS_ROW_HZ = 100.0
SYNC_BIN_S = 0.02  # bins of the gyro magnitudes correlated to time the GNSS log, s
SYNC_SMOOTH_S = 0.5  # their boxcar: the two IMUs' vibration differs, their turns do not
SYNC_MAX_LAG_S = 5.0  # the two logs start within seconds (their durations agree to 4 s)
SYNC_MIN_R = 0.8  # the correlation below which no offset is taken


def _smoothed_bins(times, values, t_end):
    """Mean of `values` per SYNC_BIN_S bin from 0 to `t_end` (navego.py's binning; None where a
    bin holds none), then a SYNC_SMOOTH_S boxcar over the bins that hold some."""
    means = navego._binned(values, times, t_end, SYNC_BIN_S)
    half = int(SYNC_SMOOTH_S / SYNC_BIN_S) // 2
    out = []
    for k, m in enumerate(means):
        window = [x for x in means[max(0, k - half) : k + half + 1] if x is not None]
        out.append(sum(window) / len(window) if m is not None else None)
    return out


def gnss_clock_offset(samples, gnss_gyro, where):
    """(offset s, r): the car IMU's time of the GNSS log's first row, to a bin, the lag (SYNC_BIN_S steps
    within SYNC_MAX_LAG_S) where the GNSS unit's gyro magnitude (rows at GNSS_ROW_HZ) best
    correlates (r) with the car samples' (t_s, accel g, gyro deg/s), both averaged per bin and
    smoothed (a rotation between the two units does not change a magnitude). ConvertError
    naming the file if no lag reaches SYNC_MIN_R."""
    n_lag = int(round(SYNC_MAX_LAG_S / SYNC_BIN_S))
    span = max(samples[-1][0], len(gnss_gyro) / GNSS_ROW_HZ) + 2 * SYNC_MAX_LAG_S
    # Both series start SYNC_MAX_LAG_S into the bins so that any lag keeps them inside.
    car = _smoothed_bins([q[0] + SYNC_MAX_LAG_S for q in samples],
                         [math.sqrt(q[4] ** 2 + q[5] ** 2 + q[6] ** 2) for q in samples], span)
    gnss = _smoothed_bins([k / GNSS_ROW_HZ + SYNC_MAX_LAG_S for k in range(len(gnss_gyro))], gnss_gyro, span)
    n_bins = len(car)
    best = None
    for lag in range(-n_lag, n_lag + 1):
        shifted = [gnss[k - lag] if 0 <= k - lag < n_bins else None for k in range(n_bins)]
        r = navego._correlation(car, shifted)
        if r is not None and (best is None or r > best[1]):
            best = (lag * SYNC_BIN_S, r)
    if best is None or best[1] < SYNC_MIN_R:
        raise ConvertError(where, None, "Gyro_X", f"no clock offset within {SYNC_MAX_LAG_S} s correlates the two IMUs' rates (best {best})")
    return best


def gnss_truth(text, where, samples):
    """RTK GNSS log: the last fix relative to the first (local east/north), the track on the
    car samples' clock (`track`: [t_s, east, north], the rows timed by [`gnss_clock_offset`])
    and the track's length."""
    lines = _lines(text)
    header = lines[0].split(",")
    names = {"lat": "Lat_GNSS", "lon": "Long_GNSS", "gx": "Gyro_X", "gy": "Gyro_Y", "gz": "Gyro_Z"}
    idx = _header_index(header, names, where, 1)
    fixes, gyro = [], []
    for ln, cells in _rows(lines, 1, where, len(header)):
        fixes.append((number(cells[idx["lat"]], where, ln, "Lat_GNSS"), number(cells[idx["lon"]], where, ln, "Long_GNSS")))
        gyro.append(math.sqrt(sum(number(cells[idx[k]], where, ln, names[k]) ** 2 for k in ("gx", "gy", "gz"))))
    if len(fixes) < 2:
        raise ConvertError(where, None, None, "fewer than two fixes")
    offset, r = gnss_clock_offset(samples, gyro, where)
    points = local_east_north(fixes)
    end = list(points[-1])
    return {
        "kind": "gnss_track",
        "frame": "unknown_heading",
        "end_displacement_m": None,
        "end_distance_m": math.hypot(*end),
        "end_displacement_enu_m": end,
        "fixes": len(fixes),
        "clock_offset_s": round(offset, 3),
        "clock_offset_r": round(r, 3),
        "track": [[round(k / GNSS_ROW_HZ + offset, 4), round(e, 4), round(n, 4)] for k, (e, n) in enumerate(points)],
        "track_min_step_m": GNSS_TRACK_MIN_STEP_M,
        "source": "GNSS.csv (RTK, local east/north about the first fix), rows at 100 Hz on the car IMU's clock shifted by clock_offset_s (measured from the two units' gyro magnitudes, convert.py); bench.py measures from the fix at the odometry's alignment and turns the track onto ours",
    }, containers.path_length(points, GNSS_TRACK_MIN_STEP_M)


def broad_truth(arrays, where):
    """BROAD's optical reference: the trial starts and ends at rest in the same place; the
    end's offset from the start (first and last seen marker positions, m) and the track's
    length. Returned as a closed loop (the offset is millimetres) with the measured offset
    kept as the tolerance."""
    pos = mat_matrix(arrays, "opt_pos", where)
    seen = [p for p in pos if len(p) == 3 and all(math.isfinite(v) for v in p)]
    if len(seen) < 2:
        raise ConvertError(where, None, "opt_pos", "fewer than two positions seen")
    end = [seen[-1][k] - seen[0][k] for k in range(3)]
    offset = math.hypot(end[0], end[1])
    if offset > 0.05:
        raise ConvertError(where, None, "opt_pos", f"the trial ends {offset:.3f} m from its start: not a closed loop")
    return {
        "kind": "closed_loop",
        "frame": "any",
        "end_displacement_m": [0.0, 0.0],
        "end_distance_m": 0.0,
        "tolerance_m": offset,
        "end_offset_mocap_m": end,
        "positions_seen": len(seen),
        "positions_missing": len(pos) - len(seen),
        "source": "opt_pos (OptiTrack, m): the last seen position minus the first; the box rests in the same place at both ends (offset in tolerance_m)",
    }, containers.path_length([p[:2] for p in seen], 0.01)


GNSS_TRACK_MIN_STEP_M = 0.5


GNSS_TRACK_SOURCE = ("GNSS fixes (sensor_msgs/NavSatFix) on the recording's clock, local east/north: bench.py measures "
                     "from the fix at the odometry's alignment to the last; the heading is not ours, so only distances are a truth")


def gnss_track_truth(fixes, where, source=GNSS_TRACK_SOURCE):
    """A robot's own GNSS fixes (t_s on the recording's clock, latitude, longitude, east-east
    covariance m^2): the track in local east/north metres (`track`: [t_s, east, north]) so that
    bench.py can measure from the fix where the odometry aligned, the last fix's distance from
    the first, and the track's length over steps of at least 0.5 m (fix noise at rest adds
    none). Our heading is not north, so only distances are a truth. `source` says where the
    fixes come from."""
    if len(fixes) < 2:
        raise ConvertError(where, None, None, "fewer than two fixes")
    points = local_east_north([(lat, lon) for _, lat, lon, _ in fixes])
    sigmas = sorted(math.sqrt(max(cov, 0.0)) for *_, cov in fixes)
    return {
        "kind": "gnss_track",
        "frame": "unknown_heading",
        "end_displacement_m": None,
        "end_distance_m": math.hypot(*points[-1]),
        "end_displacement_enu_m": list(points[-1]),
        "fixes": len(fixes),
        "fix_sigma_east_median_m": sigmas[len(sigmas) // 2],
        "track": [[round(t, 6), round(e, 4), round(n, 4)] for (t, *_), (e, n) in zip(fixes, points)],
        "track_min_step_m": GNSS_TRACK_MIN_STEP_M,
        "source": source,
    }, containers.path_length(points, GNSS_TRACK_MIN_STEP_M)


RTK_TRACK_MIN_STEP_M = 0.1
# The synchronised slice's IMU samples per RTK position: 120 Hz against 10 Hz (the MoRPINet
# README's rates).
SYNC_SAMPLES_PER_FIX = 12
# How closely the slice's gyro magnitudes must equal the raw samples' to be the same samples,
# deg/s: the slice is the raw export turned into the car's axes (a rotation keeps the
# magnitude), so they agree to rounding.
SYNC_MATCH_DPS = 1e-6


def sync_offset(samples, sync, where):
    """The index of the converted sample (t_s, accel g, gyro deg/s) where the authors'
    synchronised IMU slice (an N x 6 .npy: accelerometer m/s^2, gyro deg/s, in the car's axes)
    starts: where every one of the slice's gyro magnitudes equals the raw samples' to within
    SYNC_MATCH_DPS. ConvertError naming the file when no offset or more than one does."""
    raw = [math.sqrt(q[4] ** 2 + q[5] ** 2 + q[6] ** 2) for q in samples]
    ours = [math.sqrt(r[3] ** 2 + r[4] ** 2 + r[5] ** 2) for r in sync]
    found = [off for off in range(len(raw) - len(ours) + 1)
             if all(abs(raw[off + k] - ours[k]) <= SYNC_MATCH_DPS for k in range(len(ours)))]
    if len(found) != 1:
        raise ConvertError(where, None, "gyro", f"the slice's {len(ours)} gyro magnitudes match the raw samples at {len(found)} offsets, not one")
    return found[0]


def rtk_ned_truth(buf, where, times=None):
    """RTK positions as a .npy N x 3 array (north, east, down in m, relative to the start):
    the last position's horizontal distance from the first and the track's length over steps
    of at least 0.1 m. With `times` (one per position, s, on the recording's clock) the track
    too (`track`: [t_s, east, north], a right-handed plane with z up), so that bench.py can
    measure from the position at the odometry's alignment; without, only the distance is a
    truth (the heading is not ours)."""
    ned = read_npy(buf, where)
    if len(ned) < 2 or len(ned[0]) != 3:
        raise ConvertError(where, None, "shape", f"expected N x 3 (north, east, down) with N >= 2, got {len(ned)} x {len(ned[0]) if ned else 0}")
    if times is not None and len(times) != len(ned):
        raise ConvertError(where, None, "shape", f"{len(ned)} positions for {len(times)} times")
    end = [ned[-1][k] - ned[0][k] for k in range(3)]
    truth = {
        "kind": "rtk_endpoints",
        "frame": "unknown_heading",
        "end_displacement_m": None,
        "end_distance_m": math.hypot(end[0], end[1]),
        "end_displacement_ned_m": end,
        "positions": len(ned),
        "source": "RTK positions (north, east, down): the last minus the first; the odometry's heading is fixed at its alignment, not north, so only the distance is a truth",
    }
    if times is not None:
        truth.update({
            "kind": "rtk_track",
            "track": [[round(t, 6), round(q[1] - ned[0][1], 4), round(q[0] - ned[0][0], 4)] for t, q in zip(times, ned)],
            "track_min_step_m": RTK_TRACK_MIN_STEP_M,
            "source": "RTK positions (north, east, down) on the IMU's clock: the authors' synchronised IMU slice (syncdata/imu) found in the raw export by its gyro magnitudes, 12 samples per position; bench.py measures from the position at the odometry's alignment and turns the track onto ours",
        })
    return truth, containers.path_length([p[:2] for p in ned], RTK_TRACK_MIN_STEP_M)


def pf_pose_truth(text, where, t0_ns):
    """Lidar particle-filter poses on a known map (FrictionMaps pfPoseData.csv, x and y in m):
    the last pose relative to the first, and the track's length. The map frame's heading is
    not the odometry's, so only the distance is a truth. The track itself is kept (`track`:
    [t_s, x, y] with t_s on the recording's clock, seconds after its first IMU sample at
    `t0_ns`, and the car's heading, rad, from the pose's quaternion z and w: the filter's poses
    are planar), so that bench.py can measure from the pose where the odometry aligned (a car
    that drives off at once aligns at its first stop) and turn the truth into the odometry's
    frame when the IMU's yaw on the car is known."""
    rows = list(_stamped_rows(text, where, {"x": "x", "y": "y", "qz": "q.z", "qw": "q.w"}))
    points = [(v["x"], v["y"]) for _, v in rows]
    if len(points) < 2:
        raise ConvertError(where, None, None, "fewer than two poses")
    end = [points[-1][0] - points[0][0], points[-1][1] - points[0][1]]
    return {
        "kind": "pf_endpoints",
        "frame": "unknown_heading",
        "end_displacement_m": None,
        "end_distance_m": math.hypot(*end),
        "end_displacement_map_m": end,
        "poses": len(points),
        "track": [[round((ns - t0_ns) * 1e-9, 6), v["x"], v["y"], 2 * math.atan2(v["qz"], v["qw"])] for ns, v in rows],
        "source": "pfPoseData.csv: the particle filter's last pose minus its first (map frame, lidar on a known map); the odometry's heading is fixed at its alignment, so only the distance is a truth",
    }, containers.path_length(points, 0.1)


# ---------------------------------------------------------------------------------------------
# Conversion driver.


def git_show(git_dir, commit, path):
    proc = subprocess.run(["git", "--git-dir", str(git_dir), "show", f"{commit}:{path}"], capture_output=True)
    if proc.returncode != 0:
        msg = proc.stderr.decode(errors="replace").strip().splitlines()
        raise ConvertError(f"{git_dir} {commit}:{path}", None, None, (msg[0] if msg else "git show failed") +
                           " (fetch the repository again, or check the commit in corpus.json)")
    return proc.stdout


def sample_stats(samples, rate_hz):
    """What the odometry will meet in the time column and the rows, and the start-up rest."""
    times = [s[0] for s in samples]
    steps = [b - a for a, b in zip(times, times[1:])]
    nominal = 1.0 / rate_hz
    repeated_rows = sum(1 for a, b in zip(samples, samples[1:]) if a == b)
    first_motion = next((s[0] for s in samples
                         if abs(math.sqrt(s[1] ** 2 + s[2] ** 2 + s[3] ** 2) - 1.0) > 0.1
                         or math.sqrt(s[4] ** 2 + s[5] ** 2 + s[6] ** 2) > 20.0), None)
    return {
        "samples": len(samples),
        "duration_s": times[-1] - times[0] if times else 0.0,
        "median_step_s": statistics.median(steps) if steps else None,
        "equal_timestamps": sum(1 for d in steps if d == 0),
        "backward_timestamps": sum(1 for d in steps if d < 0),
        "gaps_over_1.5_steps": sum(1 for d in steps if d > 1.5 * nominal),
        "repeated_rows": repeated_rows,
        "first_motion_s": first_motion,
        "first_motion_rule": "first sample with | |f| - 1 g | > 0.1 g or |w| > 20 deg/s",
    }


def write_csv(path, samples, comments):
    with open(path, "w", encoding="utf-8") as f:
        for c in comments:
            f.write(f"# {c}\n")
        f.write("t_s,ax_g,ay_g,az_g,gx_dps,gy_dps,gz_dps\n")
        for s in samples:
            f.write("%.9f,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n" % s)


class SourceFiles:
    """The files of one recording, read from the source's snapshot with `git show COMMIT:PATH`."""

    def __init__(self, source, paths, git_dir):
        self.repo, self.commit, self.paths, self.git_dir = source["repo"], source["commit"], paths, git_dir

    def where(self, i):
        return f"{self.repo}@{self.commit}:{self.paths[i]}"

    def raw(self, i):
        return git_show(self.git_dir, self.commit, self.paths[i])

    def text(self, i):
        try:
            return self.raw(i).decode("utf-8-sig")
        except UnicodeDecodeError as e:
            raise ConvertError(self.where(i), None, None, f"not UTF-8 text: {e}") from None


# Per source format: (recording, source, files) -> (samples, notes, truth, distance, hints);
# truth and distance None where corpus.json states them, hints None without robot hints.
def _load_xio(rec, source, f):
    return (*parse_xio_csv(f.text(0), f.where(0)), None, None, None)


def _load_openshoe(rec, source, f):
    return (*parse_openshoe_txt(f.text(0), f.where(0), rec["rate_hz"]), None, None, None)


def _load_sensorconnect(rec, source, f):
    return (*parse_sensorconnect_csv(f.text(0), f.where(0)), *gcp_truth(f.raw(1), f.where(1)), None)


def _load_xsens_dot(rec, source, f):
    samples, notes = parse_xsens_dot_csv(f.text(0), f.where(0))
    return (samples, notes, *gnss_truth(f.text(1), f.where(1), samples), None)


def _load_xsens_dot_rtk(rec, source, f):
    samples, notes = parse_xsens_dot_csv(f.text(0), f.where(0))
    sync = read_npy(f.raw(2), f.where(2))
    off = sync_offset(samples, sync, f.where(2))
    n = len(sync) // SYNC_SAMPLES_PER_FIX
    if off + (n - 1) * SYNC_SAMPLES_PER_FIX >= len(samples):
        raise ConvertError(f.where(2), None, "shape", "the slice runs past the raw samples")
    times = [samples[off + k * SYNC_SAMPLES_PER_FIX][0] for k in range(n)]
    notes.append(f"RTK positions timed by the synchronised slice, found at sample {off} ({times[0]:.3f} s)")
    return (samples, notes, *rtk_ned_truth(f.raw(1), f.where(1), times), None)


def _load_broad(rec, source, f):
    samples, notes, arrays = parse_broad_mat(f.raw(0), f.where(0))
    return (samples, notes, *broad_truth(arrays, f.where(0)), None)


def _load_vesc(rec, source, f):
    imu_text = f.text(0)
    samples, notes, hints = parse_vesc_f1tenth(imu_text, f.text(1), f.where(0), f.where(1))
    t0_ns = next(_stamped_rows(imu_text, f.where(0), {}))[0]
    truth, distance = pf_pose_truth(f.text(2), f.where(2), t0_ns)
    truth["sensor_yaw_on_body_deg"] = source.get("sensor_yaw_on_body_deg")
    return samples, notes, truth, distance, hints


def _load_ros_bag(rec, source, f):
    samples, notes, hints, fixes = parse_ros_robot_bag(f.raw(0), f.where(0), source["topics"])
    return (samples, notes, *gnss_track_truth(fixes, f.where(0)), hints)


def _load_comma2k19(rec, source, f):
    arrays = [read_npy(f.raw(i), f.where(i)) for i in range(8)]
    samples, speeds, t0, notes = comma2k19.segment(arrays[:6], [f.where(i) for i in range(6)])
    # The CAN speed has no yaw rate: the car is called stationary on the speed alone.
    hints = odometry_hints([(t, v, 0.0) for t, v in speeds])
    notes.append(f"robot hints from {rec['paths'][5]} (CAN speed, m/s): speed valid, 1-sigma {ODOM_SPEED_SIGMA_MPS} m/s; "
                 f"stationary (encoders) after {ODOM_STATIONARY_AFTER_S} s below {ODOM_STILL_MPS} m/s")
    truth, distance = comma2k19.pose_track_truth(*arrays[6:8], t0, [f.where(i) for i in range(6, 8)])
    return samples, notes, truth, distance, hints


def _load_tyrex(rec, source, f):
    os_name = "ios" if source["format"] == "tyrex_ios_qtm" else "android"
    zero = tyrex_attitude.boot_time(f.text(4), f.where(4)) if os_name == "ios" else 0.0
    samples, start, notes = tyrex_attitude.samples_from_logs(f.text(0), f.text(1), [f.where(0), f.where(1)], os_name, zero)
    offset = tyrex_attitude.time_offset(f.text(2), f.where(2))
    truth, distance = tyrex_attitude.mocap_track_truth(read_mat(f.raw(3), f.where(3)), offset, start, samples[-1][0], f.where(3))
    truth["sensor_yaw_on_body_deg"] = source.get("sensor_yaw_on_body_deg")
    return samples, notes, truth, distance, None


def _load_navego(rec, source, f):
    samples, notes = navego.samples(read_mat(f.raw(0), f.where(0)), f.where(0))
    fixes = navego.reference_fixes(read_mat(f.raw(1), f.where(1)), f.where(1))
    track = [(t, e, n) for (t, _, _), (e, n) in zip(fixes, local_east_north([q[1:] for q in fixes]))]
    offset, r = navego.clock_offset(samples, track, f.where(1))
    notes.append(f"reference clock offset {offset:+.1f} s (yaw-rate correlation r = {r:.2f}, navego.clock_offset)")
    distance = containers.path_length([q[1:] for q in track], navego.TRACK_MIN_STEP_M)
    return samples, notes, navego.track_truth(track, offset, r), distance, None


def _load_rtklib(rec, source, f):
    texts = [f.text(0), f.raw(1), f.text(2)]
    samples, notes, fixes, timing = rtklib_logs.recording(texts, [f.where(i) for i in range(3)], local_east_north)
    truth, distance = gnss_track_truth(fixes, f.where(2), rtklib_logs.TRUTH_SOURCE)
    truth.update(timing)
    return samples, notes, truth, distance, None


def _load_tumvi(rec, source, f):
    return (*tumvi.recording([f.text(0), f.text(1)], [f.where(0), f.where(1)]), None)


def _load_phil(rec, source, f):
    samples, notes, truth, track, odom = phil_mqp.recording([f.text(i) for i in range(3)], [f.where(i) for i in range(3)], source)
    notes.append(f"robot hints: speed valid, 1-sigma {ODOM_SPEED_SIGMA_MPS} m/s; stationary (encoders) after "
                 f"{ODOM_STATIONARY_AFTER_S} s below {ODOM_STILL_MPS} m/s")
    return samples, notes, truth, containers.path_length([q[1:3] for q in track], phil_mqp.TRACK_MIN_STEP_M), odometry_hints(odom)


LOADERS = {
    "xio_csv": _load_xio, "openshoe_txt": _load_openshoe, "sensorconnect_csv": _load_sensorconnect,
    "xsens_dot_csv": _load_xsens_dot, "xsens_dot_rtk_npy": _load_xsens_dot_rtk, "broad_mat": _load_broad,
    "vesc_f1tenth_csv": _load_vesc, "ros1_bag_robot": _load_ros_bag, "comma2k19_npy": _load_comma2k19,
    "tyrex_android_qtm": _load_tyrex, "tyrex_ios_qtm": _load_tyrex, "navego_planetary_mat": _load_navego,
    "phil_turtlebot_vicon": _load_phil, "rtklib_imu_csv": _load_rtklib,
    "tumvi_room_csv": _load_tumvi,
}


def convert_recording(rec, source, git_dir, out_dir):
    commit = source["commit"]
    paths = rec["paths"]
    loc = f"{source['repo']}@{commit}:{paths[0]}"
    loader = LOADERS.get(source["format"])
    if loader is None:
        raise ConvertError("corpus.json", None, rec["id"], f"unknown format {source['format']!r}")
    samples, notes, truth, distance, hints = loader(rec, source, SourceFiles(source, paths, git_dir))
    if truth is None:
        truth, distance = dict(rec["truth"]), rec.get("distance_m")
    distance_source = rec.get("distance_source")
    if not samples:
        raise ConvertError(loc, None, None, "no samples")
    if truth.get("kind") == "closed_loop":
        truth.setdefault("end_distance_m", 0.0)
    stats = sample_stats(samples, rec["rate_hz"])
    if hints is None:
        input_path = out_dir / f"{rec['id']}.csv"
        write_csv(input_path, samples, [
            f"{rec['id']}: converted by tools/real-data/convert.py",
            f"source: {source['repo']}@{commit}: {', '.join(paths)}",
            f"licence: {source['licence']}",
            f"imu: {source['imu']}; platform: {rec['platform']}",
        ])
    else:
        # The canonical CSV has no hint columns: a recording with robot hints is written as
        # an MCAP run, which `mems-odometry offline` reads with its hints.
        messages, dropped = mcap_messages(samples, hints)
        input_path = out_dir / f"{rec['id']}.mcap"
        input_path.write_bytes(mcap_bytes(messages))
        stats["hints"] = sum(1 for m in messages if m[1] == HINT_TOPIC)
        stats["hints_stationary"] = sum(1 for h in hints if h["flags"] & HINT_STATIONARY)
        stats["samples_dropped_non_increasing_time"] = dropped
        notes.append(f"written as MCAP (JSON messages on {RAW_TOPIC} and {HINT_TOPIC}), times offset by "
                     f"{MCAP_T0_NS * 1e-9:g} s; {dropped} samples with a non-increasing time dropped")
    sidecar = {
        "id": rec["id"],
        "csv": input_path.name,
        "input": input_path.name,
        "source": {"repo": source["repo"], "commit": commit, "paths": paths},
        "licence": source["licence"],
        "imu": source["imu"],
        "platform": rec["platform"],
        "rate_hz": rec["rate_hz"],
        "truth": truth,
        "distance_m": distance,
        "distance_source": distance_source,
        "authors_result": rec.get("authors_result"),
        "authors_citation": source.get("authors_citation"),
        "extra_args": rec.get("extra_args", []),
        "source_format": source.get("format_note"),
        "conversion": {"notes": notes, **stats},
    }
    with open(out_dir / f"{rec['id']}.json", "w", encoding="utf-8") as f:
        json.dump(sidecar, f, indent=2)
        f.write("\n")
    return sidecar


def default_git_dir(repo, mirrors):
    owner, name = repo.split("/")
    return Path(mirrors) / f"{owner}+{name}" / "repo"


def convert_all(args):
    corpus = json.loads((HERE / "corpus.json").read_text())
    overrides = {}
    for item in args.git_dir or []:
        key, sep, value = item.partition("=")
        if not sep:
            sys.exit(f"convert.py: --git-dir {item!r}: expected SOURCE=DIR")
        overrides[key] = Path(value)
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    failures = 0
    for rec in corpus["recordings"]:
        if args.only and rec["id"] not in args.only:
            continue
        source = corpus["sources"][rec["source"]]
        git_dir = overrides.get(rec["source"]) or default_git_dir(source["repo"], args.mirrors)
        try:
            side = convert_recording(rec, source, git_dir, out_dir)
        except (ConvertError, OSError) as e:
            failures += 1
            print(f"convert.py: {rec['id']}: {e}", file=sys.stderr)
            continue
        c = side["conversion"]
        extra = f", {c['hints']} robot hints" if "hints" in c else ""
        print(f"{rec['id']}: {c['samples']} samples, {c['duration_s']:.1f} s, "
              f"{c['repeated_rows']} repeated rows, {c['equal_timestamps']} equal timestamps{extra} -> {out_dir / side['input']}")
    return 1 if failures else 0


# ---------------------------------------------------------------------------------------------
# Self-test: every source format on a tiny inline sample, and malformed input naming the line.


def _close(a, b, tol=1e-9):
    assert abs(a - b) <= tol * max(1.0, abs(b)), (a, b)


def _expect_error(fn, *needles):
    try:
        fn()
    except ConvertError as e:
        for n in needles:
            assert n in str(e), (str(e), n)
        return
    raise AssertionError("no error raised")


def _test_text_formats():
    """xio_csv, openshoe_txt, sensorconnect_csv, xsens_dot_csv on inline samples."""
    xio = ("Time (s),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),Accelerometer X (g),"
           "Accelerometer Y (g),Accelerometer Z (g)\n0,1,2,3,0.1,0.2,0.9\n0.0025,1,2,3,0.1,0.2,0.9\n"
           "0.0025,1,2,3,0.1,0.2,0.9\n")
    s, _ = parse_xio_csv(xio, "x.csv")
    assert s[0] == (0.0, 0.1, 0.2, 0.9, 1.0, 2.0, 3.0) and s[1] == s[2]
    st = sample_stats(s, 400)
    assert st["repeated_rows"] == 1 and st["equal_timestamps"] == 1
    _expect_error(lambda: parse_xio_csv(xio.replace("0.0025,1,2,3,0.1,0.2,0.9\n0.0025", "0.0025,1,2,x,0.1,0.2,0.9\n0.0025", 1), "x.csv"),
                 "x.csv", "line 3", "Gyroscope Z (deg/s)", "'x' is not a number")

    s, _ = parse_openshoe_txt("0,0,-9.80665,3.14159265358979,0,0\n0,0,-9.80665,0,0,0\n", "o.txt", 820)
    _close(s[0][3], -1.0)
    _close(s[0][4], 180.0, 1e-6)
    _close(s[1][0], 1 / 820)
    _expect_error(lambda: parse_openshoe_txt("1,2,3\n", "o.txt", 820), "o.txt", "line 1", "3 fields, expected 6")

    sc = ("Time,inertial-1:scaledAccelX,inertial-1:scaledAccelY,inertial-1:scaledAccelZ,inertial-1:scaledGyroX,"
          "inertial-1:scaledGyroY,inertial-1:scaledGyroZ\n0,0.1,0.2,-0.97,0.0174532925199433,0,0\n0.005,0.1,0.2,-0.97,0,0,0\n")
    s, _ = parse_sensorconnect_csv(sc, "s.csv")
    _close(s[0][4], 1.0)
    _close(s[1][0], 0.005)
    assert s[0][3] == -0.97
    _expect_error(lambda: parse_sensorconnect_csv(sc.replace("scaledGyroZ", "scaledMagZ"), "s.csv"), "s.csv", "line 1", "scaledGyroZ", "missing")

    dot = ("sep=,\nPacketCounter,SampleTimeFine,Euler_X,Euler_Y,Euler_Z,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z,\n"
           "0, 4294960000, 0, 0, 0, 0, 0, 0, 0, 0, 0, \n"
           "1, 4294962000, 1, 2, 3, 0, 0, 9.80665, 0.5, 0, 0, \n"
           "2, 3037, 1, 2, 3, 0, 0, 9.80665, 0.5, 0, 0, \n")
    s, notes = parse_xsens_dot_csv(dot, "d.csv")
    assert len(s) == 2 and any("dropped line 3" in n for n in notes), notes
    _close(s[0][3], 1.0)
    _close(s[1][0], 8333e-6)
    _expect_error(lambda: parse_xsens_dot_csv(dot.replace("2, 3037, 1", "2, 3037"), "d.csv"), "d.csv", "line 5")


def _test_mat_formats():
    """MAT v5 footprints (GCP), the GNSS log and BROAD."""
    for compress in (False, True):
        mat = mat_bytes({"GCP_exist_and_correct": (1, 1, [1.0]),
                          "GCP_meters": (3, 2, [0.0, 3.0, 3.0, 0.0, 0.0, 4.0]),
                          "tile_edge_length": (1, 1, [0.4])}, compress)
        truth, walked = gcp_truth(mat, "g.mat")
        _close(truth["end_distance_m"], 5.0)
        _close(walked, 7.0)
        if truth["footprints_m"] != [[0.0, 0.0], [3.0, 0.0], [3.0, 4.0]]:
            raise AssertionError(f"footprints_m {truth['footprints_m']}")
    bad = mat_bytes({"GCP_exist_and_correct": (1, 1, [0.0]), "GCP_meters": (1, 2, [0.0, 0.0])}, True)
    _expect_error(lambda: gcp_truth(bad, "g.mat"), "g.mat", "GCP_exist_and_correct")
    _expect_error(lambda: read_mat(b"MATLAB 7.3 MAT-file" + b"\0" * 200, "h.mat"), "h.mat", "not a MATLAB 5.0")

    # 0.001 degree of latitude north: an independent figure for the local tangent plane, the
    # length of a degree of latitude 111132.954 - 559.822 cos(2 phi) + 1.175 cos(4 phi) m
    # (the standard WGS-84 series), 111131.779 m at 45 N.
    # The GNSS unit's gyro rows (100 Hz) turn as the car's samples (120 Hz) do, 0.6 s earlier on
    # the car's clock: the track's first row is timed at 0.6 s.
    def turning(t):
        return 5 + 4 * math.sin(1.3 * t) + 2 * math.sin(2.9 * t + 0.05 * t * t)

    car = [(k / 120, 0.0, 0.0, 1.0, turning(k / 120 - 0.6), 0.0, 0.0) for k in range(1200)]
    rows = [f"{k / 10},{45.0 if k == 0 else 45.001},10.0,0,{turning(k / 100) * 0.6},{turning(k / 100) * 0.8}"
            for k in range(1000)]
    gnss = "Timestamp,Lat_GNSS,Long_GNSS,Gyro_X,Gyro_Y,Gyro_Z\n" + "\n".join(rows) + "\n"
    truth, walked = gnss_truth(gnss, "n.csv", car)
    _close(truth["end_distance_m"], 0.001 * (111132.954 - 1.175), 1e-6)
    _close(walked, truth["end_distance_m"])
    # To a bin: the bins' mean times differ by up to one between 100 and 120 Hz rows.
    assert abs(truth["clock_offset_s"] - 0.6) <= SYNC_BIN_S + 1e-9, truth["clock_offset_s"]
    _close(truth["track"][1][0] - truth["track"][0][0], 0.01, 1e-9)
    _expect_error(lambda: gnss_truth(gnss + "10,north,10,0,0,0\n", "n.csv", car), "n.csv", "line 1002", "Lat_GNSS")
    still = [(q[0], 0.0, 0.0, 1.0, 0.0, 0.0, 0.0) for q in car]
    _expect_error(lambda: gnss_truth(gnss, "n.csv", still), "n.csv", "Gyro_X", "no clock offset")

    # BROAD: column-major N x 3 arrays; opt_pos with an unseen (NaN) first row; closes within 2 mm.
    nan = float("nan")
    broad = mat_bytes({"imu_acc": (2, 3, [0.0, 0.0, 0.0, 0.0, 9.80665, -9.80665]),
                        "imu_gyr": (2, 3, [0.0174532925199433, 0.0, 0.0, 0.0, 0.0, 0.0]),
                        "sampling_rate": (1, 1, [200.0]),
                        "opt_pos": (3, 3, [nan, 0.5, 0.502, nan, 0.2, 0.2, nan, 1.0, 1.0])}, True)
    s, _, arrays = parse_broad_mat(broad, "b.mat")
    assert len(s) == 2, s
    _close(s[0][3], 1.0)
    _close(s[1][3], -1.0)
    _close(s[0][4], 1.0)
    _close(s[1][0], 0.005)
    truth, walked = broad_truth(arrays, "b.mat")
    _close(truth["tolerance_m"], 0.002)
    assert truth["kind"] == "closed_loop" and truth["positions_missing"] == 1, truth
    bad = mat_bytes({"opt_pos": (2, 3, [0.0, 1.0, 0.0, 0.0, 0.0, 0.0])}, False)
    _expect_error(lambda: broad_truth(read_mat(bad, "b.mat"), "b.mat"), "b.mat", "opt_pos", "not a closed loop")
    _expect_error(lambda: parse_broad_mat(mat_bytes({"imu_acc": (1, 3, [0.0, 0.0, 9.8])}, False), "b.mat"),
                 "b.mat", "imu_gyr", "missing")


def _test_vesc_and_mcap():
    """The FrictionMaps stateLogger (IMU, hints, particle filter) and the MCAP writer."""
    # FrictionMaps stateLogger: IMU in g and deg/s; hints from vx, stationary after 0.1 s at 0.
    imu = (",s,ns,phi_r,phi_p,phi_y,ax,ay,az,wx,wy,wz,q.x,q.y,q.z,q.w\n"
           "0,100,900000000,0,0,0,0.01,0.02,0.98,1.5,0,-2,0,0,0,1\n"
           "0,101,0,0,0,0,0.01,0.02,0.98,1.5,0,-2,0,0,0,1\n")
    odom = (",s,ns,vx,vy,vz,wx,wy,wz,x,y,q.x,q.y,q.z,q.w\n"
            "0,100,950000000,0.5,0,0,0.5,0,0,0,0,0,0,0,1\n0,101,0,0.0,0,0,0,0,0,0,0,0,0,0,1\n"
            "0,101,50000000,0.0,0,0,0,0,0,0,0,0,0,0,1\n0,101,150000000,0.0,0,0,0,0,0,0,0,0,0,0,1\n")
    s, _, hints = parse_vesc_f1tenth(imu, odom, "i.csv", "o.csv")
    _close(s[1][0], 0.1)
    assert s[0][1:] == (0.01, 0.02, 0.98, 1.5, 0.0, -2.0), s[0]
    assert [h["flags"] for h in hints] == [12, 12, 12, 13], hints
    _close(hints[0]["t_s"], 0.05)
    _expect_error(lambda: parse_vesc_f1tenth(imu.replace("0.98,1.5", "0.98,x", 1), odom, "i.csv", "o.csv"),
                 "i.csv", "line 2", "'wx'")
    pf = ",s,ns,x,y,q.x,q.y,q.z,q.w\n0,100,0,1.0,1.0,0,0,0,1\n0,100,5,1.05,1.0,0,0,0,1\n0,101,0,4.0,5.0,0,0,0.7071067811865476,0.7071067811865476\n"
    truth, walked = pf_pose_truth(pf, "p.csv", 100 * 1_000_000_000)
    _close(truth["end_distance_m"], 5.0)
    assert truth["track"][2][:3] == [1.0, 4.0, 5.0], truth["track"]
    _close(truth["track"][2][3], math.pi / 2)
    _close(walked, 5.0)  # the 5 cm step is under the 0.1 m floor: measured from (1, 1)

    # MCAP: records in order, JSON messages with the wire field names, times strictly increasing.
    messages, dropped = mcap_messages(s + [s[-1]], hints)
    assert dropped == 1, dropped
    records = read_mcap_records(mcap_bytes(messages))
    ops = [op for op, _ in records]
    assert ops[:5] == [1, 3, 4, 3, 4] and ops[-2:] == [0x0F, 0x02] and ops.count(5) == 6, ops
    bodies = [b for op, b in records if op == 5]
    raw = json.loads(bodies[0][22:])
    assert struct.unpack_from("<HIQQ", bodies[0]) == (1, 0, MCAP_T0_NS, MCAP_T0_NS), struct.unpack_from("<HIQQ", bodies[0])
    assert raw["accel_g"] == [0.01, 0.02, 0.98] and raw["gyro_counts"] == [196, 0, -262] and raw["flags"] == 16, raw
    hint = json.loads(bodies[-1][22:])
    assert hint["flags"] == 13 and hint["seq"] == 3 and hint["stamps"]["sample_ns"] == MCAP_T0_NS + 250_000_000, hint
    channel = records[2][1]
    assert channel[4:8] == struct.pack("<I", len(RAW_TOPIC)) and RAW_TOPIC.encode() in channel, channel


def _test_ros_bag():
    """A wheeled robot's ROS bag: IMU, wheel-odometry hints and GNSS fixes."""
    # ROS bag of a wheeled robot: IMU in rad/s and m/s^2; hints from the wheel odometry,
    # stationary after 0.1 s below 1 mm/s; fixes without a fix (status -1) left out.
    s0 = 1_600_000_000_000_000_000
    ms = 1_000_000
    bag = [("/imu", "sensor_msgs/Imu", s0, imu_message(s0, (math.pi / 180, 0.0, 0.0), (0.0, G0, 0.0))),
           ("/imu", "sensor_msgs/Imu", s0 + 40 * ms, imu_message(s0 + 40 * ms, (0.0, 0.0, 0.0), (0.0, G0, 0.0)))]
    bag += [("/odom", "nav_msgs/Odometry", s0 + k * 50 * ms, odometry_message(s0 + k * 50 * ms, v, 0.0))
            for k, v in enumerate([1.0, 1e-15, 0.0, 0.0, 0.0])]
    bag += [("/fix", "sensor_msgs/NavSatFix", s0 + k * ms, navsatfix_message(s0 + k * ms, st, lat, 10.0, 0.81))
            for k, st, lat in [(1, 1, 45.0), (2, -1, 46.0), (3, 1, 45.001)]]
    topics = {"imu": "/imu", "odom": "/odom", "fix": "/fix"}
    s, _, hints, fixes = parse_ros_robot_bag(bag_bytes(bag, True), "r.bag", topics)
    assert len(s) == 2 and s[0][2] == 1.0 and s[1][0] == 0.04, s
    _close(s[0][4], 1.0)
    assert [h["flags"] for h in hints] == [12, 12, 12, 13, 13], hints
    assert [f[1] for f in fixes] == [45.0, 45.001], fixes
    truth, walked = gnss_track_truth(fixes, "r.bag")
    _close(truth["end_distance_m"], 0.001 * (111132.954 - 1.175), 1e-6)
    _close(walked, truth["end_distance_m"])
    assert truth["track"][1][0] == 0.003 and truth["track_min_step_m"] == 0.5, truth
    _expect_error(lambda: parse_ros_robot_bag(bag_bytes(bag[:2], False), "r.bag", topics), "r.bag", "'/odom'", "no messages")


def _test_rtk_npy():
    """RTK positions as .npy."""
    # RTK positions as .npy (north, east, down): 3-4-5 m, the 5 cm step under the 0.1 m floor.
    truth, walked = rtk_ned_truth(npy_bytes([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [3.0, 4.0, 0.1]]), "n.npy")
    _close(truth["end_distance_m"], 5.0)
    _close(walked, 5.0)
    _expect_error(lambda: rtk_ned_truth(npy_bytes([[0.0, 0.0], [1.0, 1.0]]), "n.npy"), "n.npy", "'shape'", "N x 3")
    # Timed: the track in east/north about the first position.
    truth, _ = rtk_ned_truth(npy_bytes([[1.0, 2.0, 0.0], [4.0, 6.0, 0.0]]), "n.npy", [10.0, 10.1])
    assert truth["kind"] == "rtk_track" and truth["track"] == [[10.0, 0.0, 0.0], [10.1, 4.0, 3.0]], truth
    # The slice: the raw gyro turned by 90 deg about z (magnitudes kept), starting at sample 3.
    raw = [(0.01 * k, 0.0, 0.0, 1.0, math.sin(k), math.cos(2 * k), 0.1 * k) for k in range(40)]
    sync = [[0.0, 0.0, 9.8, -q[5], q[4], q[6]] for q in raw[3:27]]
    assert sync_offset(raw, sync, "s.npy") == 3
    _expect_error(lambda: sync_offset(raw, [[0.0, 0.0, 9.8, 5.0, 5.0, 5.0]] * 4, "s.npy"), "s.npy", "'gyro'", "0 offsets")


def self_test():
    """Every source format and container on small inline samples, and malformed input naming
    the file, line and field; no data or network needed."""
    _test_text_formats()
    _test_mat_formats()
    _test_vesc_and_mcap()
    _test_ros_bag()
    _test_rtk_npy()
    checked = [comma2k19.self_test(), tyrex_attitude.self_test(), navego.self_test(local_east_north), phil_mqp.self_test(),
               rtklib_logs.self_test(local_east_north), tumvi.self_test(), *containers.self_test()]
    print("convert.py self-test: ok (xio_csv, openshoe_txt, sensorconnect_csv, xsens_dot_csv, broad_mat, vesc_f1tenth_csv, "
          "ros1_bag_robot, xsens_dot_rtk_npy, MAT v5 GCP, GNSS, MCAP with hints, " + ", ".join(checked) + ")")
    return 0


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--git-dir", action="append", metavar="SOURCE=DIR",
                   help="bare git dir of a corpus source (default: MIRRORS/owner+name/repo)")
    p.add_argument("--mirrors", default=os.environ.get("MEMS_MIRRORS", "/work/.mirror"),
                   help="where fetched snapshots live (default $MEMS_MIRRORS or /work/.mirror)")
    p.add_argument("--out", default=os.environ.get("MEMS_REAL_DATA", "/work/real-data"),
                   help="output directory (default $MEMS_REAL_DATA or /work/real-data)")
    p.add_argument("--only", action="append", metavar="ID", help="convert only this recording (repeatable)")
    p.add_argument("--self-test", action="store_true", help="run the built-in format tests and exit")
    args = p.parse_args()
    if args.self_test:
        return self_test()
    return convert_all(args)


if __name__ == "__main__":
    sys.exit(main())
