"""Runs `odometry`'s drive_eval example and reads its table and stderr summaries.

Per case (the CLI name, e.g. `straight`, `bias20`): the table's columns, the rest flags scored
against the truth (with `--rest imu`), the hint counts (with `--hints`), and with `--per-seed`
the zero-velocity update's effective-sample factor of every seed.
"""

import re

from common import Failed, one_table

COLUMNS = ("median", "p90", "max", "within", "nees", "rest_within", "drift")
FLAGS = re.compile(
    r"  (?P<case>[a-z0-9-]+): rest flagged (?P<rest>[0-9.]+)% of rest, (?P<motion>[0-9.]+)% of motion; "
    r"false-rest runs per drive ending at a motion's start / end / in between: "
    r"(?P<r0>[0-9.]+) / (?P<r1>[0-9.]+) / (?P<r2>[0-9.]+), speed x motion left after them "
    r"(?P<c0>[0-9.]+) / (?P<c1>[0-9.]+) / (?P<c2>[0-9.]+) m"
)
HINTS = re.compile(
    r"  (?P<case>[a-z0-9-]+): per drive (?P<updates>[0-9]+) speed updates, (?P<disagree>[0-9]+) samples "
    r"of hint/detector disagreement, (?P<stale>[0-9]+) samples stale; scale error RMS (?P<scale>[0-9.]+)%; "
    r"mounting error max (?P<mount>[0-9.naN]+) deg"
)
FACTOR = re.compile(r"(?P<case>[a-z0-9-]+) seed \d+: .*effective-sample factor (?P<f>[0-9.]+)")

# The table labels of drive_eval's cases.
LABELS = {
    "straight": "straight",
    "turns": "turns",
    "in-place": "in-place turns",
    "vib0": "vibration 0 (turns)",
    "vib-dc-free": "vibration without its content below 0.2 Hz (turns)",
    "bias20-straight": "accelerometer turn-on bias 20 mg, straight",
    "bias20": "accelerometer turn-on bias 20 mg, turns",
}


def run(ctx, args, seeds=None):
    """Runs drive_eval with args (20 seeds, or 2 in a quick run); case name -> its figures."""
    args = [str(a) for a in args]
    if seeds is None:
        seeds = 2 if ctx.quick else 20
    if seeds != 20:
        args += ["--seeds", str(seeds)]
    out, err = ctx.cargo_example("odometry", "drive_eval", args)
    if ctx.dry:
        return {}
    header, rows = one_table(out, "drive_eval " + " ".join(args))
    if header[0] != "case" or len(header) != 1 + len(COLUMNS):
        raise Failed(f"drive_eval: unexpected table header {header}")
    cases = {}
    for r in rows:
        case = dict(zip(COLUMNS, r[1:]))
        case["label"] = LABELS.get(r[0], r[0])
        cases[r[0]] = case
    for m in FLAGS.finditer(err):
        cases[m["case"]]["flags"] = m.groupdict()
    for m in HINTS.finditer(err):
        cases[m["case"]]["hints"] = m.groupdict()
    for m in FACTOR.finditer(err):
        cases[m["case"]].setdefault("factors", []).append(float(m["f"]))
    if not cases:
        raise Failed("drive_eval " + " ".join(args) + ": no case in its table")
    return cases


def factor_range(case):
    """The accelerometer's effective-sample factor over the seeds, `lo-hi` (or `-`)."""
    f = case.get("factors")
    if not f:
        return "-"
    lo, hi = min(f), max(f)
    return f"{lo:.1f}" if abs(hi - lo) < 0.05 else f"{lo:.1f}-{hi:.1f}"


def flags_row(prefix, case):
    """A row of the rest-flag score table: flagged rest and motion time, false-rest runs."""
    f = case.get("flags")
    if f is None:
        raise Failed(f"drive_eval: no rest-flag summary for {case['label']} (needs --rest imu)")
    return prefix + [
        f"{f['rest']}%",
        f"{f['motion']}%",
        f"{f['r0']} / {f['r1']} / {f['r2']}",
        f"{f['c0']} / {f['c1']} / {f['c2']}",
    ]


FLAGS_HEADER = [
    "rest flagged (of rest time)",
    "rest flagged (of motion time)",
    "false-rest runs per drive ending at a motion's start / end / in between",
    "speed x motion left after them, m (start / end / in between)",
]
