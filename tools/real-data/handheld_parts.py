#!/usr/bin/env python3
"""A hand-held walk's end error split into its parts against a motion-capture track: the
distance, the heading, the forward axis; with the time the walker stands, the filter's tilt
error and what the calibration stage's gyroscope refinement took at the detector's rests.

Runs `mems-odometry offline --out` on ID (tools/real-data's converted data, an identity
calibration as bench.py gives), reads the live states and the raw and corrected samples back
from the MCAP, and turns the sidecar's `truth.track` (t_s, x, y, heading) into our navigation
frame as bench.py does. The track's heading is the one the odometry's alignment would give the
phone (the smallest turn of its up onto z, then the yaw: tyrex_attitude.py), so ours is read
the same way from the filter's attitude ([`smallest_turn_yaw`]). Over increments of
INCREMENT_S seconds, with `d` our horizontal step and `t` the track's (m, our frame, z up,
angles counter-clockwise), as error_budget.py splits a wheeled run:
- distance: `(|d| - |t|) t/|t|`, what the steps' summed length costs;
- heading: `|d| (R(e) t/|t| - t/|t|)`, `e` our yaw change since alignment minus the track's;
- forward axis: `d - t` minus both (the step's direction against the phone's yaw, ours against
  the track's: the walking frame's forward axis);
- standing: the whole `d - t` of the increments where the track moves less than STANDING_MPS
  (steps taken while the walker stands or turns on the spot), which the three above skip.
Their sums add up to the end error exactly. Also per walk:
- the share of the increments that are standing, and the length our steps add there;
- tilt: the median angle (deg) between the filter's gravity in the sensor frame and the mean
  specific force over TILT_WINDOW_S around it (a walker's mean acceleration is near zero);
- stage gyro: the calibration stage's refined gyroscope bias at the end (raw minus corrected
  rate, deg/s) along the mean up direction, and the median |heading rate| (deg/s) of the track
  over the samples the detector flags at rest.

Usage: handheld_parts.py [--bin PATH] [--data DIR] ID ... [-- offline flags]
       handheld_parts.py --self-test
"""
import json
import math
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import bench  # noqa: E402  (track_at, heading_at, evaluate, identity_calibration)

INCREMENT_S = 0.5
STANDING_MPS = 0.15
TILT_WINDOW_S = 2.0
REVISION = 1 << 2  # odometry_flags::REVISION: republished history
ALIGNED = 1 << 1  # odometry_flags::ALIGNED
ZERO_STATE = 1 << 0  # corrected_flags::ZERO_STATE: the detector's rest verdict


def rotation(q):
    """The rotation matrix (rows) of the unit quaternion (w, x, y, z), sensor to navigation."""
    w, x, y, z = q
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


def smallest_turn_yaw(q):
    """The yaw (rad) of the attitude `q` (w, x, y, z; sensor to navigation, z up) left once
    the smallest turn of the sensor's up onto z is taken out: `R = Rz(yaw) R0`, `R0` turning
    `u = R^T z` onto z about `u x z`. Undefined (None) when the sensor's up is -z."""
    r = rotation(q)
    u = (r[2][0], r[2][1], r[2][2])  # R^T z
    c = u[2]
    if c <= -1 + 1e-9:
        return None
    v = (u[1], -u[0])  # u x z (its z component is 0)
    # Rodrigues, R0 = I + [v]x + (v v^T - |v|^2 I) / (1 + c): its first row.
    r0_row0 = (1 - v[1] ** 2 / (1 + c), v[0] * v[1] / (1 + c), v[1])
    # yaw from R R0^T's first column.
    m10 = sum(r[1][k] * r0_row0[k] for k in range(3))
    m00 = sum(r[0][k] * r0_row0[k] for k in range(3))
    return math.atan2(m10, m00)


def split(ours, truth):
    """The parts of the end error over paired increments: `ours` and `truth` are lists of
    (x, y, yaw) at the same times (m, rad; our frame, yaw changes counted from the first).
    An increment where the track moves less than STANDING_MPS gives its whole `d - t` to
    `standing`; the others split it into `distance`, `heading` and `forward` (module
    documentation). Returns those end vectors (m) and their sum `total`, and the lengths
    `ours_m`, `truth_m`, `standing_steps_m` (ours in the standing increments), and
    `standing_share` (of the increments)."""
    parts = {k: [0.0, 0.0] for k in ("distance", "heading", "forward", "standing", "total")}
    ours_m = truth_m = standing_steps_m = 0.0
    standing = 0
    for (a, b), (p, q) in zip(zip(ours, ours[1:]), zip(truth, truth[1:])):
        d = (b[0] - a[0], b[1] - a[1])
        t = (q[0] - p[0], q[1] - p[1])
        dn, tn = math.hypot(*d), math.hypot(*t)
        ours_m += dn
        truth_m += tn
        for i in range(2):
            parts["total"][i] += d[i] - t[i]
        if tn < STANDING_MPS * INCREMENT_S:
            standing += 1
            standing_steps_m += dn
            for i in range(2):
                parts["standing"][i] += d[i] - t[i]
            continue
        e = bench.wrap((b[2] - ours[0][2]) - (q[2] - truth[0][2]))
        dist, head = bench.split_step(d, t, e, 1e-9)
        for i in range(2):
            parts["distance"][i] += dist[i]
            parts["heading"][i] += head[i]
            parts["forward"][i] += d[i] - t[i] - dist[i] - head[i]
    n = max(1, len(ours) - 1)
    return {**parts, "ours_m": ours_m, "truth_m": truth_m, "standing_share": standing / n,
            "standing_steps_m": standing_steps_m}


def read_run(path):
    """From the run's MCAP: the live aligned states as (t_s, x, y, yaw, gravity_sensor), the
    samples as (t_s, raw accel g, raw gyro dps, corrected gyro dps, at rest), t_s counted from
    the first raw sample."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory
    states, raw, corrected, t0 = [], {}, {}, None
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, ch, _, v in reader.iter_decoded_messages(log_time_order=False):
            if ch.topic == "mems/imu/raw":
                t0 = v.stamps.sample_ns if t0 is None else t0
                raw[v.seq] = (list(v.accel_g), list(v.gyro_dps))
            elif ch.topic == "mems/imu/corrected":
                corrected[v.seq] = (v.stamps.sample_ns, [math.degrees(w) for w in v.gyro_rps],
                                    bool(v.flags & ZERO_STATE))
            elif ch.topic == "mems/odometry/state" and not v.flags & REVISION and v.flags & ALIGNED:
                yaw = smallest_turn_yaw(list(v.attitude_wxyz))
                if yaw is not None:
                    states.append(((v.stamps.sample_ns - t0) * 1e-9, v.position_m[0],
                                   v.position_m[1], yaw, list(v.gravity_sensor_mps2)))
    samples = [((corrected[s][0] - t0) * 1e-9, raw[s][0], raw[s][1], corrected[s][1], corrected[s][2])
               for s in sorted(corrected) if s in raw]
    return states, samples


def angle_deg(a, b):
    dot = sum(x * y for x, y in zip(a, b))
    na, nb = math.sqrt(sum(x * x for x in a)), math.sqrt(sum(x * x for x in b))
    return math.degrees(math.acos(max(-1.0, min(1.0, dot / (na * nb)))))


def tilt_errors(states, samples):
    """Per state every INCREMENT_S: the angle (deg) between its gravity and the mean raw
    specific force over TILT_WINDOW_S about it."""
    out, j0, last = [], 0, -1e9
    for s in states:
        if s[0] - last < INCREMENT_S:
            continue
        last = s[0]
        while j0 < len(samples) and samples[j0][0] < s[0] - TILT_WINDOW_S / 2:
            j0 += 1
        window = [m[1] for m in samples[j0:] if m[0] <= s[0] + TILT_WINDOW_S / 2]
        if window:
            mean = [sum(f[k] for f in window) / len(window) for k in range(3)]
            out.append(angle_deg(mean, s[4]))
    return out


def parts_of(rec_id, binary, data, extra):
    side_path = data / f"{rec_id}.json"
    side = json.loads(side_path.read_text())
    track = side["truth"].get("track")
    if not track or len(track[0]) < 4:
        sys.exit(f"{side_path}: field truth.track: no track with a heading (t_s, x, y, heading) "
                 f"to split against (truth kind {side['truth'].get('kind')!r})")
    with tempfile.TemporaryDirectory() as tmp:
        calib = Path(tmp) / "identity.toml"
        calib.write_text(bench.identity_calibration())
        mcap = Path(tmp) / "run.mcap"
        cmd = [str(binary), "offline", "--calib", str(calib), "--input", str(data / side["input"]),
               "--json", "--out", str(mcap), *extra]
        proc = subprocess.run(cmd, capture_output=True, text=True, check=True)
        result = json.loads([l for l in proc.stdout.splitlines() if l.startswith("{")][-1])
        states, samples = read_run(mcap)
    t_a = result["aligned_at_s"]
    if t_a is None or len(states) < 2:
        sys.exit(f"{rec_id}: the odometry never aligned ({' '.join(cmd)}): nothing to split")
    h_a = bench.heading_at(track, t_a)
    c, s = math.cos(h_a), math.sin(h_a)
    start = bench.track_at(track, t_a)
    ours, truth, last = [], [], -1e9
    for st in states:
        if st[0] - last < INCREMENT_S:
            continue
        last = st[0]
        x, y = bench.track_at(track, st[0])
        dx, dy = x - start[0], y - start[1]
        ours.append((st[1], st[2], st[3]))
        truth.append((c * dx + s * dy, -s * dx + c * dy, bench.heading_at(track, st[0])))
    p = split(ours, truth)
    bench_row = bench.evaluate(side, result)
    tilt = tilt_errors(states, samples)
    up = [sum(m[1][k] for m in samples) for k in range(3)]
    up_n = math.sqrt(sum(x * x for x in up))
    refined = [samples[-1][2][k] - samples[-1][3][k] for k in range(3)]
    rest_rates = []
    for a, b in zip(samples, samples[1:]):
        if a[4] and b[0] > a[0]:
            ha, hb = bench.heading_at(track, a[0]), bench.heading_at(track, b[0] + 0.1)
            rest_rates.append(abs(math.degrees(bench.wrap(hb - ha)) / (b[0] + 0.1 - a[0])))
    return {
        "id": rec_id, "pct": bench_row["pct_of_distance"][1], "error_m": bench_row["error_m"][1],
        "covered": bench_row["covered"], "parts": p, "tilt_median_deg": statistics.median(tilt),
        "stage_gyro_up_dps": sum(refined[k] * up[k] for k in range(3)) / up_n,
        "rest_s": sum(1 for m in samples if m[4]) / max(1, len(samples)) * (samples[-1][0] - samples[0][0]),
        "rest_heading_rate_dps": statistics.median(rest_rates) if rest_rates else None,
    }


def print_table(rows):
    print("| walk | end error | ours / track m | distance m | heading m | forward axis m | standing m | "
          "standing share (steps there, m) | tilt deg | stage gyro up deg/s | rests s (track heading rate deg/s) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        p = r["parts"]
        norm = lambda k: math.hypot(*p[k])  # noqa: E731
        rate = r["rest_heading_rate_dps"]
        print(f"| {r['id']} | {r['error_m']:.2f} m ({r['pct']:.1f} %) | {p['ours_m']:.1f} / {p['truth_m']:.1f} | "
              f"{norm('distance'):.2f} | {norm('heading'):.2f} | {norm('forward'):.2f} | {norm('standing'):.2f} | "
              f"{100 * p['standing_share']:.0f} % ({p['standing_steps_m']:.1f}) | {r['tilt_median_deg']:.1f} | "
              f"{r['stage_gyro_up_dps']:+.1f} | {r['rest_s']:.1f} ({'-' if rate is None else f'{rate:.1f}'}) |")


def self_test():
    """The yaw against rotations built from a known yaw and tilt; the split against walks
    made with a known distance scale, heading drift and forward-axis offset."""
    def quat(axis, angle):
        n = math.sqrt(sum(a * a for a in axis))
        s = math.sin(angle / 2) / n
        return (math.cos(angle / 2), axis[0] * s, axis[1] * s, axis[2] * s)

    def mul(a, b):
        w1, x1, y1, z1 = a
        w2, x2, y2, z2 = b
        return (w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2)

    # R = Rz(psi) Ra(beta), a horizontal: the smallest turn of u = Ra(-beta) z onto z is Ra(beta).
    for psi, a_deg, beta in [(0.3, 0, 0.2), (-2.5, 70, 1.4), (1.0, 200, 1.5707), (3.0, 10, 2.5)]:
        a = (math.cos(math.radians(a_deg)), math.sin(math.radians(a_deg)), 0.0)
        yaw = smallest_turn_yaw(mul(quat((0, 0, 1), psi), quat(a, beta)))
        assert abs(bench.wrap(yaw - psi)) < 1e-9, (psi, a_deg, beta, yaw)
    assert smallest_turn_yaw(quat((1, 0, 0), math.pi)) is None

    # A walk round a square, 0.5 m per increment, the track's yaw turning with it.
    truth = [(0.0, 0.0, 0.0)]
    for i in range(200):
        heading = (i // 20) * math.pi / 2
        x, y, _ = truth[-1]
        truth.append((x + 0.5 * math.cos(heading), y + 0.5 * math.sin(heading), heading))

    def walk(scale, drift, offset):
        ours = [(0.0, 0.0, 0.0)]
        for i, (p, q) in enumerate(zip(truth, truth[1:])):
            e = drift * (i + 1)
            t = (q[0] - p[0], q[1] - p[1])
            ang = math.atan2(t[1], t[0]) + e + offset
            n = scale * math.hypot(*t)
            x, y, _ = ours[-1]
            ours.append((x + n * math.cos(ang), y + n * math.sin(ang), q[2] + e))
        return ours

    def end(ours):
        return (ours[-1][0] - truth[-1][0], ours[-1][1] - truth[-1][1])

    only_scale = split(walk(1.2, 0.0, 0.0), truth)
    assert math.hypot(*only_scale["heading"]) < 1e-9 and math.hypot(*only_scale["forward"]) < 1e-9
    assert abs(only_scale["ours_m"] / only_scale["truth_m"] - 1.2) < 1e-9
    only_drift = walk(1.0, 0.002, 0.0)
    p = split(only_drift, truth)
    assert math.hypot(*p["distance"]) < 1e-9 and math.hypot(*p["forward"]) < 1e-9
    assert math.dist(p["heading"], end(only_drift)) < 1e-9
    only_offset = walk(1.0, 0.0, 0.3)
    p = split(only_offset, truth)
    assert math.hypot(*p["distance"]) < 1e-9 and math.hypot(*p["heading"]) < 1e-9
    assert math.dist(p["forward"], end(only_offset)) < 1e-9
    mixed = walk(0.9, -0.001, 0.2)
    p = split(mixed, truth)
    total = [p["distance"][i] + p["heading"][i] + p["forward"][i] for i in range(2)]
    assert math.dist(total, end(mixed)) < 1e-9
    assert p["standing_share"] == 0.0 and math.hypot(*p["standing"]) == 0.0
    # The walker stops for 40 of the 200 increments while we step on, 0.3 m east each.
    stopped = truth[:81] + [truth[80]] * 40 + [(x, y, h) for x, y, h in truth[81:161]]
    ours = [(x, y, h) for x, y, h in truth[:81]]
    ours += [(truth[80][0] + 0.3 * (i + 1), truth[80][1], truth[80][2]) for i in range(40)]
    ours += [(x + 12.0, y, h) for x, y, h in truth[81:161]]
    p = split(ours, stopped)
    assert math.dist(p["standing"], (12.0, 0.0)) < 1e-9, p["standing"]
    assert max(math.hypot(*p[k]) for k in ("distance", "heading", "forward")) < 1e-9
    assert abs(p["standing_share"] - 40 / 200) < 1e-12 and abs(p["standing_steps_m"] - 12.0) < 1e-9
    print("handheld_parts.py self-test: ok")


def main():
    argv = sys.argv[1:]
    if argv == ["--self-test"]:
        self_test()
        return
    args, extra = bench.ids_cli(__doc__.splitlines()[0], argv)
    print_table([parts_of(rec_id, args.bin, args.data, extra) for rec_id in args.ids])


if __name__ == "__main__":
    main()
