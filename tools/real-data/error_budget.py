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
rms of x, y) and the error at each tenth of the run.

Usage: error_budget.py [--bin PATH] [--data DIR] ID ... [-- offline flags]
"""
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import bench  # noqa: E402  (track_at, heading_at: the bench's own truth handling)

INCREMENT_S = 0.5
REVISION = 1 << 2  # odometry_flags::REVISION: republished history


def yaw_of(q):
    """Yaw (rad) of the sensor's x axis in the navigation frame, from (w, x, y, z)."""
    w, x, y, z = q
    return math.atan2(2 * (x * y + w * z), 1 - 2 * (y * y + z * z))


def states(path):
    """Live odometry states as (t_s from the first raw sample, x, y, yaw, sigma_h)."""
    out, t0 = [], None
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, ch, _, v in reader.iter_decoded_messages(log_time_order=False):
            if ch.topic == "mems/imu/raw" and t0 is None:
                t0 = v.stamps.sample_ns
            if ch.topic != "mems/odometry/state" or v.flags & REVISION:
                continue
            s = v.position_sigma_m
            out.append(((v.stamps.sample_ns - t0) * 1e-9, v.position_m[0], v.position_m[1],
                        yaw_of(v.attitude_wxyz), math.sqrt((s[0] ** 2 + s[1] ** 2) / 2)))
    return out


def budget(rec_id, binary, data, extra):
    side = json.loads((data / f"{rec_id}.json").read_text())
    track = side["truth"]["track"]
    with tempfile.TemporaryDirectory() as tmp:
        mcap = Path(tmp) / "run.mcap"
        cmd = [str(binary), "offline", "--input", str(data / side["input"]), "--json",
               "--out", str(mcap), *extra]
        proc = subprocess.run(cmd, capture_output=True, text=True, check=True)
        result = json.loads(proc.stdout.splitlines()[-1])
        run = states(mcap)
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
