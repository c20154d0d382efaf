"""docs/detectors.md's short-rest table: simulated stop-and-go robots, cars stopping on slopes,
a slow cruise and an arm with short pauses, through `mems-sim` and `mems-odometry offline`
with its defaults (the arm also with the pedestrian profile)."""

import csv
import json

from common import Failed, Section, table

B = "target/release/"
TMP = "/tmp/figures-short-rests"

# (scenario, mems-sim drive arguments); each is run at the seeds of SEEDS.
SCENARIOS = [
    (
        "stop-and-go robot: rests 1-2 s, first rest 1 s, 0.2-0.5 m/s, 200 Hz",
        ["--duration", "120", "--initial-rest", "1", "--rests", "1,2", "--legs", "2,4", "--max-motion", "10", "--cruise", "0.2,0.5", "--rate", "200"],
    ),
] + [
    (
        f"the same robot vibrating while its wheels turn (`--vibration-floor 0.3,1`), {rate} Hz",
        ["--duration", "120", "--initial-rest", "1", "--rests", "1,2", "--legs", "2,4", "--max-motion", "10", "--cruise", "0.2,0.5", "--vibration-floor", "0.3,1", "--rate", rate],
    )
    # 62.5 Hz: the simulated part samples at 1 kHz behind its low-pass filter and outputs
    # 1000/n Hz, the nearest to a 64 Hz part.
    for rate in ("200", "100", "62.5", "40")
] + [
    (
        "car, stops of 3-6 s on slopes up to 5 deg, turns, 1-3 m/s, 100 Hz",
        ["--duration", "240", "--initial-rest", "2", "--rests", "3,6", "--legs", "5,10", "--max-motion", "45", "--cruise", "1,3", "--max-slope-deg", "5", "--turns", "on", "--rate", "100"],
    ),
    (
        "the same car on a level road",
        ["--duration", "240", "--initial-rest", "2", "--rests", "3,6", "--legs", "5,10", "--max-motion", "45", "--cruise", "1,3", "--turns", "on", "--rate", "100"],
    ),
    (
        "robot cruising at 0.08 m/s for 20-30 s between rests of 2-3 s, 200 Hz, vibration scaled with speed only",
        ["--duration", "120", "--initial-rest", "2", "--rests", "2,3", "--legs", "20,30", "--max-motion", "40", "--cruise", "0.08,0.08", "--rate", "200"],
    ),
    (
        "the same robot with a vibration floor of 0.3 m/s^2 and 1 deg/s per axis while its wheels turn",
        ["--duration", "120", "--initial-rest", "2", "--rests", "2,3", "--legs", "20,30", "--max-motion", "40", "--cruise", "0.08,0.08", "--vibration-floor", "0.3,1", "--rate", "200"],
    ),
]

# An arm (mems-sim arm: 1.6 s of rest, then 12 moves of 0.8-2 s between waypoints of a 0.5 m
# workspace, turns up to 90 deg, back to the start), with the profile it runs under.
ARM = ["arm", "--moves", "12", "--pauses", "0.3,0.3", "--rate", "200"]
ARMS = [
    ("arm, pauses of 0.3 s, default profile", ARM, []),
    ("arm, pauses of 0.3 s, `--profile pedestrian`", ARM, ["--profile", "pedestrian"]),
]

SEEDS = [1, 2, 3]

HEADER = [
    "scenario",
    "seed",
    "aligned at (s)",
    "distance (m)",
    "end error (m)",
    "% of distance",
    "1-sigma per axis (m)",
    "stops",
    "stops with a rest counted",
    "steady but vibrating (s)",
]


def truth_stops(path):
    """(start, end) s of the truth's rests after the first, from a mems-sim CSV."""
    stops, start, t = [], None, 0.0
    with open(path, newline="") as f:
        for row in csv.DictReader(line for line in f if not line.startswith("#")):
            t = float(row["t_s"])
            rest = row["truth_rest"] in ("1", "true")
            if rest and start is None:
                start = t
            elif not rest and start is not None:
                stops.append((start, t))
                start = None
    if start is not None:
        stops.append((start, t))
    return stops[1:]


def row(ctx, name, args, seed, offline=()):
    """One scenario at one seed (`args`: mems-sim's, `drive` unless they name a scenario;
    `offline`: mems-odometry offline's extra flags): its table row."""
    path = f"{TMP}/drive.csv"
    sim = args if args[0] == "arm" else ["drive"] + args
    ctx.run([B + "mems-sim"] + sim + ["--seed", str(seed), "--out", path, "--force"])
    try:
        out, _ = ctx.run([B + "mems-odometry", "offline", "--input", path, "--json"] + list(offline))
    except Failed:
        return [name, seed, "never"] + ["-"] * 7
    if ctx.dry:
        return None
    try:
        r = json.loads(out.strip().splitlines()[-1])
    except (json.JSONDecodeError, IndexError):
        raise Failed("mems-odometry offline --json: no JSON result")
    e, s, dist = r["truth_error_m"], r["sigma_m"], r["truth_distance_m"]
    error = (e[0] ** 2 + e[1] ** 2) ** 0.5
    sigma = ((s[0] ** 2 + s[1] ** 2) / 2) ** 0.5
    starts = [x["t_s"] for x in r["rests"]]
    # A rest counts for a stop when it starts in it or in the 5 s of braking before it.
    stops = truth_stops(path)
    counted = sum(any(a - 5.0 <= t <= b for t in starts) for a, b in stops)
    return [name, seed, f"{r['aligned_at_s']:.2f}", f"{dist:.1f}", f"{error:.3f}", f"{100 * error / dist:.2f}", f"{sigma:.3f}", len(stops), counted, f"{r['steady_vibrating_s']:.1f}"]


def short_rests(ctx):
    """The table: every scenario at every seed (one seed in a quick run)."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "mems-sim", "-p", "odometry"])
    ctx.run(["rm", "-rf", TMP])  # a fresh private directory: no stale or planted files
    ctx.run(["mkdir", "-m", "700", TMP])
    seeds = SEEDS[:1] if ctx.quick else SEEDS
    rows = [row(ctx, name, args, seed) for name, args in SCENARIOS for seed in seeds]
    rows += [row(ctx, name, args, seed, extra) for name, args, extra in ARMS for seed in seeds]
    ctx.run(["rm", "-rf", TMP])
    if ctx.dry:
        return {}
    return {"detectors-short-rests": table(HEADER, rows)}


def wheeled_vibration(ctx):
    """The corpus's wheeled robots' vibration standing, creeping and driving (the simulator's
    vibration floor stands on it)."""
    out, _ = ctx.run(["python3", "tools/real-data/vibration.py"])
    if ctx.dry:
        return {}
    return {"detectors-wheeled-vibration": out.strip()}


SECTIONS = [
    Section("short-rests", "detectors.md", ["detectors-short-rests"], "2 min", short_rests),
    Section("wheeled-vibration", "detectors.md", ["detectors-wheeled-vibration"], "10 s", wheeled_vibration),
]
