"""`docs/figures.py --self-test`: the region check and the output parsers on hand-made input
(no command is run), so that CI notices when a parser or the check stops doing its job."""

import tempfile
from pathlib import Path

import acquisition
import diagnosis
import drive_eval
import odometry
import pages
import run_diagnosis
from common import Context, tables

DRIVE_EVAL_OUT = """seeds 0-1, 200 Hz, motions of up to two 2-6 s legs, gyro correction: from the session, rest flags: IMU detector (GLRT) (hindsight 0.5 s), hints: all
| case | median % | p90 % | max % | end within 1 sigma (per axis) | NEES/2 mean | rest ends within 1 sigma | motion drift RMS revised / forward, m |
|---|---|---|---|---|---|---|---|
| vib0 | 0.05 | 0.28 | 0.37 | 90% | 0.54 | 84% | 0.10 / 0.18 |
"""
DRIVE_EVAL_ERR = """drive_eval: vib0 seed 0: distance 150.1 m, error (0.1, 0.1) m = 0.05%, sigma (0.2, 0.2) m, NEES 0.5, gyro correction error 2.0e-4, speed updates 1, disagreements 2, stale samples 3, scale error +0.1% (sigma 0.2%), mounting error NaN deg, zero-velocity update's effective-sample factor 2.34
drive_eval:   vib0: rest flagged 98.0% of rest, 7.91% of motion; false-rest runs per drive ending at a motion's start / end / in between: 19.0 / 12.0 / 2.0, speed x motion left after them 4.23 / 0.00 / 0.48 m; rests missed per drive 0.0 (longest 0.0 s), longest time between flagged rests 17.3 s
drive_eval:   vib0: per drive 14204 speed updates, 25838 samples of hint/detector disagreement, 0 samples stale; scale error RMS 0.31%; mounting error max NaN deg
"""
TIME_V = """\tUser time (seconds): 2.10
\tSystem time (seconds): 0.50
\tElapsed (wall clock) time (h:mm:ss or m:ss): 1:06.01
\tMaximum resident set size (kbytes): 8000
"""
FUZZ = "csv: 2000 executions in 0.1 s (20000/s): 100 accepted, 1900 refused with a named error, 0 panics, 0 errors without the file; largest allocation 8192 bytes, slowest input 0.10 ms (seed 1, inputs 0..2000)"
LOOP = " 4000 Hz over SPI, read every 1.33 ms: 4000.0 samples/s sustained over 60 s, bus utilisation 2.3 %, host CPU 0.59 us/sample, lost 0, overflows 0, reads 45000"
COST = "no hindsight, final flags: 600001 samples, 620000 states (20000 revised), 0 rest flags withdrawn; mean 1.02 us/sample (wall incl. timing), p50 0.5 us, p99 4.9 us, p99.9 29.0 us, max 8000 us"
DIAG = (
    "baseline  session_mean                             rms 0.00361 m/s^2 (x 0.00228); chi2 482.3 for 180.8 expected, p 1e-28\n"
    "final     session_mean+torn_reads                  rms 0.00249 m/s^2 (x 0.00183); white noise and parameter uncertainty predict "
    "0.00197; chi2 308.7 for 180.8 expected"
)


class Canned(Context):
    """A context whose commands print canned output."""

    def __init__(self, out, err=""):
        super().__init__(quick=False, dry=False)
        self.out, self.err = out, err

    def run(self, argv, **kw):
        self.shown.setdefault(self.region, []).append(" ".join(map(str, argv)))
        return self.out, self.err


def expect(cond, what):
    if not cond:
        raise AssertionError(what)


def parsers():
    cases = drive_eval.run(Canned(DRIVE_EVAL_OUT, DRIVE_EVAL_ERR), ["--case", "vib0"])
    c = cases["vib0"]
    expect(c["median"] == "0.05" and c["label"] == "vibration 0 (turns)", f"drive_eval table: {c}")
    expect(c["flags"]["rest"] == "98.0" and c["flags"]["c0"] == "4.23", f"drive_eval flags: {c.get('flags')}")
    expect(c["hints"]["updates"] == "14204", f"drive_eval hints: {c.get('hints')}")
    expect(drive_eval.factor_range(c) == "2.3", f"drive_eval factor: {drive_eval.factor_range(c)}")
    expect(pages.time_v(TIME_V, "t") == (66.01, 2.6, 8000 / 1024), f"time -v: {pages.time_v(TIME_V, 't')}")
    expect(pages.FUZZ.search(FUZZ)["ref"] == "1900", "parser-fuzz line")
    expect(acquisition.LOOP.search(LOOP)["cpu"] == "0.59", "acquire_loop line")
    expect(odometry.COST.search(COST)["p999"] == "29.0", "stage bench line")
    expect(diagnosis.predicted(DIAG, "final") == 0.00197, "diagnose prediction")
    expect(diagnosis.rms(DIAG, "final") == 0.00249 and round(diagnosis.chi2_ratio(DIAG), 2) == 2.67, "diagnose lines")
    short = diagnosis.short_cases("drift\tbias drift\ttrue\tbias_drift\tfalse\t0.00257\n")
    expect(short == [{"name": "drift", "what": "bias drift", "same": True, "want": "bias_drift", "unexplained": False, "true": 0.00257}],
           f"short_pose_sessions lines: {short}")
    j = {"baseline": {"rms_mps2": 0.02}, "final": {"rms_mps2": 0.00351}, "selected_effect": "bias_drift", "unexplained_structure": False}
    expect(diagnosis.short_row(short[0], True, j)[4:7] == ["0.02000 -> 0.00351", "0.00257", "1.37"], f"short row: {diagnosis.short_row(short[0], True, j)}")
    line = "Live states arrived from CLOCK_MONOTONIC 1 to 2 ns (pids: replay 1, calibrate 2, odometry 3, subscriber 4). CPU over the 38 s replay (% of one core): a 1.0%"
    expect(pages.latency_line(line).startswith("CPU over the 38 s replay"), "latency line")
    md = pages.markdown("## Title\n\n| a | b |\n| --- | --- |\n| 1 | 2 |\n{\"json\": 1}\n", "t")
    expect(md.startswith("**Title**") and "json" not in md, f"markdown: {md!r}")
    expect(len(tables(md)) == 1, "tables")
    run_diagnose()
    two = "| a |\n|---|\n| 1 |\n| b | c |\n|---|---|\n| 2 | 3 |\n"
    expect([h for h, _ in tables(two)] == [["a"], ["b", "c"]], f"tables back to back: {tables(two)}")


def run_diagnose():
    """`mems-odometry diagnose` reports and the model edits of the diagnosis-run section."""
    model = "[accel]\nbias = [0.0, 0.0, 0.0]\n\n[gyro]\nbias = [0.0, 0.0, 0.0]\n"
    edited = run_diagnosis.set_key(model, [("gyro", "bias", "[1.0, 0.0, 0.0]")])
    expect(edited == "[accel]\nbias = [0.0, 0.0, 0.0]\n\n[gyro]\nbias = [1.0, 0.0, 0.0]\n", f"set_key: {edited!r}")
    report = {"before": {"end_error_m": 2.0, "truth_error_m": None}, "after": {"figures": {"end_error_m": 0.5}},
              "diagnosis": {"selected": [["accel_bias", [0.1, 0.0, 0.0]]]}, "confirmed": False, "unexplained": True}
    expect(run_diagnosis.before_after(report, "end_error_m", 2) == "2.00 -> 0.50", "before_after")
    expect(run_diagnosis.before_after(report, "truth_error_m") == "- -> -", "before_after without figures")
    expect(run_diagnosis.selected(report) == "accel_bias", "selected")
    lag = {"diagnosis": {"selected": [["accel_lag", [0.0183, 0.0, 0.0]]],
                         "scores": [{"candidate": "accel_lag", "sigma": [0.0008, 0.0, 0.0]}]}}
    expect(run_diagnosis.selected(lag) == "accel_lag 18.3 +- 0.8", f"selected lag: {run_diagnosis.selected(lag)}")
    expect(run_diagnosis.unexplained(report).startswith("yes (the rerun refutes"), "refuted")
    expect(run_diagnosis.declare("a = 1\n", ("a = 1", "a = 2")) == "a = 2\n", "declare by replacement")


def check(figures):
    """The region check: a page with an orphan region, a date and a commit fails; a clean one passes."""
    with tempfile.TemporaryDirectory() as d:
        page = Path(d) / "page.md"
        saved = figures.PAGES
        figures.PAGES = [page]
        try:
            page.write_text("Measured on 2026-11-25 at 07cb453.\n<!-- figures:orphan -->\nx\n<!-- /figures:orphan -->\n")
            problems = figures.check()
            expect(any("a date" in p for p in problems), f"no date found: {problems}")
            expect(any("a commit" in p for p in problems), f"no commit found: {problems}")
            expect(any("orphan has no section" in p for p in problems), f"no orphan found: {problems}")
            expect(any("is in no page" in p for p in problems), f"no missing region found: {problems}")
            page.write_text("<!-- figures:orphan -->\nx\n")
            expect(any("unclosed" in p for p in figures.check()), "an unclosed region passes")
        finally:
            figures.PAGES = saved


def run(figures):
    parsers()
    check(figures)
    print("figures --self-test: parsers and the region check behave")
