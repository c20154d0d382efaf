"""RTKLIB stream logs of an IMU beside a GNSS receiver (rtklibexplorer/GNSS_IMU's sample data):
the IMU's text stream with its RTKLIB time-tag file, and the receiver's RTK solution.

Per recording, `data/NAME/`:
  imu_N.csv       the IMU's serial stream as captured by RTKLIB's str2str: one sample a line,
                  `ax,ay,az,gx,gy,gz,tick` with the specific force in g (+1 on the axis
                  pointing up at rest), the angular rate in deg/s (the authors'
                  convert_imu_file.py turns it into rad/s with np.deg2rad) and the IMU's own
                  clock in ms since its power-up. The capture starts and stops mid-stream, so
                  its first and last lines may be cut (the authors' conversion skips both);
  imu_N.csv.tag   RTKLIB's time tags of that capture: a 60-byte header ("TIMETAG RTKLIB
                  demo5"), the host tick rate (u32), the capture's start time in GPS time as
                  u32 seconds since 1970 plus an f64 fraction, then (host tick ms, file
                  position) u32 pairs, one per chunk written;
  gnss_N_sf.pos   the receiver's RTK solution in RTKLIB's text format: GPS-time date and
                  time, latitude and longitude (deg), height, Q (1 fix, 2 float), satellites,
                  the north/east/up sigmas (m), ..., the north/east/up velocity (m/s).

Samples: the first complete line is taken at the tag's start time and the IMU's ticks are
scaled so that the last complete line falls at the tag's last tick, as the authors'
convert_imu_file.py does (the two clocks differ by 0.03 %); t_s counts from the first complete
line. The solution is put on that clock and then shifted by the lag that best correlates the
IMU's yaw rate about its start-up up axis with the track's heading rate (navego.py's
correlation, here in 1 s bins and 25 ms steps within 2 s), which also checks the gyro's units
and sign: a slope near 1 and r >= MIN_R, else the recording is refused. Python standard library
only.
"""

import calendar
import math
import struct
import time

import navego
from containers import ConvertError

TAG_HEADER = b"TIMETAG RTKLIB"
TAG_HEADER_BYTES = 60
FIELDS = ("ax_g", "ay_g", "az_g", "gx_dps", "gy_dps", "gz_dps", "tick_ms")
POS_FIX, POS_FLOAT = 1, 2
LAG_BIN_S = 1.0  # yaw-rate bins: a car turns for a few seconds, a walker faster
LAG_STEP_S = 0.025
MAX_LAG_S = 2.0  # the tag times the capture to the host's clock; the lag left is the logging delay
MIN_R = 0.9
SLOPE_RANGE = (0.8, 1.25)  # IMU yaw rate over the track's: deg/s as stated, z turning with the track
TRUTH_SOURCE = ("the receiver's RTK solution (fixed and float epochs, RTKLIB .pos) on the IMU's clock (the tag file's "
                "timing shifted by clock_lag_s, measured from the yaw rates), local east/north: bench.py measures from "
                "the fix at the odometry's alignment to the last; the heading is not ours, so only distances are a truth")


def read_tag(buf, where):
    """(start GPS time s since 1970, last host tick ms) of an RTKLIB time-tag file."""
    if not buf.startswith(TAG_HEADER):
        raise ConvertError(where, None, "header", f"not an RTKLIB time-tag file (starts {buf[:20]!r})")
    body = len(buf) - TAG_HEADER_BYTES - 16
    if body < 8 or body % 8:
        raise ConvertError(where, None, "tags", f"{len(buf)} bytes: expected a 76-byte header and 8-byte tags")
    seconds, = struct.unpack_from("<I", buf, TAG_HEADER_BYTES + 4)
    fraction, = struct.unpack_from("<d", buf, TAG_HEADER_BYTES + 8)
    last_tick, _ = struct.unpack_from("<II", buf, len(buf) - 8)
    if not 0.0 <= fraction < 1.0 or last_tick <= 0:
        raise ConvertError(where, None, "start", f"start fraction {fraction}, last tick {last_tick}")
    return seconds + fraction, last_tick


def imu_rows(text, where):
    """(rows of (tick ms, ax, ay, az g, gx, gy, gz deg/s), notes): the stream's lines, a cut
    first or last line dropped and noted; any other malformed line is an error."""
    lines = text.replace("\r\n", "\n").split("\n")
    while lines and not lines[-1].strip():
        lines.pop()
    rows, notes = [], []
    for i, line in enumerate(lines):
        cells = line.split(",")
        edge = i in (0, len(lines) - 1)
        if len(cells) != len(FIELDS) or any(not c.strip() for c in cells):
            if edge:
                notes.append(f"line {i + 1} cut by the capture's {'start' if i == 0 else 'end'} ({len(cells)} fields): dropped")
                continue
            raise ConvertError(where, i + 1, None, f"{len(cells)} fields, expected {len(FIELDS)} ({','.join(FIELDS)})")
        values = []
        for name, cell in zip(FIELDS, cells):
            try:
                v = float(cell)
            except ValueError:
                raise ConvertError(where, i + 1, name, f"{cell.strip()!r} is not a number") from None
            if not math.isfinite(v):
                raise ConvertError(where, i + 1, name, f"{cell.strip()!r} is not finite")
            values.append(v)
        if rows and values[6] <= rows[-1][0]:
            raise ConvertError(where, i + 1, "tick_ms", f"{values[6]:.0f} does not follow {rows[-1][0]:.0f}")
        rows.append((values[6], *values[:6]))
    if len(rows) < 2:
        raise ConvertError(where, None, None, f"{len(rows)} complete lines")
    return rows, notes


def samples(rows, start_gpst, last_tick_ms):
    """(samples (t_s, specific force g, angular rate deg/s), GPS time of t_s = 0, tick scale):
    the first row at the tag's start, the last at its last tick."""
    t0, span = rows[0][0], rows[-1][0] - rows[0][0]
    scale = last_tick_ms / span
    return [((r[0] - t0) * 1e-3 * scale, *r[1:]) for r in rows], start_gpst, scale


def read_pos(text, where):
    """[(GPS time s since 1970, latitude deg, longitude deg, Q, east sigma m)] of an RTKLIB
    solution file, fixed and float solutions only (others are counted, not kept)."""
    out, other = [], 0
    for i, line in enumerate(text.replace("\r\n", "\n").split("\n")):
        if not line.strip() or line.startswith("%"):
            continue
        cells = line.split()
        if len(cells) < 9:
            raise ConvertError(where, i + 1, None, f"{len(cells)} fields, expected at least 9")
        try:
            date = [int(v) for v in cells[0].split("/")]
            hh, mm, ss = cells[1].split(":")
            gpst = calendar.timegm((date[0], date[1], date[2], int(hh), int(mm), 0)) + float(ss)
        except (ValueError, IndexError):
            raise ConvertError(where, i + 1, "GPST", f"{cells[0]} {cells[1]} is not YYYY/MM/DD HH:MM:SS.SSS") from None
        vals = {}
        for name, col in (("latitude(deg)", 2), ("longitude(deg)", 3), ("Q", 5), ("sde(m)", 8)):
            try:
                vals[name] = float(cells[col])
            except ValueError:
                raise ConvertError(where, i + 1, name, f"{cells[col]!r} is not a number") from None
        if int(vals["Q"]) not in (POS_FIX, POS_FLOAT):
            other += 1
            continue
        if out and gpst <= out[-1][0]:
            raise ConvertError(where, i + 1, "GPST", "time does not increase")
        out.append((gpst, vals["latitude(deg)"], vals["longitude(deg)"], int(vals["Q"]), vals["sde(m)"]))
    if len(out) < 2:
        raise ConvertError(where, None, "Q", f"{len(out)} fixed or float solutions ({other} others)")
    return out, other


def recording(texts, wheres, local_east_north):
    """(samples, notes, fixes on the IMU clock [(t_s, latitude, longitude, east variance
    m^2)], timing) from the IMU stream, its time tags (bytes) and the solution file; the
    caller passes its projection of (latitude, longitude) to local (east, north) metres."""
    rows, notes = imu_rows(texts[0], wheres[0])
    start, last_tick = read_tag(texts[1], wheres[1])
    out, t0_gpst, scale = samples(rows, start, last_tick)
    sols, other = read_pos(texts[2], wheres[2])
    points = local_east_north([s[1:3] for s in sols])
    track = [(s[0] - t0_gpst, e, n) for s, (e, n) in zip(sols, points)]
    lag, r, slope = navego.yaw_rate_lag(out, track, LAG_BIN_S, LAG_STEP_S, MAX_LAG_S)
    if r is None or r < MIN_R or not SLOPE_RANGE[0] <= slope <= SLOPE_RANGE[1]:
        raise ConvertError(wheres[2], None, "GPST", f"the IMU's yaw rate does not follow the track's heading rate "
                           f"within {MAX_LAG_S} s (lag {lag}, r {r}, slope {slope}): not on the tag's clock, or "
                           "the gyro is not in deg/s about a right-handed frame")
    fixes = [(t + lag, s[1], s[2], s[4] ** 2) for t, s in zip((q[0] for q in track), sols)]
    q = [s[3] for s in sols]
    notes.append(f"samples timed by the tag file (start {t0_gpst:.3f} s GPST, IMU ticks scaled by {scale:.6f}); "
                 f"ax, ay, az (g) and gx, gy, gz (deg/s) as logged")
    notes.append(f"solution: {q.count(POS_FIX)} fixed and {q.count(POS_FLOAT)} float RTK epochs kept, {other} others "
                 f"dropped; on the IMU clock {lag:+.3f} s after the tag's timing (yaw-rate correlation r = {r:.3f}, "
                 f"IMU rate / track rate {slope:.3f})")
    timing = {"tag_start_gpst_s": t0_gpst, "tick_scale": scale, "clock_lag_s": lag, "clock_lag_r": round(r, 4),
              "yaw_rate_slope": round(slope, 4), "fixed": q.count(POS_FIX), "float": q.count(POS_FLOAT)}
    return out, notes, fixes, timing


def _tag_bytes(start_gpst, ticks):
    whole = int(start_gpst)
    return (b"TIMETAG RTKLIB demo5".ljust(TAG_HEADER_BYTES, b"\0") + struct.pack("<IId", 1000, whole, start_gpst - whole)
            + b"".join(struct.pack("<II", t, 40 * k) for k, t in enumerate(ticks)))


def self_test(local_east_north):
    """A car weaving at 5 m/s with its IMU z up, the IMU's clock 0.2 % fast and the solution
    logged 0.3 s before the IMU sees the turns: times, units, the lag, the cut edge lines;
    malformed input names the line and field."""
    def heading(t):
        return 0.6 * math.sin(0.15 * t) + 0.3 * math.sin(0.4 * t)

    def rate(t):
        return 0.09 * math.cos(0.15 * t) + 0.12 * math.cos(0.4 * t)

    start = 1752003261.5
    lines = ["0.01,1.0"]  # cut by the capture's start
    for i in range(100 * 120):
        t = i / 100
        lines.append(f"0.000,0.000,1.000,0.000,0.000,{math.degrees(rate(t)):.6f},{5000 + round(i * 10 * 1.002)}")
    lines.append("0.012,-0.042,1.009,")  # cut by its end
    tag = _tag_bytes(start, [0, 60000, 119990])
    pos, e, n = ["%  GPST  latitude(deg) longitude(deg) height(m) Q ns sdn(m) sde(m) sdu(m)"], 0.0, 0.0
    lat0, lon0 = 40.0966268, -105.1474483
    for k in range(4 * 118):
        t_tag = 0.5 + k / 4  # the solution's time on the tag's clock; the IMU turns through its pose 0.3 s later
        gpst = start + t_tag
        minute = int(gpst // 60) * 60
        y, mo, d, hh, mm = time.gmtime(minute)[:5]
        pos.append(f"{y:04d}/{mo:02d}/{d:02d} {hh:02d}:{mm:02d}:{gpst - minute:06.3f} {lat0 + math.degrees(n / 6367000.0):.9f} "
                   f"{lon0 + math.degrees(e / (6388000.0 * math.cos(math.radians(lat0)))):.9f} 1601.47 {2 if k % 5 == 0 else 1} 21 "
                   f"0.0099 0.0099 0.0100")
        e += 1.25 * math.cos(heading(t_tag + 0.125 + 0.3))
        n += 1.25 * math.sin(heading(t_tag + 0.125 + 0.3))
    s, notes, fixes, timing = recording(["\n".join(lines) + "\n", tag, "\n".join(pos)], ["i.csv", "i.tag", "g.pos"],
                                        local_east_north)
    assert len(s) == 12000 and len(notes) == 4 and "cut" in notes[0] and "cut" in notes[1], notes
    assert abs(s[-1][0] - 119.99) < 1e-9 and abs(timing["tick_scale"] - 119990 / 120229.98) < 1e-6, (s[-1], timing)
    assert abs(s[0][3] - 1.0) < 1e-12 and abs(s[100][6] - math.degrees(rate(1.0))) < 1e-5, s[100]
    assert abs(timing["clock_lag_s"] - 0.3) <= 0.05 and timing["clock_lag_r"] > 0.95, timing
    assert timing["float"] == 95 and abs(fixes[0][0] - (0.5 + timing["clock_lag_s"])) < 1e-6, (timing, fixes[0])
    for bad, needle in ((lines[:5] + ["0.1,0.2,x,0.0,0.0,0.0,5100"] + lines[5:], "field 'az_g'"),
                        (lines[:5] + ["0.1,0.2"] + lines[5:], "line 6")):
        try:
            recording(["\n".join(bad), tag, "\n".join(pos)], ["b.csv", "i.tag", "g.pos"], local_east_north)
        except ConvertError as err:
            assert "b.csv" in str(err) and needle in str(err), str(err)
        else:
            raise AssertionError(f"no error for {needle}")
    try:
        read_tag(b"NOTATAG" + tag[7:], "t.tag")
    except ConvertError as err:
        assert "t.tag" in str(err) and "header" in str(err), str(err)
    else:
        raise AssertionError("no error for a bad tag header")
    return "rtklib_imu_csv"
