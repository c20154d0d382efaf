#!/usr/bin/env bash
# Reruns the commands behind the docs' figures and writes their tables into the pages
# (docs/figures.py; sections as arguments, all by default; --list, --check, --quick).
set -euo pipefail
exec python3 "$(dirname "$0")/figures.py" "$@"
