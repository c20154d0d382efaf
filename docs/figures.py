#!/usr/bin/env python3
"""Reruns the commands behind the figures of docs/*.md and README.md and writes their tables.

A page's figures live in generated regions:

    <!-- figures:NAME -->
    ... written by this script: the table(s), the command(s) that produced them, the machine ...
    <!-- /figures:NAME -->

Each region belongs to one section of this script (a section may write several regions); the
section runs its commands, parses their output (markdown tables, `--json` documents or stderr
summary lines) and replaces the regions' contents. Prose around the regions is hand-written and
states no figure that a region does not show.

Usage (from anywhere; `docs/figures.sh` is the same):

    docs/figures.py                  # every section, writing the pages
    docs/figures.py SECTION ...      # only these sections
    docs/figures.py --list           # sections, their regions and expected full-run time
    docs/figures.py --quick SECTION  # a reduced run (fewer seeds, shorter runs), printed, not written
    docs/figures.py --check          # no run: every region has a section and every section's
                                     # regions exist; no page carries a date or a commit hash
    docs/figures.py --self-test      # the output parsers and the check on hand-made input

Each command is printed with its wall time. A failing command stops the script with its exit
status and stderr; no region is written for a section unless all of its commands succeeded
(each section's regions are written together, once its commands are done). The machine's
conditions (cores, load average before and after) are written into each region; no date and no
commit.
"""

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "figures"))

import sections  # noqa: E402  (docs/figures/sections.py: the registry)
from common import REPO, Failed  # noqa: E402

PAGES = sorted((REPO / "docs").glob("*.md")) + [REPO / "README.md"]
REGION = re.compile(r"<!-- figures:([a-z0-9-]+) -->\n(.*?)<!-- /figures:([a-z0-9-]+) -->\n", re.S)
# A date (2026-11-25) or "at <7+ hex digits>" / "on <hex>" / "commit <hex>", as dated lab notes
# carry them; also a bare 7-40 digit hex word that holds a digit and a letter.
# Years 2020-2029 only: a fact such as the 32-bit time limit (2038-01-19) is no lab note.
DATE = re.compile(r"\b202[0-9]-[01][0-9]-[0-3][0-9]\b")
COMMIT = re.compile(r"\b(?:at|on|commit|of)\s+[0-9a-f]{7,40}\b")


def rel(page):
    """A page's path as shown in messages: relative to the repository when inside it."""
    return page.relative_to(REPO) if page.is_relative_to(REPO) else page


def regions(text):
    """The (name, body) of every generated region of a page's text, in order."""
    out = []
    for m in REGION.finditer(text):
        if m.group(1) != m.group(3):
            raise Failed(f"region {m.group(1)} closed as {m.group(3)}")
        out.append((m.group(1), m.group(2)))
    return out


def page_regions():
    """Region name -> page path, over every page; a name used twice is an error."""
    where = {}
    for page in PAGES:
        text = page.read_text()
        opened = re.findall(r"<!-- figures:([a-z0-9-]+) -->", text)
        found = [n for n, _ in regions(text)]
        if sorted(opened) != sorted(found):
            raise Failed(f"{rel(page)}: unclosed or malformed region among {opened}")
        for name in found:
            if name in where:
                raise Failed(f"region {name} is in {where[name]} and {rel(page)}")
            where[name] = page
    return where


def check():
    """Problems with the regions and the pages' dates and commits, as strings (empty: fine)."""
    problems = []
    try:
        where = page_regions()
    except Failed as e:
        return [str(e)]
    owned = {}
    for s in sections.SECTIONS.values():
        for r in s.regions:
            if r in owned:
                problems.append(f"region {r} belongs to sections {owned[r]} and {s.name}")
            owned[r] = s.name
            if r not in where:
                problems.append(f"section {s.name}: region {r} is in no page")
            elif where[r].name != s.page:
                problems.append(f"section {s.name}: region {r} is in {where[r].name}, not {s.page}")
    for r, page in where.items():
        if r not in owned:
            problems.append(f"{rel(page)}: region {r} has no section in docs/figures")
    for page in PAGES:
        for i, line in enumerate(page.read_text().splitlines(), 1):
            for pattern, what in ((DATE, "a date"), (COMMIT, "a commit")):
                m = pattern.search(line)
                if m:
                    problems.append(f"{rel(page)}:{i}: {what} ({m.group(0)!r})")
    return problems


def conditions(started_load, seconds):
    """The machine line written into each region: cores, load average, wall time."""
    load = os.getloadavg()[0]
    return (
        f"{os.cpu_count()} cores, load average {started_load:.1f} at the start and {load:.1f} at "
        f"the end, {seconds / 60:.0f} min for the section"
        if seconds >= 90
        else f"{os.cpu_count()} cores, load average {started_load:.1f} at the start and {load:.1f} "
        f"at the end, {seconds:.0f} s for the section"
    )


def region_text(body, commands, machine):
    """A region's full contents: the body, the commands that produced it, the machine."""
    shown = "\n".join("    " + line for c in commands for line in c.splitlines())
    return (
        "<!-- generated by docs/figures.sh; edit docs/figures/, not this region -->\n"
        f"{body.rstrip()}\n\nProduced by `docs/figures.sh` running:\n\n{shown}\n\n({machine}.)\n"
    )


def write(page, texts):
    """Replaces the named regions of a page by their new text."""
    text = page.read_text()

    def sub(m):
        name = m.group(1)
        if name not in texts:
            return m.group(0)
        return f"<!-- figures:{name} -->\n{texts[name]}<!-- /figures:{name} -->\n"

    page.write_text(REGION.sub(sub, text))


def run_section(s, quick, dry):
    """Runs one section; writes its regions unless quick (then prints them)."""
    print(f"== {s.name} ({s.page}; full run about {s.estimate})", flush=True)
    load = os.getloadavg()[0]
    t0 = time.monotonic()
    ctx = sections.Context(quick=quick, dry=dry)
    bodies = s.generate(ctx)
    if dry:
        return
    machine = conditions(load, time.monotonic() - t0)
    missing = set(s.regions) - set(bodies)
    if missing:
        raise Failed(f"section {s.name} produced no text for {sorted(missing)}")
    texts = {r: region_text(bodies[r], ctx.shown_for(r), machine) for r in s.regions}
    if quick:
        for r, t in texts.items():
            print(f"<!-- figures:{r} -->\n{t}<!-- /figures:{r} -->")
        return
    write(REPO / "docs" / s.page if s.page != "README.md" else REPO / s.page, texts)
    print(f"   wrote {', '.join(s.regions)} in {s.page}", flush=True)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("sections", nargs="*", help="sections to run (default: all)")
    p.add_argument("--check", action="store_true", help="check regions and pages, run nothing")
    p.add_argument("--list", action="store_true", help="list sections and their regions")
    p.add_argument("--quick", action="store_true", help="reduced runs, printed, pages untouched")
    p.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    p.add_argument("--self-test", action="store_true", help="the parsers and the check on hand-made input")
    a = p.parse_args()
    if a.self_test:
        import selftest

        selftest.run(sys.modules[__name__])
        return
    if a.check:
        problems = check()
        for x in problems:
            print(f"figures --check: {x}", file=sys.stderr)
        if problems:
            sys.exit(1)
        print(f"figures --check: {len(sections.SECTIONS)} sections, regions and pages consistent")
        return
    if a.list:
        total = 0.0
        for s in sections.SECTIONS.values():
            print(f"{s.name:24} {s.page:18} about {s.estimate:10} {', '.join(s.regions)}")
            n, unit = s.estimate.split()
            total += float(n) * (60 if unit == "min" else 1)
        print(f"all sections: about {total / 3600:.1f} h")
        return
    unknown = [n for n in a.sections if n not in sections.SECTIONS]
    if unknown:
        sys.exit(f"figures: unknown section(s) {unknown}; --list shows them")
    problems = check()
    if problems and not a.quick:
        for x in problems:
            print(f"figures: {x}", file=sys.stderr)
        sys.exit("figures: fix the regions first (--check)")
    chosen = a.sections or list(sections.SECTIONS)
    t0 = time.monotonic()
    try:
        for name in chosen:
            run_section(sections.SECTIONS[name], a.quick, a.dry_run)
    except Failed as e:
        sys.exit(f"figures: FAILED: {e}")
    print(f"figures: {len(chosen)} section(s) in {(time.monotonic() - t0) / 60:.1f} min")


if __name__ == "__main__":
    main()
