"""Sections of docs/odometry.md and docs/hints.md: simulated drives (`drive_eval`), the stage
bench and the fault benchmark."""

import re

import drive_eval as de
from common import Failed, one_table, table

DE = ["--dlpf-cfg", "off"]  # white samples
ST = ["--case", "straight", "--case", "turns"]
IMU = ["--rest", "imu"]

# (rest flags, rate, drive_eval arguments) per group of rows of the live table.
LIVE = [
    ("IMU (GLRT)", 200, ST + IMU),
    ("IMU (GLRT)", 1000, ST + IMU + ["--rate", 1000]),
    ("IMU (GLRT), DLPF 184 Hz", 200, ST + IMU + ["--dlpf-cfg", 1]),
    ("IMU (GLRT), DLPF 41 Hz", 200, ST + IMU + ["--dlpf-cfg", 3]),
    ("IMU (GLRT), DLPF 20 Hz", 200, ST + IMU + ["--dlpf-cfg", 4]),
    ("IMU (GLRT), DLPF 41 Hz", 1000, ST + IMU + ["--dlpf-cfg", 3, "--rate", 1000]),
    ("IMU (GLRT), DLPF 20 Hz", 1000, ST + IMU + ["--dlpf-cfg", 4, "--rate", 1000]),
    ("IMU (GLRT), white", 200, ST + IMU + DE),
    ("IMU (GLRT), white", 1000, ST + IMU + DE + ["--rate", 1000]),
    ("IMU (GLRT), white", 200, ["--case", "in-place", "--case", "bias20-straight", "--case", "bias20"] + IMU + DE),
    ("IMU (GLRT), white", 200, ["--case", "vib0"] + IMU + DE),
    ("perfect, white", 200, ST + ["--rest", "perfect"] + DE),
    ("perfect", 1000, ["--case", "straight", "--rest", "perfect", "--rate", 1000]),
    ("perfect, DLPF 20 Hz", 1000, ["--case", "straight", "--rest", "perfect", "--rate", 1000, "--dlpf-cfg", 4]),
]

RESULT_HEADER = [
    "median %",
    "p90 %",
    "max %",
    "end within 1 sigma (per axis)",
    "NEES/2 mean",
    "rest ends within 1 sigma",
]


def rate(hz):
    return "1 kHz" if hz == 1000 else f"{hz} Hz"


def results(c):
    return [c["median"], c["p90"], c["max"], c["within"], c["nees"], c["rest_within"]]


def live(ctx):
    """The live pipeline's table (rest flags from the IMU), and its flags scored against truth."""
    rows, flag_rows = [], []
    for flags, hz, args in LIVE:
        for name, c in de.run(ctx, args + ["--per-seed"]).items():
            prefix = [flags, c["label"], rate(hz)]
            rows.append(prefix + results(c) + [de.factor_range(c)])
            if "imu" in args:
                flag_rows.append(de.flags_row(prefix, c))
    return {
        "odometry-live": table(
            ["rest flags", "case", "rate"] + RESULT_HEADER + ["accelerometer effective-sample factor (over seeds)"],
            rows,
        ),
        "odometry-live-flags": table(["rest flags", "case", "rate"] + de.FLAGS_HEADER, flag_rows),
    }


def hindsight(ctx):
    """Median % (NEES/2) against the rest hindsight, white samples."""
    rows = []
    for hz, values in ((200, ["0", "0.3", "0.5", "0.75", "1"]), (1000, ["0"])):
        for x in values:
            extra = ["--rate", hz] if hz != 200 else []
            cases = de.run(ctx, ST + IMU + ["--rest-hindsight-s", x] + DE + extra)
            label = f"{x} s" + (" (default)" if x == "0.5" else "")
            rows.append([label, rate(hz)] + [f"{cases[n]['median']} ({cases[n]['nees']})" for n in ("straight", "turns")])
    return {"odometry-hindsight": table(["hindsight", "rate", "straight", "turns"], rows)}


FULL_HEADER = ["case"] + RESULT_HEADER + ["motion drift RMS revised / forward, m"]


def full_table(cases):
    return table(FULL_HEADER, [[c["label"]] + results(c) + [c["drift"]] for c in cases.values()])


def perfect(ctx):
    """The main table: perfect rest flags, white samples, every case."""
    return {"odometry-perfect": full_table(de.run(ctx, DE))}


VARIANTS = [
    ("seeds 20-39", ["--first-seed", 20, "--case", "straight", "--case", "turns", "--case", "in-place", "--case", "bias20", "--case", "vib0"]),
    ("1 kHz", ["--rate", 1000] + ST),
    ("no gyro calibration (identity)", ["--gyro-cal", "none", "--case", "straight", "--case", "turns", "--case", "in-place"]),
    ("the simulator's gyro model inverted", ["--gyro-cal", "model", "--case", "turns", "--case", "in-place"]),
]


def variants(ctx):
    """The main table's drives on other seeds, at 1 kHz and with other gyro corrections."""
    rows = []
    for what, args in VARIANTS:
        for c in de.run(ctx, args + DE).values():
            rows.append([what, c["label"]] + results(c))
    return {"odometry-variants": table(["variant", "case"] + RESULT_HEADER, rows)}


def default_legs(ctx):
    """The main table with the simulator's default motion lengths."""
    return {"odometry-default-legs": full_table(de.run(ctx, ["--sim-default-legs"] + DE))}


BUDGET = [
    ("nothing", []),
    ("gyro white noise (and ADC quantization, which it dithers)", ["--off", "gyro-noise", "--off", "adc"]),
    ("gyro white noise on x and y only", ["--off", "gyro-noise-xy"]),
    ("gyro white noise on z only", ["--off", "gyro-noise-z"]),
    ("accelerometer white noise", ["--off", "accel-noise"]),
    (
        "accelerometer residual scale/misalignment, temperature drift, turn-on bias",
        ["--off", "accel-scale", "--off", "accel-temp", "--off", "accel-turn-on"],
    ),
]


def budget(ctx):
    """Median % and NEES/2 of the turns case with one sensor-model term off at a time."""
    rows = []
    for what, off in BUDGET:
        c = de.run(ctx, ["--case", "turns"] + off + DE)["turns"]
        rows.append([what, c["median"], c["nees"]])
    c = de.run(ctx, ["--case", "vib0"] + DE)["vib0"]
    rows.append(["vibration (the vibration-0 case)", c["median"], c["nees"]])
    return {"odometry-budget": table(["switched off", "median %", "NEES/2"], rows)}


# docs/hints.md: (row label, drive_eval arguments, the per-drive column's fields).
HINT_ROWS = [
    ("none (IMU only)", ["--hints", "none"]),
    ("all (no losses)", ["--hints", "all"]),
    ("realistic (2% lost, bursts of 0.2-2 s)", ["--hints", "realistic"]),
    ("half lost (50%, and the bursts)", ["--hints", "half"]),
    ("all, stationary commanded (75 ms lead)", ["--hints", "all", "--hint-rest", "commanded"]),
    ("half lost, stationary commanded", ["--hints", "half", "--hint-rest", "commanded"]),
    ("all, perfect rest flags upstream (`--rest perfect`)", ["--hints", "all", "--rest", "perfect"]),
    ("all, IMU yawed 35 deg on the robot, configured", ["--hints", "all", "--mount-yaw-deg", 35]),
    ("all, IMU yawed 35 deg, mounting estimated", ["--hints", "all", "--mount-yaw-deg", 35, "--estimate-mounting"]),
    ("all, with moderate vibration (`--case turns`)", ["--hints", "all", "--case", "turns"]),
    ("all, 1 kHz (`--rate 1000`, the live rate)", ["--hints", "all", "--rate", 1000]),
]


def hints(ctx):
    """docs/hints.md's table: the smooth floor with turns, with and without robot hints."""
    rows = []
    for what, args in HINT_ROWS:
        case = ["--case", "vib0"] if "--case" not in args else []
        rest = ["--rest", "imu"] if "--rest" not in args else []
        (c,) = de.run(ctx, case + rest + args + DE).values()
        h = c.get("hints")
        per_drive = "-"
        if h is not None:
            per_drive = f"{h['updates']} speed updates, {h['disagree']} disagreeing, {h['stale']} stale samples"
            if "--estimate-mounting" in args:
                per_drive += f"; mounting error up to {h['mount']} deg"
        rows.append([what] + results(c) + [per_drive])
    return {"hints-smooth-floor": table(["hints"] + RESULT_HEADER + ["per drive"], rows)}


COST = re.compile(
    r"^(?P<label>[^:]+): (?P<samples>\d+) samples, (?P<states>\d+) states \((?P<revised>\d+) revised\), "
    r"(?P<withdrawn>\d+) rest flags withdrawn; mean (?P<mean>[0-9.]+) us/sample \(wall incl. timing\), "
    r"p50 (?P<p50>[0-9.]+) us, p99 (?P<p99>[0-9.]+) us, p99.9 (?P<p999>[0-9.]+) us, max (?P<max>[0-9.]+) us$",
    re.M,
)


def cost(ctx):
    """`OdometryStage::process` per call on a 10-minute 1 kHz drive (the stage bench)."""
    out, _ = ctx.run(["cargo", "bench", "-q", "-p", "odometry", "--bench", "stage"])
    if ctx.dry:
        return {}
    rows = [
        [m["label"], m["mean"], m["p50"], m["p99"], m["p999"], m["max"], m["states"], m["revised"], m["withdrawn"]]
        for m in COST.finditer(out)
    ]
    if not rows:
        raise Failed("the stage bench printed no pass")
    header = ["pass", "mean us/sample", "p50 us", "p99 us", "p99.9 us", "max us", "states", "revised", "rest flags withdrawn"]
    return {"odometry-cost": table(header, rows)}


def faults(ctx):
    """The fault benchmark: real processes, one fault each, NEES after it."""
    ctx.run(["cargo", "build", "--release", "-q", "-p", "mems-replay", "-p", "mems-sim", "-p", "calibrate",
             "-p", "calibrate-science", "-p", "odometry"])
    args = ["--seeds", 1, "--seconds", 30, "--speed", 2, "--only", "none"] if ctx.quick else ["--seeds", 3, "--seconds", 60, "--speed", 2]
    out, _ = ctx.cargo_example("mems-replay", "faults", args)
    if ctx.dry:
        return {}
    header, rows = one_table(out, "faults")
    return {"odometry-faults": table(header, rows)}
