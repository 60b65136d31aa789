"""Compare the run documents of two study caches: which runs are bit-identical and where the others part.

A study's ``--quick`` recomputes its runs; computed into another cache (``--cache DIR --out DIR``), its
documents can be set against the committed ones:

    python benchmarks/functions/run.py --quick --functions Sphere --context-dims 1 --seeds 1 \\
        --cache /tmp/sphere --out /tmp/sphere-out
    python benchmarks/compare_runs.py benchmarks/functions/runs/quick /tmp/sphere

For every run in the second cache that the first one has too, one line: ``same`` (the curve and the hit are
bit-identical) or where the curves part (the first differing point, its relative difference) and the hit
and final value of each; then the count of identical runs and each side's provenance.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

# Run by path: the repository root first on sys.path, as `python -m` puts it (see benchmarks/__init__.py).
if not __package__:
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from benchmarks.provenance import provenance_text

__all__ = ["compare", "main"]


def compare(first: dict, second: dict) -> str:
    """One line on two documents of the same run: ``same``, or where their curves part."""
    a, b = first["values"], second["values"]
    if a == b and first["episodes"] == second["episodes"] and first["hit"] == second["hit"]:
        return "same"
    part = next((i for i, (x, y) in enumerate(zip(a, b, strict=False)) if x != y), min(len(a), len(b)))
    text = f"differ from curve point {part} of {len(a)}"
    if part < min(len(a), len(b)) and None not in (a[part], b[part]) and a[part] != 0:
        text += f" (relative difference {abs(a[part] - b[part]) / abs(a[part]):.1e})"
    finals = " / ".join("none" if d["final"] is None else f"{d['final']:.6g}" for d in (first, second))
    return text + f"; hit {first['hit']} / {second['hit']}, final {finals}"


def main(argv: Sequence[str] | None = None) -> int:
    """Print the comparison of the caches ``first`` and ``second``; 0 if every shared run is the same."""
    parser = argparse.ArgumentParser(description="Compare the run documents of two study caches.")
    parser.add_argument("first", type=Path, help="a cache, e.g. benchmarks/functions/runs/quick")
    parser.add_argument("second", type=Path, help="another cache with some of the same runs")
    args = parser.parse_args(argv)
    shared = sorted(p.name for p in args.second.glob("*.json") if (args.first / p.name).exists())
    if not shared:
        print(f"no run of {args.second} is in {args.first}")
        return 2
    documents = [[json.loads((c / name).read_text()) for name in shared] for c in (args.first, args.second)]
    same = 0
    for name, first, second in zip(shared, *documents, strict=True):
        line = compare(first, second)
        same += line == "same"
        print(f"{name.removesuffix('.json')}: {line}")
    print(f"{same} of {len(shared)} runs bit-identical")
    for cache, docs in zip((args.first, args.second), documents, strict=True):
        print(f"\n{cache}: " + provenance_text(d.get("provenance") for d in docs))
    return 0 if same == len(shared) else 1


if __name__ == "__main__":
    raise SystemExit(main())
