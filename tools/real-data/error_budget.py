#!/usr/bin/env python3
"""Error budget of a hinted wheeled run against its reference track: how much of the end error
is along-track (the distance travelled: the speed scale), heading (the filter's yaw against the
track's) and the rest (the velocity's direction against the body's: lateral slip, the
mounting's yaw), over time.

Runs `mems-odometry offline --out` on ID (tools/real-data's converted data), reads the live
odometry states back from the MCAP, and turns the reference track (a particle filter's poses
with their heading, sidecar `truth.track`: t_s, x, y, heading) into our navigation frame as
bench.py does (from the pose at our alignment, turned by the car's heading there plus the IMU's
yaw on the car). Over increments of INCREMENT_S seconds, with `d` our horizontal step and `t`
the track's (m, our frame, z up, heading counter-clockwise):
- along-track: `(|d| - |t|) t/|t|`, what a wrong distance costs;
- heading: `|d| (R(e) t/|t| - t/|t|)`, `e` the filter's yaw change since alignment minus the
  track's (rad), what a wrong heading costs;
- rest: `d - t` minus both (the velocity's direction against the body's).
Their cumulative sums add up to the end error exactly. Also printed: the distance ratio
(ours over the track's), the yaw error at the end and its rms, the published 1-sigma (per-axis
rms of x, y) and the error at each tenth of the run; the mounting's yaw (the IMU's yaw on the
body, deg, counter-clockwise about up) against the sidecar's `sensor_yaw_on_body_deg`, with
where it came from and its 1-sigma; and the track's direction of travel against its own
heading (deg, folded into [-90, 90): a step backwards is a robot reversing, counted apart) over
steps of at least TRAVEL_STEP_M, whose median and spread say how steady the body's forward axis
is (a robot that does not skid: zero); and the horizontal specific force against the track's
acceleration, both in the body frame the sidecar's yaw gives (forward, left; m/s^2, means over
INCREMENT_S, the specific force's gravity taken away along the up of the alignment's last
ALIGN_REST_S, as the speed-change fit `odometry::cruise::ForwardAxis` does; the track's by
second differences of its means): their rms difference along and across the forward axis
against the track's own rms, the noise any accelerometer-based mounting estimate must overcome.
A mounting off by `m` turns every
step after it is taken by `m`: rerunning with `-- --mount 0,0,YAW` (the sidecar's yaw) shows
what is left without it.

Usage: error_budget.py [--bin PATH] [--data DIR] ID ... [-- offline flags]
"""
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import bench  # noqa: E402  (track_at, heading_at: the bench's own truth handling)

INCREMENT_S = 0.5
ALIGN_REST_S = 0.5  # the alignment's rest the specific force's up is taken over, s
G = 9.80665  # standard gravity, m/s^2 per g
TRAVEL_STEP_M = 0.05  # the track's steps for its direction of travel, m: 5 times the Vicon's 0.01
REVISION = 1 << 2  # odometry_flags::REVISION: republished history


def yaw_of(q):
    """Yaw (rad) of the sensor's x axis in the navigation frame, from (w, x, y, z)."""
    w, x, y, z = q
    return math.atan2(2 * (x * y + w * z), 1 - 2 * (y * y + z * z))


def states(path):
    """Live odometry states as (t_s from the first raw sample, x, y, yaw, sigma_h), and the raw
    samples as (t_s, specific force in the sensor frame, m/s^2)."""
    out, raw, t0, lsb = [], [], None, None
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, ch, _, v in reader.iter_decoded_messages(log_time_order=False):
            if ch.topic == "mems/imu/raw":
                t0 = v.stamps.sample_ns if t0 is None else t0
                lsb = v.accel_lsb_per_g or lsb
                # A sample in g, or in counts with its scale (the last one given).
                accel_g = list(v.accel_g) or [c / lsb for c in v.accel_counts]
                raw.append(((v.stamps.sample_ns - t0) * 1e-9, [a * G for a in accel_g]))
            if ch.topic != "mems/odometry/state" or v.flags & REVISION:
                continue
            s = v.position_sigma_m
            out.append(((v.stamps.sample_ns - t0) * 1e-9, v.position_m[0], v.position_m[1],
                        yaw_of(v.attitude_wxyz), math.sqrt((s[0] ** 2 + s[1] ** 2) / 2)))
    return out, raw


def body_axes(raw, t_a, yaw_deg):
    """Forward and left in the sensor frame (unit 3-vectors): up from the mean specific force
    over the alignment's last ALIGN_REST_S, forward the sensor's x levelled and turned by
    -yaw_deg about up (the sensor's yaw on the body, counter-clockwise), left = up x forward."""
    rest = np.array([f for t, f in raw if t_a - ALIGN_REST_S <= t <= t_a])
    up = rest.mean(axis=0)
    up /= np.linalg.norm(up)
    ex = np.array([1.0, 0.0, 0.0]) - up[0] * up
    ex /= np.linalg.norm(ex)
    ey = np.cross(up, ex)
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    forward = c * ex - s * ey
    return up, forward, np.cross(up, forward)


def bin_means(samples, t_a, count):
    """Means of (t, values) over `count` bins of INCREMENT_S from t_a; None for an empty bin."""
    sums = [None] * count
    for t, v in samples:
        k = int((t - t_a) // INCREMENT_S)
        if 0 <= k < count:
            n, acc = sums[k] or (0, [0.0] * len(v))
            sums[k] = (n + 1, [a + b for a, b in zip(acc, v)])
    return [None if b is None else [a / b[0] for a in b[1]] for b in sums]


def accel_line(raw, track, t_a, yaw_deg):
    """The horizontal specific force against the track's acceleration, along and across the
    body's forward axis (see the module documentation): their rms differences and the track's
    rms, m/s^2."""
    up, forward, left = body_axes(raw, t_a, yaw_deg)
    count = int((min(raw[-1][0], track[-1][0]) - t_a) // INCREMENT_S)
    f = bin_means(raw, t_a, count)
    p = bin_means([(q[0], q[1:3]) for q in track], t_a, count)
    along = across = truth2 = 0.0
    n = 0
    for k in range(1, count - 1):
        if None in (f[k], p[k - 1], p[k], p[k + 1]):
            continue
        a = [(p[k + 1][i] - 2 * p[k][i] + p[k - 1][i]) / INCREMENT_S ** 2 for i in range(2)]
        h = bench.heading_at(track, t_a + (k + 0.5) * INCREMENT_S)
        a_fwd = a[0] * math.cos(h) + a[1] * math.sin(h)
        a_left = -a[0] * math.sin(h) + a[1] * math.cos(h)
        fh = [x - u * sum(y * w for y, w in zip(f[k], up)) for x, u in zip(f[k], up)]
        along += (sum(x * y for x, y in zip(fh, forward)) - a_fwd) ** 2
        across += (sum(x * y for x, y in zip(fh, left)) - a_left) ** 2
        truth2 += a_fwd ** 2 + a_left ** 2
        n += 1
    if n == 0:
        return "  specific force: no increment to compare"
    return (f"  horizontal specific force against the track's acceleration ({n} x "
            f"{INCREMENT_S} s): rms {math.sqrt(along / n):.3f} m/s^2 along the forward axis, "
            f"{math.sqrt(across / n):.3f} across, the track's {math.sqrt(truth2 / n):.3f}")


def mounting_line(result, truth_yaw_deg):
    """Our mounting's yaw against the truth's (deg), with its source, time and 1-sigma."""
    hints = result.get("hints") or {}
    axis = hints.get("forward_axis")
    rpy = hints.get("mounting_rpy_deg")
    if rpy is not None and axis:
        how = (f"{axis['source']}, trusted at {axis['trusted_at_s']:.1f} s, 1-sigma "
               f"{axis['yaw_systematic_sigma_deg']:.1f} deg")
    elif (result.get("wheeled") or {}).get("mounting_rpy_deg") is not None:
        rpy = result["wheeled"]["mounting_rpy_deg"]
        how = "the IMU-only non-holonomic constraint's: the speed hints took none"
    else:
        return f"  mounting: none (truth {truth_yaw_deg:.1f} deg)"
    err = math.degrees(bench.wrap(math.radians(rpy[2] - truth_yaw_deg)))
    return (f"  mounting yaw {rpy[2]:.1f} deg ({how}) against the truth's {truth_yaw_deg:.1f}: "
            f"{err:+.1f} deg")


def travel_line(track, t_a):
    """The track's direction of travel minus its heading (deg, folded into [-90, 90)) after
    t_a: median, 10-90 % and the steps backwards."""
    slips, backwards, last = [], 0, None
    for q in track:
        if q[0] < t_a:
            continue
        if last is None:
            last = q
            continue
        dx, dy = q[1] - last[1], q[2] - last[2]
        if math.hypot(dx, dy) < TRAVEL_STEP_M:
            continue
        slip = bench.wrap(math.atan2(dy, dx) - last[3])
        folded = bench.wrap(2 * slip) / 2
        backwards += folded != slip
        slips.append(math.degrees(folded))
        last = q
    if not slips:
        return "  track: no step of its own"
    slips.sort()

    def pick(f):
        return slips[min(len(slips) - 1, int(f * len(slips)))]

    return (f"  track's travel against its heading: median {pick(0.5):+.1f} deg, 10-90 % "
            f"{pick(0.1):+.1f} to {pick(0.9):+.1f} over {len(slips)} steps of {TRAVEL_STEP_M} m "
            f"({backwards} backwards)")


def budget(rec_id, binary, data, extra):
    side = json.loads((data / f"{rec_id}.json").read_text())
    track = side["truth"]["track"]
    with tempfile.TemporaryDirectory() as tmp:
        mcap = Path(tmp) / "run.mcap"
        cmd = [str(binary), "offline", "--input", str(data / side["input"]), "--json",
               "--out", str(mcap), *extra]
        proc = subprocess.run(cmd, capture_output=True, text=True, check=True)
        result = json.loads(proc.stdout.splitlines()[-1])
        run, raw = states(mcap)
    t_a = result["aligned_at_s"]
    h_a = bench.heading_at(track, t_a)
    psi = h_a + math.radians(side["truth"]["sensor_yaw_on_body_deg"])
    c, s = math.cos(psi), math.sin(psi)
    start = bench.track_at(track, t_a)

    def truth(t):
        x, y = bench.track_at(track, t)
        dx, dy = x - start[0], y - start[1]
        return c * dx + s * dy, -s * dx + c * dy

    run = [r for r in run if r[0] >= t_a]
    yaw0 = run[0][3]
    along = [0.0, 0.0]
    heading = [0.0, 0.0]
    rest = [0.0, 0.0]
    ours_len = truth_len = 0.0
    yaw_err2, n = 0.0, 0
    last = run[0]
    rows = []
    for r in run[1:]:
        if r[0] - last[0] < INCREMENT_S and r is not run[-1]:
            continue
        d = (r[1] - last[1], r[2] - last[2])
        ta, tb = truth(last[0]), truth(r[0])
        t = (tb[0] - ta[0], tb[1] - ta[1])
        dn, tn = math.hypot(*d), math.hypot(*t)
        ours_len += dn
        truth_len += tn
        e = bench.wrap((r[3] - yaw0) - (bench.heading_at(track, r[0]) - h_a))
        yaw_err2 += e * e
        n += 1
        a, h = bench.split_step(d, t, e, 1e-6)
        for i in range(2):
            along[i] += a[i]
            heading[i] += h[i]
            rest[i] += d[i] - t[i] - a[i] - h[i]
        tr = truth(r[0])
        rows.append((r[0], math.hypot(r[1] - tr[0], r[2] - tr[1]), r[4], math.hypot(*along),
                     math.hypot(*heading), math.hypot(*rest), math.degrees(e)))
        last = r
    total = math.hypot(along[0] + heading[0] + rest[0], along[1] + heading[1] + rest[1])
    hints = result.get("hints") or {}
    print(f"{rec_id} ({' '.join(extra) or 'no flags'}): aligned at {t_a:.1f} s, "
          f"track {truth_len:.1f} m, ours {ours_len:.1f} m (ratio {ours_len / truth_len:.3f})")
    print(f"  end error {total:.2f} m: along-track {math.hypot(*along):.2f} m, heading "
          f"{math.hypot(*heading):.2f} m, rest {math.hypot(*rest):.2f} m; yaw error at the end "
          f"{rows[-1][6]:+.1f} deg, rms {math.degrees(math.sqrt(yaw_err2 / n)):.1f} deg; "
          f"1-sigma {rows[-1][2]:.2f} m; scale state {hints.get('speed_scale')}")
    print(mounting_line(result, side["truth"]["sensor_yaw_on_body_deg"]))
    print(travel_line(track, t_a))
    print(accel_line(raw, track, t_a, side["truth"]["sensor_yaw_on_body_deg"]))
    print("  t_s     error_m  sigma_m  along_m  heading_m  rest_m  yaw_err_deg")
    for i in range(1, 11):
        q = rows[min(len(rows) - 1, i * len(rows) // 10 - 1)]
        print("  {:6.1f}  {:7.2f}  {:7.2f}  {:7.2f}  {:9.2f}  {:6.2f}  {:+7.1f}".format(*q))


def main():
    args, extra = bench.ids_cli(__doc__.splitlines()[0], sys.argv[1:])
    for rec_id in args.ids:
        budget(rec_id, args.bin, args.data, extra)


if __name__ == "__main__":
    main()
