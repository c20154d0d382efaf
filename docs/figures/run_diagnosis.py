"""docs/diagnosis.md, "The residual loop on an odometry run": `mems-odometry diagnose` on
simulated arm runs (each effect undeclared and declared, a clean run, an effect no candidate
covers) and on every recording of the real-data corpus (/work/real-data, run as
tools/real-data/bench.py runs them: the identity calibration, the sidecar's extra arguments)."""

import json
import math
import os
import sys
from pathlib import Path

from common import REPO, Failed, Section, table

sys.path.insert(0, str(REPO / "tools" / "real-data"))
from bench import identity_calibration  # noqa: E402

B = "target/release/mems-odometry"
SIM = "target/release/mems-sim"
DIR = "/tmp/figures-rundiag"
DATA = Path(os.environ.get("MEMS_REAL_DATA", "/work/real-data"))
ARM = ["arm", "--moves", "24", "--pauses", "1,2", "--rate", "200", "--seed", "3"]
LONG_ARM = ["arm", "--moves", "60", "--pauses", "1,2", "--rate", "200", "--seed", "3"]
# A drive with turns for the lever-arm candidate (the IMU ahead of the rear axle), run as the vehicle profile.
DRIVE = ["drive", "--duration", "120", "--turns", "on", "--seed", "4", "--rate", "200"]
IDENTITY_SCALE = "scale = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]"

# (case, model changes (table, key, value), what the calibration file declares).
EFFECTS = [
    ("accel_bias", [("accel", "bias", "[0.006, -0.005, 0.0]")], ("bias_g = [0.0, 0.0, 0.0]", "bias_g = [0.006, -0.005, 0.0]")),
    ("accel_scale", [("accel", "scale", "[0.012, -0.01, 0.001]")],
     (IDENTITY_SCALE, "scale = [[1.012, 0.0, 0.0], [0.0, 0.99, 0.0], [0.0, 0.0, 1.001]]")),
    ("gyro_scale", [("gyro", "scale", "[0.08, -0.07, 0.01]")],
     "\n[gyro]\ncorrection = [[%r, 0.0, 0.0], [0.0, %r, 0.0], [0.0, 0.0, %r]]\n" % (1 / 1.08, 1 / 0.93, 1 / 1.01)),
    # (I + M)^-1 of a symmetric x-y cross-axis M (0.08) and of a rotation M = [phi]x, phi = 0.05 rad about x.
    ("gyro_cross_axis", [("gyro", "misalignment", "[[0.0, 0.08, 0.0], [0.08, 0.0, 0.0], [0.0, 0.0, 0.0]]")],
     "\n[gyro]\ncorrection = [[%r, %r, 0.0], [%r, %r, 0.0], [0.0, 0.0, 1.0]]\n" % (1 / (1 - 0.08**2), -0.08 / (1 - 0.08**2),
                                                                           -0.08 / (1 - 0.08**2), 1 / (1 - 0.08**2))),
    ("gyro_rotation", [("gyro", "misalignment", "[[0.0, 0.0, 0.0], [0.0, 0.0, -0.05], [0.0, 0.05, 0.0]]")],
     "\n[gyro]\ncorrection = [[1.0, 0.0, 0.0], [0.0, %r, %r], [0.0, %r, %r]]\n" % (1 / (1 + 0.05**2), 0.05 / (1 + 0.05**2),
                                                                           -0.05 / (1 + 0.05**2), 1 / (1 + 0.05**2))),
    ("accel_temp_bias", [("accel", "bias_temp_coeff", "[0.002, -0.0015, 0.0]"), ("thermal", "ambient_drift_c_per_s", "0.15"),
                         ("thermal", "self_heating_c", "0.0")],
     "\n[temperature]\nreference_c = 25.0\nbias_g_per_c = [0.002, -0.0015, 0.0]\n"),
]
# The uncovered effect: a gyro nonlinearity (deg/s read as u + k u^2) on a part whose gyro is calibrated (scale and
# misalignment zero, declared to 0.1 %); "calibrated gyro" is the same part without it.
CALIBRATED_GYRO = [("gyro", "scale", "[0.0, 0.0, 0.0]"), ("gyro", "misalignment", "[[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]")]
GYRO_DECLARED = ("\n[gyro]\ncorrection = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\n"
                 "correction_sigma = [[0.001, 0.001, 0.001], [0.001, 0.001, 0.001], [0.001, 0.001, 0.001]]\n")
UNCOVERED = [("gyro", "nonlinearity", "[0.0001, -0.0001, 0.0001]")]


def set_key(model, changes):
    """The `print-model` TOML with each (table, key, value) set."""
    out, table_name = [], ""
    for line in model.splitlines():
        if line.startswith("["):
            table_name = line.strip("[]")
        for t, k, v in changes:
            if t == table_name and line.startswith(k + " = "):
                line = f"{k} = {v}"
        out.append(line)
    return "\n".join(out) + "\n"


def declare(identity, declared):
    """The identity calibration with an effect declared: a replacement or an appended table."""
    if isinstance(declared, tuple):
        return identity.replace(*declared)
    return identity + declared


def fmt(v, digits=3):
    return "-" if v is None else f"{v:.{digits}f}"


def lever_found(report):
    """The lever-arm candidate's report when found, else None."""
    lever = report.get("lever_arm") or {}
    return lever if (lever.get("candidate") or {}).get("found") else None


def before_after(report, key, digits=3):
    after = (report.get("after") or {}).get("figures", {}).get(key)
    lever = lever_found(report)
    if after is None and lever is not None:
        after = lever["after"].get(key)
    return f"{fmt(report['before'].get(key), digits)} -> {fmt(after, digits)}"


def lever_score(report):
    """The lever-arm candidate's score and forward offset (m), or None where it was not testable."""
    c = (report.get("lever_arm") or {}).get("candidate") or {}
    if not c or c.get("untestable"):
        return None
    return f"lever_arm {c['gain']:.0f} ({c['r_x_m']:.2f} +- {c['sigma_m']:.2f} m)"


def selected(report):
    """The selected candidates; the lag with its value and 1-sigma (ms)."""
    names = []
    for name, params in report["diagnosis"]["selected"]:
        if name == "accel_lag":
            sd = next(c["sigma"][0] for c in report["diagnosis"]["scores"] if c["candidate"] == name)
            name = f"accel_lag {1e3 * params[0]:.1f} +- {1e3 * sd:.1f}"
        names.append(name)
    lever = lever_found(report)
    if lever is not None:
        c = lever["candidate"]
        names.append(f"lever_arm {c['r_x_m']:.2f} +- {c['sigma_m']:.2f} m")
    return ", ".join(names) if names else "none"


def diagnose(ctx, run, calib, extra=(), closed=True, flags=()):
    argv = [B, "diagnose", run, "--calib", calib, "--json"] + (["--closed-loop"] if closed else []) + list(flags)
    argv += ["--", *extra] if extra else []
    out, _ = ctx.run(argv, timeout=600)
    if ctx.dry:
        return None
    try:
        return json.loads(out)
    except json.JSONDecodeError as e:
        raise Failed(f"{' '.join(argv)}: no JSON ({e})")


def unexplained(report):
    """yes / no, and why when the rerun refuted the selection."""
    if report["confirmed"] is False:
        return "yes (the rerun refutes the selection)"
    return "yes" if report["unexplained"] else "no"


def saturation(report):
    """The saturation candidate: found or not, the rate hidden on the axes that clipped (deg/s) and the clipped motions'
    tilt rms before -> after (mrad); `-` where it could not be tested."""
    s = report["diagnosis"]["saturation"]
    motions = f"{s['motions']} clipped motion" + ("" if s["motions"] == 1 else "s")
    if s["untestable"]:
        return f"- ({motions})"
    hidden = ", ".join(f"{'xyz'[i]} {math.degrees(h):.1f}" for i, h in enumerate(s["hidden_rps"]) if s["clipped_axes"][i])
    verdict = "found" if s["found"] else "not found"
    return (f"{verdict} ({motions}): {hidden} deg/s; tilt {1e3 * s['rms_before']:.1f} -> "
            f"{1e3 * s['rms_after']:.1f} mrad")


def velocity(report):
    """The velocity rows' rms before -> after the lag, and their stated 1-sigma (m/s)."""
    v = report["diagnosis"]["velocity"]
    return f"{v['rms_before']:.3f} -> {v['rms_after']:.3f} / {v['rms_noise']:.3f}"


def sim_row(label, effect, calib_label, r):
    return [label, effect, calib_label, selected(r), unexplained(r),
            before_after(r, "rest_innovation_rms_mps"), before_after(r, "end_error_m"), before_after(r, "truth_error_m"),
            velocity(r), saturation(r)]


def simulated(ctx, identity_path, identity):
    ctx.region = "diagnosis-run-sim"
    model, _ = ctx.run([SIM, "print-model", "--preset", "calibrated"])
    rows = []

    def case(name, changes, calib_text, label, effect, calib_label, arm=ARM, declare=()):
        mpath, run, cpath = f"{DIR}/{name}.model.toml", f"{DIR}/{name}.mcap", f"{DIR}/{name}.calib.toml"
        if not ctx.dry:
            Path(mpath).write_text(set_key(model, changes))
            Path(cpath).write_text(calib_text)
        ctx.run([SIM, *arm, "--model", mpath, "--out", run, "--force"])
        r = diagnose(ctx, run, cpath, flags=declare)
        if r is not None:
            rows.append(sim_row(label, effect, calib_label, r))

    case("clean", [], identity, "clean", "none", "identity")
    for name, changes, declared in EFFECTS:
        effect = "; ".join(f"{t}.{k} = {v}" for t, k, v in changes)
        case(name, changes, identity, f"{name}, undeclared", effect, "identity")
        case(name + "-declared", changes, declare(identity, declared), f"{name}, declared", effect, "the effect")
    lag = [*ARM, "--accel-lag-s", "0.02"]
    case("accel_lag", [], identity, "accel_lag, undeclared", "accelerometer 20 ms behind the gyro (--accel-lag-s 0.02)",
         "identity", arm=lag)
    case("accel_lag-declared", [], identity, "accel_lag, declared", "the same", "identity; diagnose --accel-lag-s 0.02",
         arm=lag, declare=["--accel-lag-s", "0.02"])
    case("lever_arm", [], identity, "lever arm", "sensor 0.3, -0.2, 0.1 m from the tool point (--lever-arm-m)", "identity",
         arm=[*ARM, "--lever-arm-m", "0.3,-0.2,0.1"])
    gyro_label = "gyro calibrated to 0.1 %"
    case("calibrated-gyro", CALIBRATED_GYRO, identity + GYRO_DECLARED, "calibrated gyro", "gyro.scale and misalignment zero", gyro_label)
    case("uncovered", CALIBRATED_GYRO + UNCOVERED, identity + GYRO_DECLARED, "uncovered",
         "the same; gyro.nonlinearity = [0.0001, -0.0001, 0.0001]", gyro_label)
    for ahead, label, declared in [(0.0, "drive, IMU on the axle", ()),
                                   (1.5, "drive, IMU 1.5 m ahead, undeclared", ()),
                                   (1.5, "drive, IMU 1.5 m ahead, declared", ("--lever-arm", "-1.5,0,0"))]:
        name = f"drive-{ahead}" + ("-declared" if declared else "")
        run = f"{DIR}/{name}.mcap"
        ctx.run([SIM, *DRIVE, "--lever-arm-m", f"{ahead},0,0", "--out", run, "--force"])
        r = diagnose(ctx, run, identity_path, ["--profile", "vehicle"], closed=False, flags=declared)
        if r is not None:
            calib = "identity; diagnose " + " ".join(declared) if declared else "identity"
            rows.append(sim_row(label, f"120 s drive with turns, --lever-arm-m {ahead},0,0", calib, r))
    case("saturation", [], identity, "60 moves, +-250 deg/s", "the gyro clips", "identity", arm=LONG_ARM)
    case("saturation-wide", [], identity, "60 moves, +-500 deg/s", "nothing clips", "identity",
         arm=[*LONG_ARM, "--gyro-range", "500"])
    header = ["run", "effect in the simulated part", "calibration", "selected (accel_lag in ms)", "unexplained",
              "rest innovation rms (m/s) before -> after", "closed-loop end error (m)", "truth end error (m)",
              "velocity rows rms (m/s) before -> after / 1-sigma", "gyro saturation"]
    return table(header, rows)


def corpus(ctx, identity_path):
    ctx.region = "diagnosis-run-corpus"
    rows = []
    for side in sorted(DATA.glob("*.json")):
        s = json.loads(side.read_text())
        run = str(DATA / (s.get("input") or s["csv"]))
        closed = s["truth"]["kind"] == "closed_loop"
        try:
            r = diagnose(ctx, run, identity_path, s.get("extra_args") or [], closed)
        except Failed:
            # A recording the odometry gives no position for (the bench's table says why)
            # has nothing to diagnose: a row says so, and the others go on.
            rows.append([s["id"], s["platform"], "no position: the odometry run failed"] + ["-"] * 8)
            continue
        if r is None:
            continue
        d = r["diagnosis"]
        m, t = d["magnitude"], d["tilt"]
        scores = [f"{c['candidate']} {c['gain']:.0f}" for c in d["scores"] if not c["untestable"]]
        scores = ", ".join(scores + [x for x in [lever_score(r)] if x]) or "none testable"
        rows.append([s["id"], s["platform"], d["rests"], f"{d['motions']} ({d['motions_gyro_clipped']})",
                     f"{1e3 * m['rms_before']:.1f} / {1e3 * m['rms_noise']:.1f}", f"{1e3 * t['rms_before']:.1f} / {1e3 * t['rms_noise']:.1f}",
                     scores, selected(r), unexplained(r),
                     before_after(r, "rest_innovation_rms_mps"), before_after(r, "end_error_m", 2) if closed else "-"])
    header = ["recording", "platform", "rests", "motions (gyro clipped)", "magnitude rms / noise (mm/s^2)", "tilt rms / noise (mrad)",
              "held-out scores", "selected", "unexplained", "rest innovation rms (m/s) before -> after", "closed-loop end error (m)"]
    return table(header, rows)


def generate(ctx):
    ctx.region = "diagnosis-run-sim"
    ctx.run(["cargo", "build", "--release", "-q", "-p", "odometry", "-p", "mems-sim"])
    ctx.run(["rm", "-rf", DIR])  # a fresh private directory: no stale or planted files
    ctx.run(["mkdir", "-m", "700", DIR])
    identity = identity_calibration()
    identity_path = f"{DIR}/identity.toml"
    if not ctx.dry:
        Path(identity_path).write_text(identity)
    sim = simulated(ctx, identity_path, identity)
    real = corpus(ctx, identity_path)
    ctx.run(["rm", "-rf", DIR])
    if ctx.dry:
        return {}
    return {"diagnosis-run-sim": sim, "diagnosis-run-corpus": real}


SECTIONS = [Section("diagnosis-run", "diagnosis.md", ["diagnosis-run-sim", "diagnosis-run-corpus"], "3 min", generate)]
