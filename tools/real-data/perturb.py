#!/usr/bin/env python3
"""Corpus recordings with a cheap part's errors added, run as bench.py runs them: a table of
the end error and 1-sigma of each recording as converted (clean) and perturbed, with what the
odometry reported of the perturbation.

The perturbation, applied to every sample in this order (sensor frame, the units of the
converted files: accelerometer in g, gyroscope in deg/s):
1. accelerometer errors of an uncalibrated part: `a' = (1 + s) a + b` with `s` from
   `--accel-scale` (a fraction, the same on every axis: 0.04 reads 4 % high) and `b` from
   `--accel-bias-g` (g, the same on every axis, or three comma-separated values x,y,z);
2. the range of a cheap part: every gyroscope column capped at +-DPS deg/s (`--gyro-dps`) and
   every accelerometer column at +-G g (`--accel-g`), as a part with that range outputs its
   end of range for anything beyond.
Nothing tells the odometry of either: it infers a range from the readings stuck at the
file's extreme (ipc_types::stream::range) and an accelerometer error from its rests
(docs/odometry.md, "An uncalibrated accelerometer"). A CSV recording is rewritten row by row;
an MCAP recording (convert.py's JSON messages) message by message, its raw samples' `accel_g`,
`gyro_dps` and counts. Errors and coverage are bench.py's (`evaluate`: horizontal end error,
covered when within the 68 % radius).

With a range (clipping), the foot walks are run three ways: as the odometry runs them (each
clipped motion reconstructed at its rest, odometry/src/clip.rs), bridged only
(`--bridge-clipped`: the 1-sigma widened for what the clips hid, nothing reconstructed) and
integrated as measured (`--trust-clipped`, the behaviour before the check); a run passes within
2x of its clean error; otherwise every corpus recording is run and a run passes within 1.5x (at
least 5 cm: below that the clean error is noise).

Usage: perturb.py [--gyro-dps DPS] [--accel-g G] [--accel-scale S] [--accel-bias-g B[,B,B]]
                  [--bin PATH] [--data DIR] [--only ID ...] [--json]
"""

import argparse
import json
import struct
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench  # noqa: E402
import containers  # noqa: E402

ACCEL, GYRO = ("ax_g", "ay_g", "az_g"), ("gx_dps", "gy_dps", "gz_dps")
# Smallest error a perturbed run is measured against: a clean error below it is luck.
FLOOR_M = 0.05


class Perturbation:
    """The errors of one part (see the module documentation)."""

    def __init__(self, args):
        self.scale = 1.0 + (args.accel_scale or 0.0)
        bias = [float(b) for b in (args.accel_bias_g or "0").split(",")]
        if len(bias) not in (1, 3):
            raise SystemExit(f"--accel-bias-g {args.accel_bias_g}: one value or three (x,y,z), g")
        self.bias = bias * 3 if len(bias) == 1 else bias
        self.accel_g, self.gyro_dps = args.accel_g, args.gyro_dps

    @property
    def clips(self):
        return self.accel_g is not None or self.gyro_dps is not None

    @property
    def rescales(self):
        """Whether every sample's values change (not only the clipped ones)."""
        return self.scale != 1.0 or any(self.bias)

    def apply(self, accel, gyro):
        """The perturbed (accel g, gyro deg/s) and whether a value was capped."""
        accel = [self.scale * a + b for a, b in zip(accel, self.bias)]
        capped = False
        for values, limit in ((accel, self.accel_g), (gyro, self.gyro_dps)):
            if limit is None:
                continue
            for i, v in enumerate(values):
                if abs(v) > limit:
                    values[i] = limit if v > 0 else -limit
                    capped = True
        return accel, gyro, capped

    def describe(self):
        parts = []
        if self.scale != 1.0 or any(self.bias):
            parts.append(f"accelerometer scale {100 * (self.scale - 1):+g} %, bias "
                         f"{', '.join(f'{b:g}' for b in self.bias)} g")
        if self.gyro_dps is not None:
            parts.append(f"clipped at +-{self.gyro_dps:g} deg/s (gyro)")
        if self.accel_g is not None:
            parts.append(f"clipped at +-{self.accel_g:g} g (accel)")
        return "; ".join(parts)


def perturb_csv(src, dst, p):
    """Writes `src` to `dst` perturbed by `p`; returns the rows capped."""
    ia, ig, capped = [], [], 0

    def header(cells, _line):
        ia.extend(cells.index(c) for c in ACCEL)
        ig.extend(cells.index(c) for c in GYRO)
        return cells

    def row(cells):
        nonlocal capped
        accel, gyro, hit = p.apply([float(cells[i]) for i in ia], [float(cells[i]) for i in ig])
        if p.rescales or hit:
            for i, v in zip(ia + ig, accel + gyro):
                cells[i] = repr(v)
        capped += hit
        return cells

    bench.rewrite_csv(src, dst, header, row)
    return capped


def perturb_mcap(src, dst, p):
    """Writes convert.py's MCAP `src` to `dst` with its raw samples perturbed by `p`; returns
    the samples capped."""
    buf = src.read_bytes()
    out, capped = [containers.MCAP_MAGIC], 0
    for op, body in containers.read_mcap_records(buf):
        if op == containers.MCAP_OP["message"]:
            head, msg = body[:22], json.loads(body[22:])
            if "accel_g" in msg:
                accel, gyro, hit = p.apply(msg["accel_g"], msg["gyro_dps"])
                capped += hit
                msg["accel_g"], msg["gyro_dps"] = accel, gyro
                msg["accel_counts"] = [containers._counts(v, 16384) for v in accel]
                msg["gyro_counts"] = [containers._counts(v, 131) for v in gyro]
                body = head + json.dumps(msg, separators=(",", ":")).encode()
        out.append(struct.pack("<BQ", op, len(body)) + body)
    out.append(containers.MCAP_MAGIC)
    dst.write_bytes(b"".join(out))
    return capped


def figures(row):
    """(horizontal error upper end, m; 1-sigma, m; covered; clipped samples; the accelerometer
    error the odometry reported) of a run, None if it failed."""
    if "error" in row:
        return None
    r, out = row["result"], row["odometry"]
    return r["error_m"][1], r["sigma_h_m"], r["covered"], out.get("clipped_samples"), out.get("accel_error")


def run_all(args, p, recordings):
    data = Path(args.data)
    rows = []
    with bench.plain_and_changed(args.bin, data) as (plain, perturbed, changed):
        for rec in recordings:
            name = bench.copy_sidecar(data, changed, rec)
            write = perturb_mcap if name.endswith(".mcap") else perturb_csv
            capped = write(data / name, changed / name, p)
            extra = list(rec.get("extra_args", []))
            row = {
                "id": rec["id"],
                "rows_capped": capped,
                "clean": figures(plain.row(rec, extra)),
                "perturbed": figures(perturbed.row(rec, extra)),
            }
            if p.clips:
                row["bridged"] = figures(perturbed.row(rec, extra + ["--bridge-clipped"]))
                row["trusted"] = figures(perturbed.row(rec, extra + ["--trust-clipped"]))
            rows.append(row)
            print(f"{rec['id']}: done", file=sys.stderr)
    return rows


def fmt(f):
    return "failed" if f is None else f"{f[0]:.2f} / {f[1]:.2f}"


def clipping_table(p, rows):
    """The table of a run with a range (clipped.py's, as docs/input-checks.md shows it)."""
    print(f"Foot walks {p.describe()}; horizontal end error / 1-sigma, m")
    print()
    print("| walk | rows clipped | unclipped | clipped, reconstructed at the rest | covered | within 2x of unclipped "
          "| clipped, bridged only | covered | within 2x | clipped, integrated as measured |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    tally = {"perturbed": [0, 0], "bridged": [0, 0]}
    for r in rows:
        u, t = r["clean"], r["trusted"]
        cells = []
        for key in ("perturbed", "bridged"):
            c = r[key]
            within = u is not None and c is not None and c[0] <= 2 * max(u[0], 0.0)
            covered = c is not None and c[2] == "yes"
            tally[key][0] += within
            tally[key][1] += covered
            cells.append(f"{fmt(c)} | {c[2] if c else '-'} | {'yes' if within else 'no'}")
        c = r["perturbed"]
        print(f"| {r['id']} | {r['rows_capped']} ({c[3] if c else '?'} flagged) | {fmt(u)} | {cells[0]} | {cells[1]} | {fmt(t)} |")
    print()
    for key, what in (("perturbed", "reconstructed at the rest"), ("bridged", "bridged only (--bridge-clipped)")):
        good, covered = tally[key]
        print(f"{what}: {good} of {len(rows)} within 2x of their unclipped error; {covered} of {len(rows)} covered by the 1-sigma")
        print()


def describe_estimate(e):
    """The accelerometer bias the odometry estimated (m/s^2, sensor frame, +- 1-sigma) and,
    where its rests at several attitudes gave one, the per-axis scale error (%, +- 1-sigma),
    as the table shows them; `uncalibrated` when it used the uncalibrated prior."""
    if not e:
        return "-"
    b, s = e["bias_mps2"], e["bias_sigma_mps2"]
    text = ", ".join(f"{v:+.2f} +- {d:.2f}" for v, d in zip(b, s))
    fit = e.get("per_axis")
    scale = ""
    if fit:
        k = ", ".join(f"{100 * v:+.2f} +- {100 * d:.2f}" for v, d in zip(fit["scale"], fit["scale_sigma"]))
        scale = f"; scale % ({k}) from {fit['poses']} attitudes"
    return f"{'uncalibrated: ' if e['uncalibrated'] else ''}({text}){scale}"


def error_table(p, rows):
    """The table of a run with accelerometer errors only."""
    print(f"Corpus recordings with {p.describe()}; horizontal end error / 1-sigma, m")
    print()
    print("| recording | clean | perturbed | covered | clipped | accelerometer error estimated: bias, m/s^2; per-axis scale | within 1.5x of clean |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    good = covered = ran = clean_covered = both = 0
    for r in rows:
        u, c = r["clean"], r["perturbed"]
        within = u is not None and c is not None and c[0] <= 1.5 * max(u[0], FLOOR_M)
        good += within
        ran += c is not None
        covered += c is not None and c[2] == "yes"
        if u is not None and u[2] == "yes":
            clean_covered += 1
            both += c is not None and c[2] == "yes"
        print(f"| {r['id']} | {fmt(u)} | {fmt(c)} | {c[2] if c else '-'} | {c[3] if c else '-'} | "
              f"{describe_estimate(c[4]) if c else '-'} | {'yes' if within else 'no'} |")
    print()
    print(f"{ran} of {len(rows)} gave a position; {good} within 1.5x of their clean error (at least "
          f"{FLOOR_M} m); {covered} of {len(rows)} covered by the 1-sigma ({both} of the {clean_covered} "
          f"whose clean run is)")


def self_test():
    """Perturbs a two-sample CSV and the same samples as convert.py's MCAP (with a hint) and
    checks the values read back; no data needed."""
    p = Perturbation(argparse.Namespace(accel_scale=0.04, accel_bias_g="0.15", accel_g=None, gyro_dps=250.0))
    samples = [(0.0, 0.0, 0.0, 1.0, 10.0, 300.0, -300.0), (0.01, 0.5, -0.5, 1.0, 0.0, 0.0, 0.0)]
    expected = [([0.15, 0.15, 1.19], [10.0, 250.0, -250.0]), ([0.67, -0.37, 1.19], [0.0, 0.0, 0.0])]
    hint = {"t_s": 0.0, "forward_speed_mps": 1.0, "forward_speed_sigma_mps": 0.05, "flags": 12}

    def close(got, want):
        return all(abs(a - b) < 1e-9 for a, b in zip(got, want))

    # The changed-copies directory the corpus runs write into (bench.plain_and_changed, entered
    # as they enter it; no run is made).
    with bench.plain_and_changed("mems-odometry", ".") as (_, _, tmp):
        src, dst = Path(tmp) / "in.csv", Path(tmp) / "out.csv"
        src.write_text("# test\nt_s," + ",".join(ACCEL + GYRO) + "\n"
                       + "".join(",".join(map(repr, row)) + "\n" for row in samples))
        assert perturb_csv(src, dst, p) == 1, "CSV: one row capped"
        rows = [line.split(",") for line in dst.read_text().splitlines()[2:]]
        for row, (accel, gyro) in zip(rows, expected):
            assert close([float(v) for v in row[1:4]], accel) and close([float(v) for v in row[4:7]], gyro), row
        messages, _ = containers.mcap_messages(samples, [hint])
        src, dst = Path(tmp) / "in.mcap", Path(tmp) / "out.mcap"
        src.write_bytes(containers.mcap_bytes(messages))
        assert perturb_mcap(src, dst, p) == 1, "MCAP: one sample capped"
        raw, hints = [], []
        for op, body in containers.read_mcap_records(dst.read_bytes()):
            if op == containers.MCAP_OP["message"]:
                msg = json.loads(body[22:])
                (raw if "accel_g" in msg else hints).append(msg)
        assert len(raw) == 2 and len(hints) == 1 and hints[0]["forward_speed_mps"] == 1.0, (raw, hints)
        for msg, (accel, gyro) in zip(raw, expected):
            assert close(msg["accel_g"], accel) and close(msg["gyro_dps"], gyro), msg
            assert msg["accel_counts"] == [round(v * 16384) for v in accel], msg
            assert msg["gyro_counts"] == [round(v * 131) for v in gyro], msg
    print("perturb.py self-test: ok (CSV, MCAP)")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--gyro-dps", type=float, help="clip the gyroscope at +-DPS deg/s")
    p.add_argument("--accel-g", type=float, help="clip the accelerometer at +-G g")
    p.add_argument("--accel-scale", type=float, help="accelerometer scale error, fraction (0.04: 4 %% high)")
    p.add_argument("--accel-bias-g", help="accelerometer bias, g: one value for every axis or x,y,z")
    bench.add_run_args(p)
    p.add_argument("--self-test", action="store_true", help="check the CSV and MCAP perturbation on inline samples (no data) and exit")
    args = p.parse_args()
    if args.self_test:
        self_test()
        return 0
    perturbation = Perturbation(args)
    if not perturbation.describe():
        p.error("nothing to perturb: give --gyro-dps, --accel-g, --accel-scale or --accel-bias-g")
    recordings = bench.corpus_recordings(args.only, "foot" if perturbation.clips else None)
    rows = run_all(args, perturbation, recordings)
    if args.json:
        json.dump(rows, sys.stdout, indent=1)
        print()
    elif perturbation.clips:
        clipping_table(perturbation, rows)
    else:
        error_table(perturbation, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
