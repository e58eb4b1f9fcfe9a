"""Run every ``benchmarks/bench_*.py`` module's ``main()`` in name order, then the summary.

Each figure with a target is marked OK or MISS (benchmarks.verdict); the last line counts
them. Exit status 0 whatever the figures (benchmarks are not tests); a benchmark that
cannot run is reported as ERROR in the summary and the others still run.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys

import benchmarks
from benchmarks import verdict


def main(argv: list[str]) -> int:
    """Arguments before the first option select benchmarks by substring of their module
    name; the options after them are the benchmarks' own (``faults --seconds 20``: their
    values select nothing)."""
    names = sorted(m.name for m in pkgutil.iter_modules(benchmarks.__path__)
                   if m.name.startswith("bench_"))
    first_option = next((i for i, a in enumerate(argv) if a.startswith("-")), len(argv))
    selectors = argv[:first_option]
    if selectors:
        names = [n for n in names if any(a in n for a in selectors)]
    for name in names:
        try:
            module = importlib.import_module(f"benchmarks.{name}")
            module.main()
        except Exception as exc:  # reported in the summary; the rest still run
            print(verdict.error(name, exc))
        print()
    print(verdict.summary())
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
