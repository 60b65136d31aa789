"""Which committed ``c-cma-es`` study runs restarted: the runs that a change acting only at a restart
(``keep_best``, ``restart_baseline_loss``) would change, and what recomputing them costs.

    python benchmarks/restart_inventory.py            # counts and recorded seconds per study
    python benchmarks/restart_inventory.py --list     # and every run's file

Runs whose options set ``restarts``, ``keep_best`` or ``restart_baseline_loss`` are left out (a new default
does not reach them). The contextual BBO study records each run's restarts and the kick study's checkpoints
hold ``restarts_done``. The documents of the function, scaling and C-CMA-ES studies record neither: a run
*certainly* restarted when its optimiser stopped it (the criteria fire only once the restarts are used up),
and *probably* when its curve climbs back by more than :data:`JUMP` over its lowest value so far, to within
1/100 of its first value (a restart goes back to the initial distribution). Others may have restarted
unseen, so their counts are lower bounds. The cost is the runs' recorded ``seconds``.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from creps_gym.optimizers.state_files import load_state

__all__ = ["climbs_back", "inventory", "main", "summary"]

HERE = Path(__file__).resolve().parent
PINNED = {"restarts", "keep_best", "restart_baseline_loss"}
JUMP = 1e3
CURVE_STUDIES = ("functions", "scaling", "ccmaes")


def climbs_back(values: Sequence[float | None]) -> bool:
    """True when a curve climbs back by more than :data:`JUMP` times its lowest value so far, to within
    1/100 of its first value."""
    curve = np.abs(np.asarray([v for v in values if v is not None], dtype=np.float64))
    if curve.size < 3:
        return False
    lowest = np.minimum.accumulate(curve)
    return bool(np.any((curve[1:] > JUMP * lowest[:-1]) & (curve[1:] > 1e-2 * curve[0])))


def _curve_study(study: str) -> list[tuple[str, str, float]]:
    rows = []
    for path in sorted((HERE / study / "runs").rglob("*.json")):
        if "partial" in path.parts:
            continue
        document = json.loads(path.read_text(encoding="utf-8"))
        spec = document.get("spec", {})
        if spec.get("method") != "c-cma-es" or PINNED & {name for name, _ in spec.get("options", [])}:
            continue
        if str(document.get("stop_reason")).startswith("optimizer:"):
            rows.append(("certain", str(path.relative_to(HERE)), float(document["seconds"])))
        elif climbs_back(document["values"]):
            rows.append(("probable", str(path.relative_to(HERE)), float(document["seconds"])))
    return rows


def _recorded_studies() -> list[tuple[str, str, float]]:
    rows = []
    for path in sorted((HERE / "contextual_bbo" / "runs").rglob("*.json")):
        document = json.loads(path.read_text(encoding="utf-8"))
        if PINNED & set(document["spec"].get("options", {})) or document["spec"]["method"] != "c-cma-es":
            continue
        if document.get("restarts", 0) > 0:
            rows.append(("recorded", str(path.relative_to(HERE)), float(document["seconds"])))
    for path in sorted((HERE / "kick" / "results").glob("*/runs/*/c-cma-es-trial*.npz")):
        state = load_state(path)  # the project's checkpoint reader: bounded, never unpickles
        if state.get("restarts_done", 0) > 0:
            seconds = json.loads(path.with_suffix(".json").read_text(encoding="utf-8"))[
                "seconds_last_session"
            ]
            rows.append(("recorded", str(path.relative_to(HERE)), float(seconds)))
    return rows


def inventory() -> dict[str, list[tuple[str, str, float]]]:
    """study -> [(how it is known, file, recorded seconds)] of the runs that restarted."""
    found: dict[str, list[tuple[str, str, float]]] = defaultdict(list)
    for study in CURVE_STUDIES:
        found[study] = _curve_study(study)
    for row in _recorded_studies():
        found[row[1].split("/")[0]].append(row)
    return dict(found)


def summary(found: dict[str, list[tuple[str, str, float]]]) -> str:
    """One line per study and kind: runs and their recorded seconds; then the total."""
    lines = []
    for study, rows in found.items():
        for kind in ("certain", "probable", "recorded"):
            chosen = [seconds for how, _, seconds in rows if how == kind]
            if chosen:
                lines.append(f"{study}: {len(chosen)} runs {kind}, {sum(chosen):,.0f} s recorded")
    total = [seconds for rows in found.values() for _, _, seconds in rows]
    lines.append(f"total: {len(total)} runs, {sum(total):,.0f} s recorded")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Print the inventory."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--list", action="store_true", help="print every run's file")
    args = parser.parse_args(argv)
    found = inventory()
    print(summary(found))
    if args.list:
        for rows in found.values():
            for how, name, seconds in rows:
                print(f"{how}\t{seconds:.1f}\t{name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
