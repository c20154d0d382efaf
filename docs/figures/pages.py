"""Sections of the pages other than docs/odometry.md and docs/hints.md."""

import json
import os
import re

from common import Failed, Section, number, one_table, table, tables

SHARED = "../shared/data/capstone"


def markdown(out, what, drop=(), edit=lambda line: line):
    """A command's markdown output as a region body: its tables and text, headings made bold
    (a region sits inside a page's own headings), JSON lines and tables whose first header cell
    is in `drop` left out."""
    kept, skipping = [], False
    for line in out.splitlines():
        if line.startswith("{"):
            continue
        if line.startswith("|"):
            if not skipping and kept and not kept[-1].startswith("|"):
                skipping = line.strip("| ").split("|")[0].strip() in drop
            if not skipping:
                kept.append(line)
            continue
        skipping = False
        line = edit(line)
        m = re.match(r"#+ (.*)", line)
        kept.append(f"**{m.group(1)}**" if m else line)
    text = re.sub(r"\n{3,}", "\n\n", "\n".join(kept)).strip()
    if "|" not in text:
        raise Failed(f"{what}: no table in its output")
    return text


def detectors(ctx):
    """docs/detectors.md: the detectors on labelled drives, at 1 kHz and at 4 kHz without gyro."""
    seeds = 1 if ctx.quick else 10
    ctx.region = "detectors-1khz"
    out, _ = ctx.cargo_example("calibrate", "detectors", ["--seeds", seeds, "--vibration", "1,0"])
    ctx.region = "detectors-4khz"
    out4, _ = ctx.cargo_example("calibrate", "detectors", ["--rate", 4000, "--no-gyro", "--seeds", seeds, "--vibration", "1,0"])
    if ctx.dry:
        return {}
    return {"detectors-1khz": table(*one_table(out, "detectors")), "detectors-4khz": table(*one_table(out4, "detectors --rate 4000"))}


def real_data(ctx):
    """docs/real-data.md: the real-data bench and its leave-one-source-out tables (one run of
    `bench.py --loso`, which prints the bench's table first)."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "odometry"])
    only = ["--only", "xio-short-walk", "--only", "gdin-34"] if ctx.quick else []
    out, _ = ctx.run(["python3", "tools/real-data/bench.py", "--loso"] + only)
    if ctx.dry:
        return {}
    lines = out.splitlines()
    starts = [i for i, l in enumerate(lines) if l.startswith("|") and (i == 0 or not lines[i - 1].startswith("|"))]
    if len(starts) < 2:
        raise Failed("bench.py --loso: expected the results table and the leave-one-source-out tables")
    bench = "\n".join(lines[starts[0] : starts[1]]).strip().splitlines()
    rows = [l for l in bench if l.startswith("|")]
    summary = ["    " + l for l in bench if l.strip() and not l.startswith("|")]
    loso = "\n".join(lines[starts[1] :])
    return {
        "real-data-bench": "\n".join(rows) + "\n\n" + "\n".join(summary),
        "real-data-loso": markdown(loso, "bench.py --loso"),
    }


def latency(ctx):
    """docs/latency.md: the live pipeline's latency, CPU and throughput, and the bridge."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "mems-replay", "-p", "mems-sim", "-p", "calibrate",
             "-p", "calibrate-science", "-p", "odometry"])
    ctx.region = "latency"
    args = ["--seconds", 1, "--cpu-seconds", 3] if ctx.quick else ["--seconds", 5]
    out, _ = ctx.cargo_example("mems-replay", "latency", args + ["--json"])
    ctx.region = "latency-bridge"
    ctx.run(["cargo", "build", "--release", "-q", "-p", "mems-bridge"])
    bridge, _ = ctx.cargo_example("mems-bridge", "loopback", ["--seconds", 3 if ctx.quick else 60, "--rate", 1000])
    if ctx.dry:
        return {}
    last = out.strip().splitlines()[-1]
    try:
        headline = json.loads(last)
    except json.JSONDecodeError:
        raise Failed("latency --json: the last line is not JSON")
    keys = ["bare_chain3_p99_us", "pipeline_p99_us", "pinned_pipeline_p99_us", "idle_under_1_percent", "stages_1khz_under_10_percent"]
    head = table(["figure", "value"], [[k, headline.get(k, "-")] for k in keys])
    body = markdown(out, "latency", drop=("published ns",), edit=latency_line)
    return {"latency": head + "\n\n" + body, "latency-bridge": "\n".join("    " + l for l in bridge.strip().splitlines())}


def latency_line(line):
    """A latency text line without its run's process ids and clock readings."""
    m = re.match(r"Live states arrived from .*?\. (CPU over .*)", line)
    if m:
        return m.group(1)
    return re.sub(r"; the first \d+ \(publish time CLOCK_MONOTONIC ns; hops in us\):", ".", line)


def allan_json(ctx, path):
    """`mems-calibrate-offline allan --json` of one thesis file, as a dict."""
    out, _ = ctx.run(["target/release/mems-calibrate-offline", "allan", "--gravity", "9.797", "--json", "--input", path])
    if ctx.dry:
        return None
    try:
        return json.loads(out)
    except json.JSONDecodeError:
        raise Failed(f"allan --json {path}: not JSON")


def sampling_row(name, r):
    """A row of the sampling and repair table from an allan report."""
    t = r["timing"]
    torn = r.get("torn") or {}
    repaired = ", ".join(str(a["repaired"]) for a in torn.get("accel", [])) or "-"
    return [
        name,
        r["samples"],
        f"{1e3 * t['mean_interval_s']:.3f} / {1e3 * t['median_interval_s']:.3f} ms",
        f"{t['gaps']} (longest {1e3 * t['longest_interval_s']:.0f} ms)",
        t["splits"],
        r["repeats"]["repeats"],
        repaired,
    ]


def noise(ctx):
    """docs/noise.md: the thesis's static recordings, the Monte Carlo check, the Allan bench."""
    ctx.region = "noise-sampling"
    ctx.run(["cargo", "build", "--release", "-q", "-p", "calibrate-science", "--bin", "mems-calibrate-offline"])
    six = SHARED + "/Six-Position-Test/data/trial_{0}/six_position_test_data_{0}.csv"
    runs = SHARED + "/Preliminary-Tests/Start-Up-Shut-Down/Data/start_up_data_{}.csv"
    rows, split_runs = [], []
    for t in (1, 2, 3):
        r = allan_json(ctx, six.format(t))
        if r:
            rows.append(sampling_row(f"trial {t}", r))
    for k in range(1, 3 if ctx.quick else 61):
        r = allan_json(ctx, runs.format(k))
        if r and r["timing"]["splits"]:
            split_runs.append(f"run {k} ({r['timing']['splits']} split, longest interval {r['timing']['longest_interval_s']:.2f} s)")
    allan = "target/release/mems-calibrate-offline allan --gravity 9.797 --json --input"
    ctx.shown["noise-sampling"] = ctx.shown["noise-sampling"][:1] + [
        f"for t in 1 2 3; do {allan} {six.format('$t')}; done",
        f"for k in $(seq 60); do {allan} {runs.format('$k')}; done",
    ]
    ctx.region = "noise-thesis"
    out, _ = ctx.cargo_example("noise", "thesis_noise", [SHARED, "/tmp/figures-noise-pooled.png"])
    ctx.region = "noise-monte-carlo"
    mc, mc_err = ctx.run(["cargo", "test", "--release", "-q", "-p", "noise", "--test", "monte_carlo", "--", "--nocapture"])
    ctx.region = "noise-allan-bench"
    bench, _ = ctx.run(["cargo", "bench", "-q", "-p", "noise", "--bench", "allan"])
    if ctx.dry:
        return {}
    mc_lines = [l for l in (mc + mc_err).splitlines() if re.search(r"within|cover|resolved", l)]
    if not mc_lines:
        raise Failed("monte_carlo: no coverage lines in its output")
    bench_lines = [l for l in bench.splitlines() if l.strip() and not l.startswith("test ")]
    header = ["file", "samples", "mean / median interval", "gaps (>2x)", "splits (>10x)", "repeats", "torn reads repaired x, y, z"]
    sampling = table(header, rows) + "\n\nStart-up runs split by a gap: " + ("; ".join(split_runs) or "none") + "."
    return {
        "noise-sampling": sampling,
        "noise-thesis": markdown(out, "thesis_noise"),
        "noise-monte-carlo": "\n".join("    " + l for l in mc_lines),
        "noise-allan-bench": "\n".join("    " + l for l in bench_lines),
    }


SECTIONS = [
    Section("detectors", "detectors.md", ["detectors-1khz", "detectors-4khz"], "10 min", detectors),
    Section("real-data", "real-data.md", ["real-data-bench", "real-data-loso"], "3 min", real_data),
    Section("latency", "latency.md", ["latency", "latency-bridge"], "10 min", latency),
    Section("noise", "noise.md", ["noise-sampling", "noise-thesis", "noise-monte-carlo", "noise-allan-bench"], "2 min", noise),
]


def datasheet_drive(ctx):
    """docs/detectors.md: the datasheet-level part's 10-minute drive through the live stages'
    defaults, calibrated as `mems-stack` calibrates it, with white samples."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "mems-sim", "-p", "calibrate", "-p", "odometry"])
    tmp = "/tmp/figures-datasheet-drive"
    b = "target/release/"
    duration = "120" if ctx.quick else "600"
    ctx.run(["rm", "-rf", tmp])  # a fresh private directory: no stale or planted files
    ctx.run(["mkdir", "-m", "700", tmp])
    ctx.run([b + "mems-sim", "six-position", "--preset", "datasheet", "--seed", "1001", "--rate", "200", "--dlpf", "off", "--out", f"{tmp}/six.csv"])
    ctx.run([b + "mems-calibrate", "fit", "--input", f"{tmp}/six.csv", "--model", "full", "--out", f"{tmp}/cal.toml"])
    ctx.run([b + "mems-sim", "orientations", "--n", "16", "--preset", "datasheet", "--seed", "2001", "--rate", "200", "--dlpf", "off", "--out", f"{tmp}/ori.csv"])
    ctx.run([b + "mems-odometry", "gyrocal", "--input", f"{tmp}/ori.csv", "--calib", f"{tmp}/cal.toml", "--into", f"{tmp}/cal.toml"])
    ctx.run([b + "mems-sim", "drive", "--duration", duration, "--turns", "on", "--preset", "datasheet", "--rate", "200", "--seed", "1", "--dlpf", "off", "--out", f"{tmp}/drive.mcap"])
    out, _ = ctx.run([b + "mems-odometry", "offline", "--calib", f"{tmp}/cal.toml", "--input", f"{tmp}/drive.mcap", "--json"])
    if ctx.dry:
        return {}
    try:
        r = json.loads(out.strip().splitlines()[-1])
    except (json.JSONDecodeError, IndexError):
        raise Failed("mems-odometry offline --json: no JSON result")
    err, dist = r.get("truth_error_m"), r.get("truth_distance_m")
    if err is None or not dist:
        raise Failed("mems-odometry offline --json: no truth error (the drive carries its truth)")
    horizontal = (err[0] ** 2 + err[1] ** 2) ** 0.5
    rests = [x["t_s"] for x in r.get("rest_intervals") or []]
    rows = [
        ["distance (truth)", f"{dist:.1f} m"],
        ["end error, horizontal", f"{horizontal:.2f} m ({100 * horizontal / dist:.2f} % of distance)"],
        ["rests ended", len(rests)],
        ["the last rest ended at", f"{max(rests):.0f} s" if rests else "-"],
    ]
    return {"detectors-datasheet-drive": table(["figure", "value"], rows)}


SECTIONS.append(Section("detectors-drive", "detectors.md", ["detectors-datasheet-drive"], "2 min", datasheet_drive))


def offline_throughput(ctx):
    """docs/offline.md: one hour of a simulated drive at 1 kHz and at 4 kHz read, run through
    the stages and through `mems-odometry offline`, and read by the official Python reader."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "odometry", "-p", "mems-sim"])
    tmp = "/tmp/figures-offline"
    ctx.run(["rm", "-rf", tmp])  # a fresh private directory: no stale or planted files
    ctx.run(["mkdir", "-m", "700", tmp])
    duration = "60" if ctx.quick else "3600"
    blocks = []
    for rate in ([1000] if ctx.quick else [1000, 4000]):
        path = f"{tmp}/drive{rate // 1000}k.mcap"
        ctx.run(["target/release/mems-sim", "drive", "--duration", duration, "--turns", "on", "--rate", str(rate), "--out", path, "--force"])
        out, _ = ctx.cargo_example("odometry", "throughput", ["--input", path, "--python", "python3"])
        blocks.append("\n".join("    " + l for l in out.strip().splitlines()))
    ctx.run(["rm", "-rf", tmp])
    if ctx.dry:
        return {}
    return {"offline-throughput": "\n\n".join(blocks)}


SECTIONS.append(Section("offline", "offline.md", ["offline-throughput"], "20 min", offline_throughput))


def time_v(err, what):
    """Wall s, CPU s and peak RSS MB from `/usr/bin/time -v`'s stderr."""
    m = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (?:(\d+):)?(\d+):([0-9.]+)", err)
    if not m:
        raise Failed(f"{what}: no /usr/bin/time -v report")
    wall = 3600 * float(m.group(1) or 0) + 60 * float(m.group(2)) + float(m.group(3))
    cpu = number(r"User time \(seconds\): ([0-9.]+)", err, what) + number(r"System time \(seconds\): ([0-9.]+)", err, what)
    rss = number(r"Maximum resident set size \(kbytes\): (\d+)", err, what) / 1024
    return wall, cpu, rss


def recording_run(ctx):
    """docs/recording.md: a 60 s run of the full stack recorded, its size per layout and topic."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "mems-stack", "-p", "mems-record", "-p", "odometry", "-p", "calibrate",
             "-p", "acquire", "-p", "mems-info", "-p", "calibrate-science", "-p", "mems-sim"])
    tmp = "/tmp/figures-recording"
    run = f"{tmp}/run.mcap"
    ctx.run(["rm", "-rf", tmp])  # a fresh private directory: no stale or planted files
    ctx.run(["mkdir", "-m", "700", tmp])
    ctx.run(["target/release/mems-stack", "--duration", "10" if ctx.quick else "60", "--record", run, "--force", "--namespace", "figures-size"])
    info, _ = ctx.run(["target/release/mems-info", run, "--json"])
    ctx.run(["python3", "tools/recording/python/read_recording.py", run])
    ctx.region = "recording-layouts"
    cost, _ = ctx.cargo_example("recording", "encoding_cost", [run])
    ctx.run(["rm", "-rf", tmp])
    if ctx.dry:
        return {}
    i = json.loads(info)
    files = i.get("files") or []
    topics = i.get("topics") or {}
    revisions = sum(t.get("revisions", 0) for t in topics.values())
    size = table(
        ["recording", "bytes", "messages", "revisions"],
        [["`run.mcap` (protobuf, finished)", sum(f["bytes"] for f in files), sum(f["messages"] for f in files), revisions]],
    )
    found = tables(cost)
    if len(found) != 2:
        raise Failed("encoding_cost: expected the layout table and the topic table")
    return {"recording-size": size, "recording-layouts": table(*found[0]), "recording-topics": table(*found[1])}


def recording_drive(ctx):
    """docs/recording.md: the tour's 600 s, 1 kHz drive exported to ROS 2 and replayed."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "mems-sim", "-p", "odometry", "-p", "mems-ros2", "-p", "mems-replay", "-p", "calibrate"])
    tmp = "/tmp/figures-drive"
    b = "target/release/"
    ctx.run(["rm", "-rf", tmp])  # a fresh private directory: no stale or planted files
    ctx.run(["mkdir", "-m", "700", tmp])
    drive, states, bag = f"{tmp}/drive.mcap", f"{tmp}/states.mcap", f"{tmp}/states-ros2.mcap"
    calib, six, poses = f"{tmp}/calib.toml", f"{tmp}/six.csv", f"{tmp}/poses.csv"
    # The README tour's calibration of the simulated part, then its drive through offline.
    ctx.run([b + "mems-sim", "six-position", "--preset", "datasheet", "--rate", "1000", "--out", six])
    ctx.run([b + "mems-calibrate", "fit", "--input", six, "--model", "full", "--out", calib])
    ctx.run([b + "mems-sim", "orientations", "--n", "16", "--preset", "datasheet", "--out", poses])
    ctx.run([b + "mems-odometry", "gyrocal", "--input", poses, "--calib", calib, "--into", calib])
    ctx.run([b + "mems-sim", "drive", "--preset", "datasheet", "--duration", "60" if ctx.quick else "600", "--turns", "on", "--out", drive, "--force"])
    ctx.run([b + "mems-odometry", "offline", "--calib", calib, "--input", drive, "--out", states, "--force"])
    ctx.region = "recording-ros2-export"
    _, err = ctx.run(["/usr/bin/time", "-v", b + "mems-ros2", "export", states, "--out", bag, "--force"])
    sizes = {}
    if not ctx.dry:
        sizes = {p: os.path.getsize(p) for p in (drive, states, bag)}
    export = time_v(err, "mems-ros2 export") if not ctx.dry else None
    ctx.region = "recording-replay"
    _, err = ctx.run(["/usr/bin/time", "-v", b + "mems-replay", drive, "--max"])
    ctx.run(["rm", "-rf", tmp])
    if ctx.dry:
        return {}
    replay = time_v(err, "mems-replay --max")
    header = ["input", "input MB", "output MB", "wall s", "CPU s", "peak RSS MB"]
    return {
        "recording-ros2-export": table(header, [["states.mcap", f"{sizes[states] / 1e6:.1f}", f"{sizes[bag] / 1e6:.1f}"] + [f"{v:.1f}" for v in export]]),
        "recording-replay": table(["input", "input MB", "wall s", "CPU s", "peak RSS MB"], [["drive.mcap", f"{sizes[drive] / 1e6:.1f}"] + [f"{v:.2f}" for v in replay]]),
    }


SECTIONS.append(Section("recording-run", "recording.md", ["recording-size", "recording-layouts", "recording-topics"], "3 min", recording_run))
SECTIONS.append(Section("recording-drive", "recording.md", ["recording-ros2-export", "recording-replay"], "2 min", recording_drive))


FUZZ = re.compile(
    r"^(?P<reader>\w+): (?P<n>\d+) executions in (?P<wall>[0-9.]+) s \([0-9]+/s\): (?P<acc>\d+) accepted, "
    r"(?P<ref>\d+) refused with a named error, (?P<panics>\d+) panics, (?P<other>\d+) errors without the file; "
    r"largest allocation (?P<alloc>\d+) bytes",
    re.M,
)


def seconds(s):
    """A wall time for a table: whole seconds from 10 s up, else one decimal."""
    return f"{s:.0f} s" if s >= 10 else f"{s:.1f} s"


def fuzz(ctx):
    """docs/input-checks.md: a million mutated inputs per file reader (seed 1)."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "parser-fuzz"])
    runs = "2000" if ctx.quick else "1000000"
    out, err = ctx.run(["/usr/bin/time", "-v", "target/release/parser-fuzz", "--runs", runs, "--seed", "1"])
    if ctx.dry:
        return {}
    rows = [
        [m["reader"], f"{int(m['n']):,}", f"{int(m['acc']):,}", f"{int(m['ref']):,}", m["panics"], m["other"],
         f"{int(m['alloc']) / 1024:.0f} KiB", seconds(float(m["wall"]))]
        for m in FUZZ.finditer(out)
    ]
    if not rows:
        raise Failed("parser-fuzz: no campaign line")
    wall, cpu, rss = time_v(err, "parser-fuzz")
    header = ["reader", "inputs", "accepted", "refused, file named", "panics", "other failures", "largest allocation", "wall time"]
    return {"input-checks-fuzz": table(header, rows) + f"\n\nAll four readers: {cpu:.0f} s of CPU, peak resident memory {rss:.1f} MB."}


def offline_refusal(ctx):
    """docs/input-checks.md: `mems-odometry offline`'s refusal of a canonical CSV whose line
    1502 holds `ay_g` = 1e300."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "odometry", "-p", "mems-sim"])
    tmp = "/tmp/figures-bad"
    script = f"""
mkdir -p {tmp}
target/release/mems-sim drive --duration 20 --out {tmp}/good.csv --force > /dev/null
python3 -c '
import csv, sys
rows = list(csv.reader(open("{tmp}/good.csv")))
rows[1501][rows[0].index("ay_g")] = "1e300"
csv.writer(open("{tmp}/bad.csv", "w", newline=""), lineterminator="\\n").writerows(rows)'
cd {tmp}
status=0
$OLDPWD/target/release/mems-odometry offline --input bad.csv 2>&1 || status=$?
echo "exit status $status"
[ "$status" -ne 0 ]
"""
    out, _ = ctx.shell(script)
    ctx.run(["rm", "-rf", tmp])
    if ctx.dry:
        return {}
    return {"input-checks-offline": "\n".join("    " + l for l in out.strip().splitlines())}


SECTIONS.append(Section("input-checks-fuzz", "input-checks.md", ["input-checks-fuzz"], "8 min", fuzz))
SECTIONS.append(Section("input-checks-offline", "input-checks.md", ["input-checks-offline"], "10 s", offline_refusal))


def clipping(ctx):
    """docs/input-checks.md: the corpus's foot walks clipped at +-250 deg/s and at +-2 g
    (tools/real-data/perturb.py), unclipped, clipped and reconstructed at the rest, bridged
    only, integrated as measured; the reconstruction's prior against the truth of every
    clipped run (tools/real-data/clip_prior.py); and the walks with their true rates flagged
    clipped (tools/real-data/clip_oracle.py)."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "odometry"])
    only = ["--only", "xio-short-walk", "--only", "gdin-34"] if ctx.quick else []
    gyro, _ = ctx.run(["python3", "tools/real-data/perturb.py", "--gyro-dps", "250"] + only)
    accel, _ = ctx.run(["python3", "tools/real-data/perturb.py", "--accel-g", "2"] + only)
    prior, _ = ctx.run(["python3", "tools/real-data/clip_prior.py", "--gyro-dps", "250"])
    oracle, _ = ctx.run(["python3", "tools/real-data/clip_oracle.py", "--gyro-dps", "250"] + only)
    if ctx.dry:
        return {}
    tables = (gyro, accel, prior, oracle)
    return {"input-checks-clipping": "\n\n".join(t.strip() for t in tables)}


SECTIONS.append(Section("input-checks-clipping", "input-checks.md", ["input-checks-clipping"], "2 min", clipping))


def uncalibrated(ctx):
    """docs/real-data.md: every corpus recording with an uncalibrated accelerometer's errors
    added (tools/real-data/perturb.py: 4 % scale, 0.15 g bias on every axis), clean against
    perturbed."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "odometry"])
    only = ["--only", "xio-short-walk", "--only", "gdin-34"] if ctx.quick else []
    out, _ = ctx.run(["python3", "tools/real-data/perturb.py", "--accel-scale", "0.04",
                      "--accel-bias-g", "0.15"] + only)
    if ctx.dry:
        return {}
    return {"real-data-uncalibrated": out.strip()}


SECTIONS.append(Section("real-data-uncalibrated", "real-data.md", ["real-data-uncalibrated"], "4 min", uncalibrated))


def luck(ctx):
    """docs/real-data.md: every corpus row clean and with white noise far below its part's
    added, over five seeds (tools/real-data/luck.py): how much of each row is luck."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "odometry"])
    only = ["--only", "xio-short-walk", "--only", "gdin-34"] if ctx.quick else []
    out, _ = ctx.run(["python3", "tools/real-data/luck.py", "--seeds", "5"] + only)
    if ctx.dry:
        return {}
    return {"real-data-luck": out.strip()}


SECTIONS.append(Section("real-data-luck", "real-data.md", ["real-data-luck"], "2 min", luck))
