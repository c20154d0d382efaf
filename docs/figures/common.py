"""What every section of docs/figures.py uses: running commands, reading and writing tables."""

import re
import shlex
from dataclasses import dataclass
from typing import Callable
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent.parent


@dataclass
class Section:
    """One section: the page it writes, its regions, its full run's wall time on the 2-core
    development machine with nothing else running, and the function that runs it (a Context
    in, region name -> region body out)."""

    name: str
    page: str
    regions: list
    estimate: str
    generate: Callable


class Failed(Exception):
    """A command failed or its output was not what the section expects; nothing is written."""


class Context:
    """One section's run: quick or full, the commands run (shown in the regions)."""

    def __init__(self, quick, dry):
        self.quick = quick
        self.dry = dry
        self.shown = {}
        self.region = None

    def shown_for(self, region):
        """The commands run for a region: those tagged with it, else all of the section's."""
        tagged = self.shown.get(region)
        if tagged:
            return tagged
        return [c for cmds in self.shown.values() for c in cmds]

    def run(self, argv, timeout=None, stdin=None, shown=None):
        """Runs argv from the repository root; (stdout, stderr); Failed on a non-zero exit.
        `shown` is how the command is written in the region (default: argv, quoted)."""
        shown = shown or " ".join(shlex.quote(a) for a in argv)
        self.shown.setdefault(self.region, []).append(shown)
        print(f"   $ {shown}", flush=True)
        if self.dry:
            return "", ""
        t0 = time.monotonic()
        try:
            p = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, timeout=timeout, stdin=stdin)
        except subprocess.TimeoutExpired:
            raise Failed(f"{shown}: no result within {timeout} s")
        except OSError as e:
            raise Failed(f"{shown}: {e}")
        print(f"     {time.monotonic() - t0:.1f} s, exit {p.returncode}", flush=True)
        if p.returncode != 0:
            sys.stderr.write(p.stderr[-4000:])
            raise Failed(f"{shown}: exit status {p.returncode}")
        return p.stdout, p.stderr

    def cargo_example(self, package, example, args, **kw):
        """`cargo run --release -p PACKAGE --example EXAMPLE -- ARGS`."""
        argv = ["cargo", "run", "--release", "-q", "-p", package, "--example", example, "--"]
        return self.run(argv + [str(a) for a in args], **kw)

    def shell(self, script):
        """Runs a bash script (`set -euo pipefail` first) from the repository root; shown as
        the script itself."""
        script = script.strip()
        return self.run(["bash", "-c", "set -euo pipefail\n" + script], shown=script)


def tables(text):
    """Every markdown table in text: a list of (header cells, rows of cells). Two tables
    printed without a line between them are two tables (a separator row starts a new one)."""
    out, block = [], []

    def close(rows):
        if len(rows) >= 2 and is_separator(rows[1]):
            out.append((rows[0], rows[2:]))

    for line in text.splitlines() + [""]:
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if is_separator(cells) and len(block) >= 3:
                close(block[:-1])
                block = block[-1:]
            block.append(cells)
            continue
        close(block)
        block = []
    return out


def is_separator(cells):
    """Whether a row's cells are a markdown table's header separator (`---`, `:--`)."""
    return all(c and set(c) <= set("-: ") for c in cells)


def table(header, rows):
    """A markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def one_table(text, what):
    """The single (or first) table of a command's output; Failed if there is none."""
    found = tables(text)
    if not found:
        raise Failed(f"{what}: no table in its output")
    return found[0]


def number(pattern, text, what):
    """The float captured by pattern's first group in text; Failed when absent."""
    m = re.search(pattern, text)
    if not m:
        raise Failed(f"{what}: no match for {pattern!r} in its output")
    return float(m.group(1))


def lines_after_table(text):
    """The non-empty lines that follow the last table of text (a command's summary lines)."""
    lines = text.splitlines()
    last = max((i for i, l in enumerate(lines) if l.startswith("|")), default=-1)
    return [l for l in lines[last + 1 :] if l.strip()]
