r"""Carry the committed runs over four default changes: issue 45's ``ridge_centre`` "zero" → "old" of
``c-cma-es``, c-bo's refit data (2026-11-30: ``fit_points`` 256 → 1024, ``fit_subset`` "recent" →
"spread"), c-bo's log transform scale (2026-11-30: ``log_quantile`` 0.5 → 0.25) and MES's floor
(2026-11-30: ``mes_floor`` "candidates" → "observed").

Every committed run of ``c-cma-es`` or ``c-cma-es-surrogate`` that does not set ``ridge_centre`` was
computed with C3, the default until issue 45. The studies pin those columns to ``ridge_centre="zero"``
(their column definitions add it: :func:`benchmarks.study_options.pin_c3`), so their committed runs stay
the runs of their specs and render as before; the new default's runs are measured beside them
(``benchmarks/default_trial.py``, and the C3r columns of the
contextual BBO and contexts studies). Likewise every committed ``c-bo`` run (the low-budget study's c-bo
columns, on its own GP and on the libraries') was computed with the refits on the 256 most recent
episodes, the log transform's scale at the median gap and MES's floor over the candidates: its columns carry
:data:`~benchmarks.study_options.CBO_PINS`; ``benchmarks/low_budget/refit_data.py`` and
``benchmarks/low_budget/recommenders.py --options`` measure the new defaults beside them.
This script writes the pin into each such document:

    python benchmarks/pin_defaults.py            # list what it would change
    python benchmarks/pin_defaults.py --write    # change it (run again: nothing left to change)

* the function, C-CMA-ES and scaling studies key a run by its options: the document's ``spec.options`` gets
  the pin and the file is renamed to the pinned spec's key;
* the contextual BBO study keys a run by its column's label: the options get the pin and an empty label
  becomes the method's name, so the key stays;
* the low-budget study records the column's options (``method.options``): they get the pin of the
  run's optimiser (:data:`LOW_BUDGET_PINS`), the file names stay; the kick study records its setting's
  options (``options``, ``setting.options``, in the result and in its history file): they get the pin, the
  file names stay. The kick's optimiser checkpoints have no ``ridge_centre`` field and load as C3
  (``FORMER_ABSENT`` of :mod:`creps_gym.optimizers.ccmaes_config`).

The contexts study stores no options per run; its column definitions carry the pin.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

if not __package__:  # run by path: the repository root first on sys.path (see benchmarks/__init__.py)
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from benchmarks.study_options import C3_METHODS, C3_PIN, CBO_PINS, options_dict, pin_c3
from benchmarks.study_tools import RunSpec, load_document, store_document

__all__ = ["main", "pinned", "plan"]

HERE = Path(__file__).resolve().parent
KEYED_BY_OPTIONS = ("functions", "ccmaes", "scaling")
#: The low-budget study's pins by optimiser: C3 for C-CMA-ES and ``CBO_PINS`` for c-bo (its columns on
#: BoTorch's and scikit-learn's GP too), each added where the run's options do not set all of it (an option
#: the run sets keeps its value).
LOW_BUDGET_PINS = {**{name: C3_PIN for name in C3_METHODS}, "c-bo": CBO_PINS}


def _documents(folder: Path) -> Iterator[Path]:
    for path in sorted(folder.rglob("*.json")):
        if "partial" not in path.parts and not path.is_symlink():
            yield path


def pinned(study: str, path: Path, document: dict[str, Any]) -> tuple[Path, dict[str, Any]] | None:
    """The path and document of ``document`` (at ``path``, in ``study``) with the pin, or None if it needs
    none."""
    if study in KEYED_BY_OPTIONS or study == "contextual_bbo":
        spec = document.get("spec", {})
        old = options_dict(spec.get("options"))
        new = dict(pin_c3(spec.get("method", ""), old))
        if new == old:
            return None
        if study == "contextual_bbo":
            new_spec = dict(spec, options=new, label=spec.get("label") or spec["method"])
            return path, {**document, "spec": new_spec}
        new_spec = dict(spec, options=[list(pair) for pair in new.items()])
        key = RunSpec(**dict(spec, options=tuple(new.items()))).key
        return path.with_name(f"{key}.json"), {**document, "spec": new_spec}
    if study == "low_budget":
        method = document.get("method", {})
        pin = LOW_BUDGET_PINS.get(method.get("optimizer"))
        options = method.get("options", {})
        if pin is None or all(name in options for name, _ in pin):
            return None
        return path, {**document, "method": {**method, "options": {**dict(pin), **options}}}
    if study == "kick":
        name = document.get("name") or path.name.split("-trial")[0]
        setting = document.get("setting", {})
        if name not in C3_METHODS or "options" not in setting or "ridge_centre" in setting["options"]:
            return None  # another method, a selector's state (no setting), or a C3r run
        options = dict(pin_c3(name, setting["options"]))
        new = {**document, "setting": {**setting, "options": options}}
        if "options" in document:
            new["options"] = options
        return path, new
    raise ValueError(f"study: expected one of {(*KEYED_BY_OPTIONS, 'contextual_bbo', 'low_budget', 'kick')}")


def plan(study: str) -> list[tuple[Path, Path, dict[str, Any]]]:
    """(old path, new path, new document) of every committed document of ``study`` the pin changes."""
    folder = HERE / study / ("results" if study == "kick" else "runs")
    changes = []
    for path in _documents(folder):
        if study == "kick" and "-trial" not in path.name:
            continue
        document = load_document(path)
        if document is None:
            raise ValueError(f"{path}: expected a JSON document, got an unreadable file")
        change = pinned(study, path, document)
        if change is not None:
            changes.append((path, *change))
    return changes


def main(argv: Sequence[str] | None = None) -> int:
    """List, or with ``--write`` make, the pin's changes in every study."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", action="store_true", help="change the documents (default: list them)")
    args = parser.parse_args(argv)
    for study in (*KEYED_BY_OPTIONS, "contextual_bbo", "low_budget", "kick"):
        changes = plan(study)
        for old, new, document in changes:
            if args.write:
                if new != old and new.exists():
                    raise ValueError(f"{new}: expected no document under the pinned key, found one")
                store_document(new, document)
                if new != old:
                    old.unlink()
        verb = "pinned" if args.write else "would pin"
        renamed = sum(new != old for old, new, _ in changes)
        print(f"{study}: {verb} {len(changes)} documents ({renamed} renamed)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
