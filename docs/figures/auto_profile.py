"""Sections of `--profile auto` (docs/real-data.md) and of the wheeled profile's IMU-only
non-holonomic constraint on simulated drives (docs/odometry.md)."""

import json

from common import Failed, Section, table

TMP = "/tmp/figures-platform"
BIN = "target/release/"


def fresh(ctx):
    """A fresh private directory for the simulated recordings: no stale or planted files."""
    ctx.run(["rm", "-rf", TMP])
    ctx.run(["mkdir", "-m", "700", TMP])


def result(out, what):
    """The JSON result of `mems-odometry offline --json`."""
    try:
        return json.loads(out.strip().splitlines()[-1])
    except (json.JSONDecodeError, IndexError):
        raise Failed(f"{what}: no JSON result")


def features_row(name, truth, r):
    """A table row: what the recording is, what auto found over the whole recording and the
    figures it found it on, the profile the run used and how it was chosen."""
    p = r["profile"]
    f = p.get("platform") or {}
    live = p.get("live_rule_platform")
    how = p["chosen_by"].replace("auto: ", "")
    if live:
        how += f" ({live['platform']}, at {p['decided_at_s']:.0f} s)"
    return [
        name,
        truth,
        f.get("platform", "-"),
        f"{f.get('moving_s', 0):.0f}",
        f"{f.get('tilt_rate_dps', 0):.1f}",
        f"{f.get('principal_share', 0):.2f}",
        f"{f.get('principal_axis_deg', 0):.0f}",
        f"{f.get('impacts_per_min', 0):.1f}",
        f"{f.get('gait_steps_per_min', 0):.0f}",
        f"{f.get('still_share', 0):.2f}",
        p["profile"],
        how,
    ]


HEADER = ["recording", "class", "whole recording", "moving s", "tilt rate deg/s", "principal share", "axis from gravity deg", "impacts/min", "gait steps/min", "still share", "profile used", "chosen"]
# The profiles a class's recordings should get: a hand-held sensor is walked by a pedestrian
# (walking) or moved by hand (other), which the corpus's class does not tell apart.
PROFILES_OF_CLASS = {"foot": {"pedestrian"}, "wheeled": {"vehicle"}, "vehicle": {"vehicle"}, "handheld": {"other", "walking"}, "arm": {"other"}, "other": {"other"}, "walking": {"walking"}}
PROFILE_OF_PLATFORM = {"foot": "pedestrian", "wheeled": "vehicle", "other": "other", "walking": "walking", "-": "-"}


def auto(ctx):
    """docs/real-data.md: what `--profile auto` picks on every corpus recording (the bench's
    JSON, no profile flag) and on simulated walks, drives and arm-like paths."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "odometry", "-p", "mems-sim"])
    only = ["--only", "xio-short-walk", "--only", "wid-car-10", "--only", "broad-11-slow"] if ctx.quick else []
    bench, _ = ctx.run(["python3", "tools/real-data/bench.py", "--json"] + only)
    fresh(ctx)
    seeds = [1] if ctx.quick else [1, 2, 3]
    sims = {
        "walk": (["walk", "--laps", "1"], "foot"),
        "drive": (["drive", "--duration", "300", "--turns", "on"], "wheeled"),
        "arm": (["orientations", "--n", "12", "--hold", "6"], "other"),
        "hand-held walk": (["handheld", "--laps", "2"], "walking"),
    }
    outs = []
    for seed in seeds:
        for name, (args, truth) in sims.items():
            path = f"{TMP}/{name.replace(' ', '-')}-{seed}.mcap"
            ctx.run([BIN + "mems-sim", *args, "--rate", "200", "--seed", str(seed), "--out", path])
            out, _ = ctx.run([BIN + "mems-odometry", "offline", "--input", path, "--json"])
            outs.append((f"simulated {name}, seed {seed}", truth, out))
    if ctx.dry:
        return {}
    rows, failed = [], []
    for r in json.loads(bench)["rows"]:
        # A run that gave no position (the bench's table shows its error) has no record of
        # what the profile chose: it is named below the table, not counted.
        if r.get("odometry") is None:
            failed.append(r["id"])
            continue
        rows.append(features_row(r["id"], r["sidecar"]["platform"], r["odometry"]))
    rows += [features_row(name, truth, result(out, name)) for name, truth, out in outs]
    whole = sum(1 for r in rows if PROFILE_OF_PLATFORM[r[2]] in PROFILES_OF_CLASS[r[1]])
    used = sum(1 for r in rows if r[10] in PROFILES_OF_CLASS[r[1]])
    counts = f"The whole recording recognized as its class: {whole} of {len(rows)}; the profile used is its class's: {used} of {len(rows)}."
    if failed:
        counts += f" No position, so not counted (the bench's table gives why): {', '.join(failed)}."
    return {"platform-auto": table(HEADER, rows) + "\n\n" + counts}


def wheeled(ctx):
    """docs/odometry.md: simulated drives without hints, the wheeled profile (the IMU-only
    non-holonomic constraint) against the profile without it, and the continuous drive of
    odometry/tests/wheeled_without_hints.rs."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "odometry", "-p", "mems-sim"])
    fresh(ctx)
    seeds = [1] if ctx.quick else [1, 2, 3, 4, 5]
    duration = "120" if ctx.quick else "600"
    runs = []
    for seed in seeds:
        path = f"{TMP}/drive-{seed}.mcap"
        ctx.run([BIN + "mems-sim", "drive", "--duration", duration, "--turns", "on", "--rate", "200", "--seed", str(seed), "--out", path])
        for profile in ["vehicle", "other"]:
            out, _ = ctx.run([BIN + "mems-odometry", "offline", "--input", path, "--json", "--profile", profile])
            runs.append((seed, profile, out))
    test, test_err = ctx.run(["cargo", "test", "--release", "-q", "-p", "odometry", "--test", "wheeled_without_hints", "--", "--nocapture"])
    if ctx.dry:
        return {}
    rows = []
    for seed, profile, out in runs:
        r = result(out, f"seed {seed} {profile}")
        e, s, d = r["truth_error_m"], r["sigma_m"], r["truth_distance_m"]
        err = (e[0] ** 2 + e[1] ** 2) ** 0.5
        sig = ((s[0] ** 2 + s[1] ** 2) / 2) ** 0.5
        covered = "yes" if err <= 1.515 * sig else "no"
        rows.append([seed, profile, f"{d:.0f}", f"{err:.2f}", f"{100 * err / d:.2f} %", f"{sig:.2f}", covered])
    lines = [l.strip() for l in (test + test_err).splitlines() if l.startswith("continuous drive:")]
    if not lines:
        raise Failed("wheeled_without_hints: no `continuous drive:` line")
    header = ["seed", "profile", "distance m", "end error m", "% of distance", "1-sigma m (per axis)", "covered (r68)"]
    return {"wheeled-sim": table(header, rows) + "\n\n    " + "\n    ".join(lines)}


SECTIONS = [
    Section("platform", "real-data.md", ["platform-auto"], "6 min", auto),
    Section("wheeled-sim", "odometry.md", ["wheeled-sim"], "5 min", wheeled),
]
