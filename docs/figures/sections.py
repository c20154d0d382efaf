"""The registry: every section of docs/figures.py, its page, its regions and its run time.

`estimate` is the full run's wall time on the 2-core development machine, extrapolated from
reduced runs (`--quick`) taken while four engineers' builds and tests kept its load average
near 9; the crates already built. A quiet machine takes less.
"""

import acquisition
import diagnosis
import odometry
import pages
import auto_profile
import rests
import run_diagnosis
from common import Context, Section  # noqa: F401  (Context: for docs/figures.py)


SECTIONS = {
    s.name: s
    for s in [
        Section("odometry-live", "odometry.md", ["odometry-live", "odometry-live-flags"], "21 min", odometry.live),
        Section("odometry-hindsight", "odometry.md", ["odometry-hindsight"], "8 min", odometry.hindsight),
        Section("odometry-perfect", "odometry.md", ["odometry-perfect"], "4 min", odometry.perfect),
        Section("odometry-variants", "odometry.md", ["odometry-variants"], "8 min", odometry.variants),
        Section("odometry-default-legs", "odometry.md", ["odometry-default-legs"], "4 min", odometry.default_legs),
        Section("odometry-budget", "odometry.md", ["odometry-budget"], "4 min", odometry.budget),
        Section("odometry-cost", "odometry.md", ["odometry-cost"], "2 min", odometry.cost),
        Section("odometry-faults", "odometry.md", ["odometry-faults"], "30 min", odometry.faults),
        Section("hints", "hints.md", ["hints-smooth-floor"], "9 min", odometry.hints),
    ]
    + pages.SECTIONS
    + auto_profile.SECTIONS
    + acquisition.SECTIONS
    + diagnosis.SECTIONS
    + run_diagnosis.SECTIONS
    + rests.SECTIONS
}
