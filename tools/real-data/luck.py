#!/usr/bin/env python3
"""How much of each corpus row is luck: every recording run as bench.py runs it, clean and
with white noise far below any part's own added to every sample, once per seed; the table
gives each row's % of distance clean and its smallest, median and largest over the seeds, and
each platform class's median per seed. A change whose effect on a row or a class median lies
inside that spread is not measured by the row.

The noise (sensor frame, the units of the converted files): `--accel-ug` micro-g and
`--gyro-mdps` milli-deg/s of 1-sigma per sample and axis, by default 100 ug and 10 mdps:
below an MPU-9250's own white noise even at its slowest output filter (300 ug/sqrt(Hz) and
0.01 deg/s/sqrt(Hz) over 5 Hz, PS-MPU-9250A-01 rev 1.1, tables 3.1 and 3.2: 670 ug and
22 mdps), about one count of a +-2 g or +-250 deg/s range (61 ug, 7.6 mdps). Seed `s` draws the noise of every recording from a
generator seeded with `s` and the recording's id, so a run is repeatable.

Usage: luck.py [--seeds N] [--accel-ug U] [--gyro-mdps M] [--bin PATH] [--data DIR]
               [--only ID ...] [--json] [--self-test]
"""

import argparse
import json
import random
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench  # noqa: E402
import perturb  # noqa: E402


class Noise:
    """White noise added to every sample (module documentation); perturb.py's interface."""

    clips = False
    rescales = True

    def __init__(self, accel_g, gyro_dps, seed):
        self.accel_g, self.gyro_dps = accel_g, gyro_dps
        self.rng = random.Random(seed)

    def apply(self, accel, gyro):
        """The noisy (accel g, gyro deg/s); nothing is capped."""
        accel = [a + self.rng.gauss(0.0, self.accel_g) for a in accel]
        gyro = [w + self.rng.gauss(0.0, self.gyro_dps) for w in gyro]
        return accel, gyro, False


def pct(row):
    """% of distance (upper end) of a bench row, None if it failed."""
    return None if "error" in row else row["result"]["pct_of_distance"][1]


def run(args, recordings):
    """{id: {"platform", "clean", "seeds": [% per seed]}}."""
    out = {r["id"]: {"platform": r["platform"], "seeds": []} for r in recordings}
    extra = {r["id"]: list(r.get("extra_args", [])) for r in recordings}
    for seed in range(0, args.seeds + 1):
        # A runner per seed: a runner keeps each recording's result.
        with bench.plain_and_changed(args.bin, args.data) as (plain, noisy, changed):
            for rec in recordings:
                if seed == 0:
                    out[rec["id"]]["clean"] = pct(plain.row(rec, extra[rec["id"]]))
                    continue
                name = bench.copy_sidecar(args.data, changed, rec)
                write = perturb.perturb_mcap if name.endswith(".mcap") else perturb.perturb_csv
                noise = Noise(args.accel_ug * 1e-6, args.gyro_mdps * 1e-3, f"{seed}:{rec['id']}")
                write(Path(args.data) / name, changed / name, noise)
                out[rec["id"]]["seeds"].append(pct(noisy.row(rec, extra[rec["id"]])))
        print(f"seed {seed}: done", file=sys.stderr)
    return out


def fmt(v):
    return "failed" if v is None else f"{v:.2f}"


def spread(values):
    """(smallest, median, largest) with failed runs as infinite."""
    v = sorted(float("inf") if x is None else x for x in values)
    return v[0], statistics.median(v), v[-1]


def table(args, out):
    print(f"Corpus rows, % of distance (upper end): clean, and with white noise of {args.accel_ug:g} ug "
          f"and {args.gyro_mdps:g} mdps per sample over {args.seeds} seeds")
    print()
    print("| recording | class | clean | smallest | median | largest |")
    print("|---|---|---|---|---|---|")
    for rid, r in out.items():
        lo, mid, hi = spread(r["seeds"])
        print(f"| {rid} | {r['platform']} | {fmt(r['clean'])} | {fmt(lo)} | {fmt(mid)} | {fmt(hi)} |")
    print()
    print("| class | clean median | medians over the seeds (smallest, median, largest) |")
    print("|---|---|---|")
    for platform in sorted({r["platform"] for r in out.values()}):
        rows = [r for r in out.values() if r["platform"] == platform]
        clean = spread([r["clean"] for r in rows])[1]
        per_seed = [spread([r["seeds"][i] for r in rows])[1] for i in range(args.seeds)]
        lo, mid, hi = spread(per_seed)
        print(f"| {platform} | {fmt(clean)} | {fmt(lo)}, {fmt(mid)}, {fmt(hi)} |")


def self_test():
    """Adds the noise to an inline CSV of 4000 samples: no noise leaves every value as it was,
    a seed gives the same values twice, and the added values' standard deviation is the one
    asked (within 5 %); no data needed."""
    cols = perturb.ACCEL + perturb.GYRO
    samples = [[0.01 * i] + [0.0, 0.0, 1.0, 0.0, 0.0, 0.0] for i in range(4000)]
    text = "# test\nt_s," + ",".join(cols) + "\n" + "".join(",".join(map(repr, r)) + "\n" for r in samples)

    def noisy(accel_g, gyro_dps, seed):
        with tempfile.TemporaryDirectory() as tmp:
            src, dst = Path(tmp) / "in.csv", Path(tmp) / "out.csv"
            src.write_text(text)
            perturb.perturb_csv(src, dst, Noise(accel_g, gyro_dps, seed))
            return [[float(v) for v in line.split(",")[1:]] for line in dst.read_text().splitlines()[2:]]

    assert noisy(0.0, 0.0, "1:x") == [r[1:] for r in samples], "no noise changes nothing"
    once, twice = noisy(1e-4, 1e-2, "1:x"), noisy(1e-4, 1e-2, "1:x")
    assert once == twice, "a seed repeats"
    for axis, sigma in ((0, 1e-4), (2, 1e-4), (3, 1e-2), (5, 1e-2)):
        added = [row[axis] - base[axis + 1] for row, base in zip(once, samples)]
        sd = statistics.pstdev(added)
        assert abs(sd / sigma - 1.0) < 0.05, (axis, sd, sigma)
    print("luck.py self-test: ok (no noise, repeatable seed, standard deviation)")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--accel-ug", type=float, default=100.0, help="accelerometer noise, micro-g per sample")
    p.add_argument("--gyro-mdps", type=float, default=10.0, help="gyroscope noise, milli-deg/s per sample")
    bench.add_run_args(p)
    p.add_argument("--self-test", action="store_true", help="check the noise on inline samples (no data) and exit")
    args = p.parse_args()
    if args.self_test:
        self_test()
        return 0
    if args.seeds < 1:
        p.error("--seeds must be at least 1")
    recordings = bench.corpus_recordings(args.only)
    out = run(args, recordings)
    if args.json:
        json.dump(out, sys.stdout, indent=1)
        print()
    else:
        table(args, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
