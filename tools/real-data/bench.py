#!/usr/bin/env python3
"""Runs `mems-odometry offline` on every converted real-data recording and prints a table.

Reads tools/real-data/corpus.json for the recording list and, from the data directory
(default $MEMS_REAL_DATA or /work/real-data, written by convert.py), each recording's ID.csv and
sidecar ID.json (truth, distance, extra arguments). One run per recording; a run that fails
(non-zero exit, no JSON) gets a row with its error message and the next one runs.

Figures (horizontal plane, metres; our navigation frame has z up, origin and heading fixed at
alignment):
- end error: |e| with e = estimated end displacement minus true end displacement. A closed loop
  ends where it started (truth 0 in every frame). For truths known only as a distance from the
  start in a frame whose heading is not ours (footprints, GNSS, RTK), |e| lies in
  [ | |p| - |t| |, |p| + |t| ] with p our end displacement and t the truth's; the table prints
  that interval.
- % of distance: end error over the true distance (our own estimated distance, marked *, where
  the source publishes none). A truth given as a track on the recording's clock (a particle
  filter's poses, a robot's GNSS fixes) counts from the pose at our alignment, distance included;
  where it has no heading of its own, it is turned into our frame by the rotation that best
  maps its first ALIGN_PATH_M metres onto our track (the JSON's `track`) at the same times, and
  the error is then one figure, not an interval.
- ours / true distance: the path our run reports (the JSON's `distance_m`: the track's length,
  or a walk's summed steps) over the true distance, where the source gives one. A closed loop's
  end error rewards a run that goes nowhere: one that counts no step of a walk ends where the
  walk began, as the walk does (a step-counting rule that dropped most of the hand-held walks'
  steps more than halved their median end error): the ratio shows it.
- track error: where the truth is a track on the recording's clock, the root mean square over
  our track's poses (the JSON's `track`) of the horizontal distance to the truth's pose at the
  same time, both from our alignment and the truth turned into our frame as for the end error
  (the absolute trajectory error of Zhang and Scaramuzza, IROS 2018, sec. IV, with that
  yaw-only alignment), as % of the true distance. An end error says where a run stopped; a
  run whose heading spun ends near its start on a loop, as the truth does, and only its track
  shows it.
- 1-sigma: sqrt((sx^2 + sy^2) / 2) of the reported position sigma (per-axis rms).
- covered: error <= r68 = 1.515 * sqrt((sx^2 + sy^2) / 2), the radius holding 68 % of a circular
  2-D Gaussian with that per-axis sigma (r = sigma sqrt(-2 ln 0.32) = 1.5096 sigma; 1.515 is
  that figure rounded up). With an interval: yes if its upper end is covered, no if its lower
  end is not, `?` otherwise.

Summaries are per platform class (corpus.json: foot, wheeled, vehicle, handheld, arm): runs
that gave a position, 1-sigma coverage, the median % of distance (upper end of the interval
where the truth is a distance only), the median of ours / true distance with its range, and
the median track error over the runs that have one.

Leave one source out (`--loso`): corpus.json's `tuning` section lists the `mems-odometry
offline` flags whose values were (or would be) chosen on the corpus, each with its candidate
values and the platform classes it applies to. Per class, the candidates are searched as a
joint grid when it has at most MAX_GRID points, else one flag at a time from the defaults.
In-sample: the candidate with the smallest median % of distance over all of the class's
recordings, and that median. Leave one source out: for each source S of the class, the
candidate with the smallest median over the class's recordings from the other sources, then
S's recordings run with it; the median of those runs over the class. A source here is a
repository: corpus.json sources from one repository are held out together, unless a source
names its own `holdout` group (the Tyrex phones: separate sessions on two phones with
different IMU makes, held out by phone). A class with a single source has no other source to choose on: its
recordings are run with the defaults (the values the binary uses without flags), and the
table says so. A failed run counts as an
infinite error, as does a run with no distance after its alignment. Runs are cached by
(recording, arguments).

Usage: bench.py [--bin PATH] [--calib TOML] [--data DIR] [--only ID ...] [--json] [--timeout S] [--loso]
"""

import argparse
import bisect
import contextlib
import itertools
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import containers

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
R68_FACTOR = 1.515


def ids_cli(description, argv):
    """The command line of a per-recording tool of this folder: `[--bin PATH] [--data DIR] ID
    ... [-- ARGS]`, the arguments after `--` passed on to `mems-odometry offline`. Returns
    (parsed arguments, extra arguments)."""
    extra = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1:]
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--bin", type=Path, default=REPO / "target/release/mems-odometry")
    ap.add_argument("--data", type=Path,
                    default=Path(os.environ.get("MEMS_REAL_DATA", "/work/real-data")))
    ap.add_argument("ids", nargs="+")
    return ap.parse_args(argv), extra


def identity_calibration(gravity_mps2=9.80665):
    """An identity accelerometer calibration file (bias 0, S = I, zero covariance) in the
    format of calibrate/src/calibfile.rs, for recordings that come with no calibration."""
    zeros12 = "[" + ", ".join(["0.0"] * 12) + "]"
    return "\n".join([
        "format_version = 1",
        'model = "full"',
        'method = "labelled"',
        'weighting = "unweighted"',
        'covariance_mode = "residual_scaled"',
        f"gravity_mps2 = {gravity_mps2}",
        "bias_g = [0.0, 0.0, 0.0]",
        "scale = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]",
        'param_names = ["b_x", "b_y", "b_z", "S_xx", "S_xy", "S_xz", "S_yx", "S_yy", "S_yz", "S_zx", "S_zy", "S_zz"]',
        "covariance = [" + ", ".join([zeros12] * 12) + "]",
        "sigma = " + zeros12,
        "",
        "[source]",
        'file = "identity (tools/real-data/bench.py)"',
        'kind = "none"',
        "poses = 0",
        "",
        "[residuals]",
        "rms_g = [0.0, 0.0, 0.0]",
        "max_abs_g = 0.0",
        "dof = [0, 0, 0]",
        "chi2 = [0.0, 0.0, 0.0]",
        "per_pose_g = []",
        "",
    ])


def failure_message(stderr, code):
    """The error line of a failed run: the last non-empty stderr line (notes such as the
    defaulted-noise message come first, the error last), or the exit code."""
    lines = [l.strip() for l in stderr.splitlines() if l.strip()]
    return lines[-1] if lines else f"exit code {code}, no message"


def run_one(binary, calib, csv, extra, timeout):
    cmd = [str(binary), "offline", "--calib", str(calib), "--input", str(csv), "--json", *extra]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, f"timed out after {timeout} s", cmd, ""
    if proc.returncode != 0:
        return None, failure_message(proc.stderr, proc.returncode), cmd, proc.stderr
    for line in reversed(proc.stdout.splitlines()):
        if line.startswith("{"):
            try:
                return json.loads(line), None, cmd, proc.stderr
            except json.JSONDecodeError as e:
                return None, f"unreadable JSON output: {e}", cmd, proc.stderr
    return None, "no JSON line on stdout", cmd, proc.stderr


ALIGN_FOOTPRINT = 3
CHECK_FOOTPRINT = 5
MAX_ALIGN_DISAGREEMENT_DEG = 10.0


def heading_to(rests, footprint):
    """The heading change (rad) that turns `footprint` (m, relative to the first) onto our
    track's direction at the same distance from the start: the track being the start and our
    rests' positions in order, interpolated linearly where it first reaches that distance.
    None if it never does."""
    d = math.hypot(*footprint)
    prev, prev_d = (0.0, 0.0), 0.0
    for r in rests:
        q = r["position_m"][:2]
        q_d = math.hypot(*q)
        if q_d >= d:
            a = (d - prev_d) / (q_d - prev_d)
            x, y = (prev[i] + a * (q[i] - prev[i]) for i in range(2))
            return math.atan2(y, x) - math.atan2(footprint[1], footprint[0])
        prev, prev_d = q, q_d
    return None


def footprints_in_our_frame(truth, rests):
    """The footprint truth's end point turned into our frame, as the dataset's authors align
    their INS (the heading from the start to the third footprint, own_data.py strideAlign = 3):
    our track's heading from the start at the third footprint's distance, against the
    footprint's. The turn is a proper rotation: the authors negate the GCP y axis to match
    their z-down INS frame (own_data.py), so the published one matches our z-up frame, which
    fitting the whole track confirms (on four of the five walks the footprints lie 0.3-0.6 m
    from our rests unflipped, 0.8-6 m flipped; the fifth is an out-and-back). Checked against the same at the fifth footprint; None (the
    distance-only truth then applies) when the two disagree by more than 10 degrees, when a
    rest is missing, or when the truth has no footprints."""
    fp = truth.get("footprints_m")
    if truth.get("kind") != "gcp" or not fp or len(fp) <= CHECK_FOOTPRINT:
        return None
    yaw = heading_to(rests, fp[ALIGN_FOOTPRINT])
    check = heading_to(rests, fp[CHECK_FOOTPRINT])
    if yaw is None or check is None:
        return None
    disagreement = math.degrees(math.remainder(yaw - check, 2 * math.pi))
    if abs(disagreement) > MAX_ALIGN_DISAGREEMENT_DEG:
        return None
    c, s = math.cos(yaw), math.sin(yaw)
    x, y = fp[-1]
    return {
        "yaw_deg": math.degrees(yaw),
        "check_disagreement_deg": disagreement,
        "end_m": [c * x - s * y, s * x + c * y],
    }


TRACK_MIN_STEP_M = 0.1


def wrap(a):
    """The angle `a` (rad) wrapped into [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


def split_step(d, t, e, min_m):
    """One step of our track, `d` (dx, dy, m), against the truth's over the same time, `t`,
    with our heading `e` (rad) off the truth's there: the share of `d - t` that is distance,
    the step's length error along the truth's direction, and the share that is heading, our
    step turned by `e` against the truth's direction at our length. Returns (distance,
    heading), each (dx, dy) in m; zeros for a truth step not longer than `min_m` (no
    direction). What is left, `d - t - distance - heading`, is the direction's own error."""
    tn = math.hypot(*t)
    if tn <= min_m:
        return (0.0, 0.0), (0.0, 0.0)
    dn = math.hypot(*d)
    u = (t[0] / tn, t[1] / tn)
    distance = ((dn - tn) * u[0], (dn - tn) * u[1])
    ru = (math.cos(e) * u[0] - math.sin(e) * u[1], math.sin(e) * u[0] + math.cos(e) * u[1])
    return distance, (dn * (ru[0] - u[0]), dn * (ru[1] - u[1]))


def heading_at(track, t_s):
    """The track's heading (rad, its 4th column) at the last pose at or before t_s."""
    best = track[0]
    for q in track:
        if q[0] > t_s:
            break
        best = q
    return best[3]


def track_at(track, t_s):
    """The track's (x, y) at time t_s (linear between its poses, clamped to its ends)."""
    if t_s <= track[0][0]:
        return track[0][1:3]
    for a, b in zip(track, track[1:]):
        if a[0] <= t_s <= b[0]:
            f = (t_s - a[0]) / (b[0] - a[0]) if b[0] > a[0] else 0.0
            return [a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2])]
    return track[-1][1:3]


def track_length(track, t_s, min_step=TRACK_MIN_STEP_M):
    """The track's length from time t_s to its end, over steps of at least `min_step` m (the
    truth's `track_min_step_m` where it has one: 0.5 m for GNSS fixes; else 0.1 m, as
    convert.py measures the particle filter's whole track)."""
    return containers.path_length([track_at(track, t_s)] + [q[1:3] for q in track if q[0] > t_s], min_step)


ALIGN_PATH_M = 10.0
CHECK_PATH_M = 20.0


def track_heading(truth, ours, t0, path_m):
    """The heading change (rad) that turns the truth track's displacements from its pose at
    our alignment (time t0, s) onto our track's at the same times, over the truth's first
    `path_m` metres of path: the least-squares rotation in the plane, atan2(sum t x o,
    sum t . o) (a yaw-only alignment of the first poses, as in Zhang and Scaramuzza, "A
    Tutorial on Quantitative Trajectory Evaluation for Visual(-Inertial) Odometry", IROS 2018,
    sec. IV: an IMU alone cannot know its heading, so only the first stretch fixes it). None
    when either track ends before that much path or the stretch's end lies less than half of
    it from its start (a turn on the spot tells no direction)."""
    start = track_at(truth["track"], t0)
    min_step = truth.get("track_min_step_m", TRACK_MIN_STEP_M)
    ours_xy = [p[:3] for p in ours]
    cross = dot = walked = 0.0
    last = start
    for q in truth["track"]:
        if q[0] <= t0:
            continue
        if q[0] > ours[-1][0]:
            return None
        step = math.dist(q[1:3], last)
        if step >= min_step:
            walked += step
            last = q[1:3]
        t = (q[1] - start[0], q[2] - start[1])
        o = track_at(ours_xy, q[0])
        cross += t[0] * o[1] - t[1] * o[0]
        dot += t[0] * o[0] + t[1] * o[1]
        if walked >= path_m:
            return math.atan2(cross, dot) if math.hypot(*t) >= 0.5 * path_m else None
    return None


def track_in_our_frame(truth, out):
    """The truth track's end, from its pose at our alignment, turned into our frame by
    [`track_heading`] over ALIGN_PATH_M of path; None (the distance-only truth then applies)
    when our JSON has no track or the stretch tells no heading. The poses are paired with ours
    by time on the recording's one clock, so unlike the footprints (paired by distance) no
    check on a longer stretch refuses it: a heading that differs there is our own drift, which
    the end error must show. The same over CHECK_PATH_M is reported beside it."""
    ours, t0 = out.get("track"), out.get("aligned_at_s")
    if not truth.get("track") or not ours or t0 is None:
        return None
    yaw = track_heading(truth, ours, t0, ALIGN_PATH_M)
    if yaw is None:
        return None
    check = track_heading(truth, ours, t0, CHECK_PATH_M)
    to_ours = turned(track_at(truth["track"], t0), yaw)
    return {
        "yaw_deg": math.degrees(yaw),
        "check_disagreement_deg": None if check is None else math.degrees(math.remainder(yaw - check, 2 * math.pi)),
        "end_m": list(to_ours(truth["track"][-1][1:3])),
    }


def turned(start, yaw):
    """The map of a truth (x, y) into our frame: from `start`, turned by `yaw` (rad,
    counter-clockwise)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return lambda q: (c * (q[0] - start[0]) - s * (q[1] - start[1]),
                      s * (q[0] - start[0]) + c * (q[1] - start[1]))


def into_our_frame(truth, out):
    """The map of the truth track's (x, y) into our frame (from its pose at our alignment),
    or None where the truth tells no heading: turned by the body's heading there plus the
    IMU's yaw on the body where the sidecar gives both (our heading is the sensor's x axis at
    alignment, eskf::align: the smallest turn of the measured up onto z), else by
    [`track_heading`] over ALIGN_PATH_M of path."""
    t0 = out.get("aligned_at_s")
    if not truth.get("track") or t0 is None:
        return None
    start = track_at(truth["track"], t0)
    yaw_on_body = truth.get("sensor_yaw_on_body_deg")
    if yaw_on_body is not None and len(truth["track"][0]) > 3:
        return turned(start, -(heading_at(truth["track"], t0) + math.radians(yaw_on_body)))
    if not out.get("track"):
        return None
    yaw = track_heading(truth, out["track"], t0, ALIGN_PATH_M)
    return None if yaw is None else turned(start, yaw)


def track_error(truth, out, to_ours):
    """The track error (module documentation), m: rms over our track's poses within the
    truth's time span of the horizontal distance to the truth's pose at the same time (linear
    between its poses), in our frame by `to_ours` ([`into_our_frame`]); None without it."""
    if to_ours is None:
        return None
    poses = truth["track"]
    times = [q[0] for q in poses]
    sum_sq, n = 0.0, 0
    for t, x, y, *_ in out["track"]:
        i = bisect.bisect_left(times, t)
        if i == 0 or i == len(times):
            continue
        a, b = poses[i - 1], poses[i]
        f = (t - a[0]) / (b[0] - a[0])
        tx, ty = to_ours((a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2])))
        sum_sq += (x - tx) ** 2 + (y - ty) ** 2
        n += 1
    return math.sqrt(sum_sq / n) if n else None


def evaluate(side, out):
    """The row's figures from the sidecar (truth) and the odometry's JSON."""
    p = out["end_displacement_m"]
    s = out["sigma_m"]
    sigma_h = math.sqrt((s[0] ** 2 + s[1] ** 2) / 2)
    r68 = R68_FACTOR * sigma_h
    truth = side["truth"]
    turned_end = None
    to_ours = into_our_frame(truth, out)
    t_vec = truth.get("end_displacement_m")
    if truth.get("frame") in ("any", "nav") and t_vec is not None:
        err = math.hypot(p[0] - t_vec[0], p[1] - t_vec[1])
        lo = hi = err
    elif truth.get("track") and out.get("aligned_at_s") is not None:
        # A track on the recording's clock (particle-filter poses, a robot's GNSS fixes): the
        # truth counts from the pose where the odometry aligned, as our position does.
        start = track_at(truth["track"], out["aligned_at_s"])
        end = truth["track"][-1][1:3]
        if truth.get("sensor_yaw_on_body_deg") is not None and len(truth["track"][0]) > 3:
            t_vec = list(to_ours(end))
            lo = hi = math.hypot(p[0] - t_vec[0], p[1] - t_vec[1])
        elif (turned_end := track_in_our_frame(truth, out)) is not None:
            t_vec = turned_end["end_m"]
            lo = hi = math.hypot(p[0] - t_vec[0], p[1] - t_vec[1])
        else:
            t = math.dist(start, end)
            ours = math.hypot(p[0], p[1])
            lo, hi = abs(ours - t), ours + t
    elif (turned_end := footprints_in_our_frame(truth, out.get("rests", []))) is not None:
        t_vec = turned_end["end_m"]
        err = math.hypot(p[0] - t_vec[0], p[1] - t_vec[1])
        lo = hi = err
    else:
        t = truth["end_distance_m"]
        ours = math.hypot(p[0], p[1])
        lo, hi = abs(ours - t), ours + t
    distance = side.get("distance_m")
    if truth.get("track") and out.get("aligned_at_s") is not None:
        distance = track_length(truth["track"], out["aligned_at_s"], truth.get("track_min_step_m", TRACK_MIN_STEP_M))
    ours_distance = distance is None
    if ours_distance:
        distance = out.get("distance_m")
    if not distance:
        # Nothing navigated (aligned only at the end): no position worth the name to cover.
        covered = "no"
    elif hi <= r68:
        covered = "yes"
    elif lo > r68:
        covered = "no"
    else:
        covered = "?"
    pct = (lambda e: 100.0 * e / distance if distance else None)
    ours = out.get("distance_m")
    track_rms = track_error(truth, out, to_ours)
    return {
        "end_displacement_m": p,
        "sigma_m": s,
        "track_rms_m": track_rms,
        "track_rms_pct": pct(track_rms) if track_rms is not None else None,
        "estimated_distance_m": ours,
        "distance_ratio": ours / distance if distance and not ours_distance and ours is not None else None,
        "error_m": [lo, hi],
        "distance_m": distance,
        "distance_is_estimate": ours_distance,
        "pct_of_distance": [pct(lo), pct(hi)],
        "sigma_h_m": sigma_h,
        "r68_m": r68,
        "covered": covered,
        "truth_turned": turned_end,
    }


def fmt_range(lo, hi, digits):
    if lo is None:
        return "-"
    if abs(hi - lo) < 10 ** -digits:
        return f"{lo:.{digits}f}"
    return f"{lo:.{digits}f} - {hi:.{digits}f}"


def table(rows):
    head = ["recording", "IMU", "platform", "duration (s)", "distance (m)", "end error (m)",
            "% of distance", "track error, % of distance", "ours / true distance", "1-sigma (m)", "r68 (m)",
            "covered", "authors' result"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        side = r.get("sidecar") or {}
        conv = side.get("conversion", {})
        base = [r["id"], side.get("imu", "-").split(" (")[0], side.get("platform", "-"),
                f"{conv['duration_s']:.1f}" if conv else "-"]
        if r.get("error"):
            dist = side.get("distance_m")
            base.append(f"{dist:.1f}" if dist else "-")
            out.append("| " + " | ".join(base + [f"failed: {r['error']}", "", "", "", "", "", "",
                                                side.get("authors_result") or "-"]) + " |")
            continue
        e = r["result"]
        dist = f"{e['distance_m']:.1f}" + ("*" if e["distance_is_estimate"] else "")
        pct = e["pct_of_distance"]
        out.append("| " + " | ".join(base + [
            dist, fmt_range(*e["error_m"], 3),
            fmt_range(pct[0], pct[1], 2) if pct[0] is not None else "-",
            f"{e['track_rms_pct']:.2f}" if e.get("track_rms_pct") is not None else "-",
            f"{e['distance_ratio']:.2f}" if e.get("distance_ratio") is not None else "-",
            f"{e['sigma_h_m']:.3f}", f"{e['r68_m']:.3f}", e["covered"],
            side.get("authors_result") or "-"]) + " |")
    return "\n".join(out)


def pct_upper(row):
    """The row's % of distance, upper end of its interval; infinite for a failed run and for
    one with no distance to divide by (a run that aligned at its very end)."""
    if row.get("error") or row["result"]["pct_of_distance"][1] is None:
        return math.inf
    return row["result"]["pct_of_distance"][1]


def fmt_pct(value):
    return "inf" if value == math.inf else f"{value:.2f} %"


def navigated(row):
    """Whether the run gave a position over some distance (not failed, not aligned only at its
    very end)."""
    return not row.get("error") and bool(row["result"]["distance_m"])


def summary(rows):
    done = [r for r in rows if navigated(r)]
    covered = sum(1 for r in done if r["result"]["covered"] == "yes")
    undecided = sum(1 for r in done if r["result"]["covered"] == "?")
    loops = [r["result"]["pct_of_distance"][1] for r in done
             if r["sidecar"]["platform"] == "foot" and r["sidecar"]["truth"]["kind"] == "closed_loop"]
    lines = [
        f"positions produced (over some distance): {len(done)} of {len(rows)}",
        f"1-sigma covers the error (r68): {covered} of {len(rows)} ({undecided} undecided: truth known as a distance only)",
    ]
    if loops:
        lines.append(f"median end error over the foot-mounted closed loops: {statistics.median(loops):.2f} % of distance ({len(loops)} runs)")
    classes = {}
    for r in rows:
        platform = (r.get("sidecar") or {}).get("platform", "-")
        classes.setdefault(platform, []).append(r)
    for platform, group in classes.items():
        ok = [r for r in group if navigated(r)]
        cov = sum(1 for r in ok if r["result"]["covered"] == "yes")
        sources = sorted({r["sidecar"]["source"]["repo"] for r in group if r.get("sidecar")})
        med = statistics.median(pct_upper(r) for r in group)
        ratios = [r["result"]["distance_ratio"] for r in ok if r["result"].get("distance_ratio") is not None]
        ratio = (f"; ours / true distance median {statistics.median(ratios):.2f} ({min(ratios):.2f}-"
                 f"{max(ratios):.2f}, {len(ratios)} runs)" if ratios else "")
        tracks = [r["result"]["track_rms_pct"] for r in ok if r["result"].get("track_rms_pct") is not None]
        track = (f"; track error median {statistics.median(tracks):.2f} % ({len(tracks)} runs)"
                 if tracks else "")
        lines.append(f"{platform}: {len(ok)} of {len(group)} runs gave a position, {cov} covered; median % of "
                     f"distance (upper end; failed or unmeasured runs infinite): {fmt_pct(med)}; "
                     f"{len(sources)} source{'s' if len(sources) != 1 else ''}{ratio}{track}")
    return lines


class Runner:
    """Runs `mems-odometry offline` on a recording with given extra arguments, once per
    (recording, arguments)."""

    def __init__(self, binary, calib, data, timeout, quiet):
        self.binary, self.calib, self.data, self.timeout, self.quiet = binary, calib, data, timeout, quiet
        self.cache = {}

    def row(self, rec, extra):
        key = (rec["id"], tuple(extra))
        if key in self.cache:
            return self.cache[key]
        row = {"id": rec["id"], "args": list(extra)}
        side_path = self.data / f"{rec['id']}.json"
        if not side_path.is_file():
            row["error"] = f"not converted: no {side_path} (run convert.py)"
            self.cache[key] = row
            return row
        side = json.loads(side_path.read_text())
        path = self.data / side.get("input", side.get("csv", ""))
        row["sidecar"] = side
        if not path.is_file():
            row["error"] = f"not converted: no {path} (run convert.py)"
            self.cache[key] = row
            return row
        out, err, cmd, stderr = run_one(self.binary, self.calib, path, extra, self.timeout)
        row["command"] = cmd
        row["stderr"] = stderr
        if err:
            row["error"] = err
        else:
            row["odometry"] = out
            row["result"] = evaluate(side, out)
        if not self.quiet:
            print(f"{rec['id']} {' '.join(extra)}: {'failed: ' + err if err else 'done'}", file=sys.stderr)
        self.cache[key] = row
        return row


def corpus_recordings(only, platform=None):
    """corpus.json's recordings, those with an id in `only` when it names any, and of
    `platform` when given."""
    corpus = json.loads((HERE / "corpus.json").read_text())
    return [r for r in corpus["recordings"]
            if (platform is None or r.get("platform") == platform) and (not only or r["id"] in only)]


def add_run_args(p):
    """The flags of every script that runs the corpus: the binary, the converted data, the
    recordings to run and JSON output."""
    p.add_argument("--bin", default=str(REPO / "target" / "release" / "mems-odometry"), help="mems-odometry binary")
    p.add_argument("--data", default=os.environ.get("MEMS_REAL_DATA", "/work/real-data"), help="converted data (default $MEMS_REAL_DATA or /work/real-data)")
    p.add_argument("--only", action="append", metavar="ID", help="run only this recording (repeatable)")
    p.add_argument("--json", action="store_true", help="print one JSON document instead of the table")


@contextlib.contextmanager
def plain_and_changed(binary, data):
    """Yields (plain, changed, directory): two quiet runners under the identity calibration,
    one on the converted recordings in `data`, one on `directory`, a temporary directory where
    the caller writes changed copies of them (`copy_sidecar` puts each one's sidecar there)."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        calib = tmp / "identity.toml"
        calib.write_text(identity_calibration())
        changed = tmp / "changed"
        changed.mkdir()
        yield (Runner(Path(binary), calib, Path(data), 900.0, quiet=True),
               Runner(Path(binary), calib, changed, 900.0, quiet=True), changed)


def copy_sidecar(data, changed, rec):
    """Copies `rec`'s sidecar from `data` into `changed`; returns its recording's file name."""
    side = json.loads((Path(data) / f"{rec['id']}.json").read_text())
    (Path(changed) / f"{rec['id']}.json").write_text(json.dumps(side))
    return side.get("input", side["csv"])


def rewrite_csv(src, dst, header, row):
    """Copies the canonical CSV `src` to `dst` (changed copies of a converted recording):
    comment and blank lines as they are, the header line's cells as `header(cells, line)`
    returns them (`line`: its 1-based number, for errors) and each sample line's as `row(cells)`
    returns them."""
    with open(src) as fin, open(dst, "w") as fout:
        seen_header = False
        for n, line in enumerate(fin, 1):
            if line.startswith("#") or not line.strip():
                fout.write(line)
                continue
            cells = line.rstrip("\n").split(",")
            cells = row(cells) if seen_header else header(cells, n)
            seen_header = True
            fout.write(",".join(cells) + "\n")


MAX_GRID = 24


def tuning_args(params, combo):
    """The flags of one candidate: a flag whose value is its default (what the binary uses
    without it) is left out, so that the defaults' runs are the plain bench's."""
    args = []
    for param, value in zip(params, combo):
        if value != param["default"]:
            args += [param["flag"], str(value)]
    return args


def candidates(params, score):
    """Candidate combinations of `params` to search with `score` (lower is better): the joint
    grid when small, else one flag at a time from the defaults (each flag's best value kept
    before the next flag is searched). Returns (best combo, combos tried)."""
    defaults = tuple(p["default"] for p in params)
    size = 1
    for p in params:
        size *= len(p["candidates"])
    if size <= MAX_GRID:
        grid = list(itertools.product(*(p["candidates"] for p in params)))
        # Ties go to the defaults, then to the earlier candidate.
        best = min(grid, key=lambda c: (score(c), c != defaults))
        return best, len(grid)
    best, tried = list(defaults), 0
    for i, p in enumerate(params):
        trial = []
        for v in p["candidates"]:
            combo = tuple(best[:i] + [v] + best[i + 1:])
            trial.append(combo)
            tried += 1
        best = list(min(trial, key=lambda c: (score(c), c[i] != defaults[i])))
    return tuple(best), tried


def held_out_groups(group, corpus):
    """The class's recordings by held-out group, each labelled by its corpus.json sources
    joined with '+'. A source's group is its `holdout` key where it has one, else its
    repository: sources from one repository come from one data set and are held out together,
    unless corpus.json says why they are independent enough to be held out apart."""
    groups = {}
    for rec in group:
        src = corpus["sources"][rec["source"]]
        groups.setdefault(src.get("holdout", src["repo"]), []).append(rec)
    return [("+".join(dict.fromkeys(r["source"] for r in recs)), recs) for recs in groups.values()]


def loso(corpus, runner, only):
    """The leave-one-source-out report (see the module docstring): per class, the in-sample
    candidate and median, the per-source held-out candidates and runs, the LOSO median."""
    tuning = corpus.get("tuning", {}).get("parameters", [])
    recs = [r for r in corpus["recordings"] if not only or r["id"] in only]
    classes = {}
    for rec in recs:
        classes.setdefault(rec["platform"], []).append(rec)
    report = []
    for platform, group in classes.items():
        # Each flag's default for this class: its profile's own where it differs.
        params = [dict(p, default=p.get("class_defaults", {}).get(platform, p["default"]))
                  for p in tuning if platform in p["classes"]]

        def args_for(rec, combo):
            return list(rec.get("extra_args", [])) + tuning_args(params, combo)

        def score(subset, combo):
            return statistics.median(pct_upper(runner.row(r, args_for(r, combo))) for r in subset)

        defaults = tuple(p["default"] for p in params)
        if params:
            best_all, tried = candidates(params, lambda c: score(group, c))
        else:
            best_all, tried = defaults, 1
        in_sample = {r["id"]: pct_upper(runner.row(r, args_for(r, best_all))) for r in group}
        sources = []
        for source, mine in held_out_groups(group, corpus):
            others = [r for r in group if r not in mine]
            if params and others:
                choice, _ = candidates(params, lambda c: score(others, c))
                how = "chosen on the other sources"
            else:
                choice = defaults
                how = "no other source in the class: the defaults" if params else "no tuned flag applies"
            held = {r["id"]: pct_upper(runner.row(r, args_for(r, choice))) for r in mine}
            sources.append({"source": source, "choice": dict(zip((p["flag"] for p in params), choice)),
                            "how": how, "runs": held})
        held_out = {k: v for s in sources for k, v in s["runs"].items()}
        med_in = statistics.median(in_sample.values())
        med_out = statistics.median(held_out.values())
        report.append({
            "platform": platform,
            "flags": [p["flag"] for p in params],
            "candidates_per_search": tried,
            "in_sample_choice": dict(zip((p["flag"] for p in params), best_all)),
            "in_sample": in_sample,
            "in_sample_median": med_in,
            "sources": sources,
            "loso_median": med_out,
            "ratio": (med_out / med_in) if med_in not in (0, math.inf) and med_out != math.inf else None,
            "recordings": len(group),
        })
    return report


def loso_tables(report, runs):
    head = ["platform", "recordings", "sources", "flags searched", "in-sample choice", "in-sample median",
            "LOSO median", "LOSO / in-sample"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for c in report:
        choice = ", ".join(f"{k} {v}" for k, v in c["in_sample_choice"].items()) or "-"
        ratio = f"{c['ratio']:.2f}" if c["ratio"] is not None else "-"
        out.append("| " + " | ".join([c["platform"], str(c["recordings"]), str(len(c["sources"])),
                                      ", ".join(c["flags"]) or "-", choice, fmt_pct(c["in_sample_median"]),
                                      fmt_pct(c["loso_median"]), ratio]) + " |")
    out += ["", "| platform | held-out source | its choice | how | its runs (% of distance, upper end) |",
            "|---|---|---|---|---|"]
    for c in report:
        for s in c["sources"]:
            choice = ", ".join(f"{k} {v}" for k, v in s["choice"].items()) or "-"
            held = ", ".join(f"{k} {fmt_pct(v)}" for k, v in s["runs"].items())
            out.append(f"| {c['platform']} | {s['source']} | {choice} | {s['how']} | {held} |")
    out += ["", f"runs of mems-odometry offline: {runs}"]
    return "\n".join(out)


def finite(value):
    """`value` with every infinite float (a failed run's % of distance) as null: valid JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite(v) for v in value]
    return value


def self_test():
    """The track's turn into our frame on made-up tracks: ours is the truth turned by a known
    yaw (about our alignment's pose, with our track sampled at other times than the truth's),
    plus a slow heading drift of ours; the turn found over the first ALIGN_PATH_M must be the
    known yaw, and the end error the drift's alone."""
    yaw = math.radians(130.0)

    def truth_xy(t):
        # 1 m/s east, then a left arc: a path, not a line.
        return (t, 0.0) if t < 20 else (20 + 10 * math.sin((t - 20) / 10), 10 - 10 * math.cos((t - 20) / 10))

    t0 = 2.0
    truth = {"track": [[0.1 * k, *truth_xy(0.1 * k)] for k in range(600)], "track_min_step_m": 0.1}
    drift = math.radians(0.05)  # ours turns 0.05 deg per s on top

    def ours_at(t):
        x, y = truth_xy(t)
        x0, y0 = truth_xy(t0)
        a = yaw + drift * (t - t0)
        c, s_ = math.cos(a), math.sin(a)
        return [c * (x - x0) - s_ * (y - y0), s_ * (x - x0) + c * (y - y0)]

    ours = [[t0 + 0.1 * k + 0.03, *ours_at(t0 + 0.1 * k + 0.03), 0.0] for k in range(575)]
    got = track_heading(truth, ours, t0, ALIGN_PATH_M)
    assert abs(math.degrees(got - yaw)) < 0.5, math.degrees(got)
    out = {"track": ours, "aligned_at_s": t0, "end_displacement_m": ours[-1][1:3] + [0.0],
           "sigma_m": [1.0, 1.0, 1.0]}
    row = evaluate({"truth": truth}, out)
    lo, hi = row["error_m"]
    assert lo == hi, row["error_m"]
    # The drift's share: the end turned by drift * (t_end - t0 - the stretch's mean time) about
    # the start; bounded above by turning it by the whole drift.
    end = math.dist(truth_xy(59.9), truth_xy(t0))
    assert 0.0 < hi < end * drift * (59.9 - t0), (hi, end)
    assert track_heading(truth, ours[:50], t0, ALIGN_PATH_M) is None, "ours ends before 10 m"
    # The track error: each of our poses is the truth's turned about the start by the drift
    # accumulated since t0 less what the found yaw took, so it lies a chord away from it.
    chords = []
    for t, *_ in ours:
        if t < 59.9:
            r = math.dist(truth_xy(t), truth_xy(t0))
            chords.append(2 * r * math.sin(abs(yaw + drift * (t - t0) - got) / 2))
    expected = math.sqrt(sum(c * c for c in chords) / len(chords))
    assert abs(row["track_rms_m"] - expected) < 1e-3 * expected + 1e-3, (row["track_rms_m"], expected)
    print("bench.py self-test: ok (track turned into our frame, track error)")


def main():
    if "--self-test" in sys.argv[1:]:
        self_test()
        return
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_args(p)
    p.add_argument("--calib", help="calibration TOML for every run (default: an identity calibration written to a temporary file)")
    p.add_argument("--timeout", type=float, default=900.0, help="per-run limit, s")
    p.add_argument("--self-test", action="store_true", help="check the track's turn into our frame on made-up tracks (no data) and exit")
    p.add_argument("--loso", action="store_true", help="also tune corpus.json's `tuning` flags per platform class, in sample and leaving each source out, and print both")
    args = p.parse_args()

    binary = Path(args.bin)
    if not binary.is_file():
        sys.exit(f"bench.py: {binary}: no such binary (build it: cargo build --release -p odometry)")
    corpus = json.loads((HERE / "corpus.json").read_text())
    data = Path(args.data)
    with tempfile.TemporaryDirectory() as tmp:
        calib = Path(args.calib) if args.calib else Path(tmp) / "identity.toml"
        if not args.calib:
            calib.write_text(identity_calibration())
        runner = Runner(binary, calib, data, args.timeout, quiet=args.json)
        rows = []
        for rec in corpus["recordings"]:
            if args.only and rec["id"] not in args.only:
                continue
            rows.append(runner.row(rec, list(rec.get("extra_args", []))))
        report = loso(corpus, runner, args.only) if args.loso else None
    if args.json:
        doc = {"rows": rows, "summary": summary(rows)}
        if report is not None:
            doc["loso"] = report
            doc["runs"] = len(runner.cache)
        json.dump(finite(doc), sys.stdout, indent=1)
        print()
    else:
        print(table(rows))
        print()
        for line in summary(rows):
            print(line)
        if report is not None:
            print()
            print(loso_tables(report, len(runner.cache)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
