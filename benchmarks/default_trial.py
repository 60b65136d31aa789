r"""Measure a candidate default of ``c-cma-es`` on a study's committed runs, cell by cell (issue 45).

A default changes every ``c-cma-es`` run of every study, so before it changes the candidate is run on each
study's own specs and compared with the current default there, seed by seed. This script does that for the
studies whose runs are :class:`~benchmarks.study_tools.RunSpec` runs through the runner (``functions``,
``ccmaes``, ``scaling``; the contextual BBO protocol has its own option columns):

    python benchmarks/default_trial.py run --study functions --options '{"ridge_centre": "old"}'
    python benchmarks/default_trial.py run --study scaling --options '{"ridge_centre": "old"}' \
        --base-options '{"keep_best": false, "restart_baseline_loss": "squared"}'

Issue 45 measured C3r (``ridge_centre="old"``) so, then made it the default and pinned the committed runs
to C3 (``benchmarks/pin_defaults.py``): its comparisons are rendered against the pinned columns,

    python benchmarks/default_trial.py render --study functions --options '{"ridge_centre": "old"}' \
        --base-options '{"ridge_centre": "zero"}'

(the scaling study's base: ``{"keep_best": false, "restart_baseline_loss": "squared", "ridge_centre":
"zero"}``).

* ``run`` computes, for every committed document of the study's default column (method ``c-cma-es``, no
  options, no divergence rule; or the column whose options are ``--base-options``, as the scaling study's
  ``c-cma-es`` pinned to the restarts before issue 33), the same spec with ``--options`` added, through the
  study's own worker and into its own cache folder (so the study resumes, and its key records the options).
  It first brings that column itself to the current code where it can have changed (see :func:`stale`;
  ``--no-refresh`` leaves it).
* ``render`` pairs each default document with its trial and writes ``docs/results/default_trial/
  <study>-<label>.json`` (the cells, each run's provenance) and ``.md`` (the table, rendered from that
  JSON; a test renders it again).

**Which default documents the current code can change.** Issue 45's C12 gates a restart on the budget:
a search that stops at E episodes restarts only if the B − E episodes left are at least the E_search it
took. A run that hit its target at H ≤ B/2 restarted, if at all, at some E ≤ H ≤ B/2 with E_search ≤ E,
so B − E ≥ E ≥ E_search: C12 allowed every one of its restarts and the run is the same, bit for bit. Only
the runs that missed the target or hit it after B/2 can differ; ``--refresh`` recomputes those.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import statistics
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if not __package__:  # run by path: the repository root first on sys.path (see benchmarks/__init__.py)
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from benchmarks.study_cli import json_object
from benchmarks.study_options import options_dict
from benchmarks.study_tools import RunSpec, load_document, store_document, write_text

__all__ = [
    "METHOD",
    "STUDIES",
    "cells",
    "default_documents",
    "label_of",
    "main",
    "outcome",
    "render_markdown",
    "run_trial",
    "stale",
    "trial_spec",
]

HERE = Path(__file__).resolve().parent
OUT = HERE.parent / "docs" / "results" / "default_trial"
METHOD = "c-cma-es"
STUDIES = ("functions", "ccmaes", "scaling")
#: The spec fields that name a cell (every field but the seed).
CELL_FIELDS = ("function", "dim", "context_dim", "budget", "samples", "eval_contexts", "initial")


def default_documents(
    folder: Path, base: dict[str, Any] | None = None, match: str = ""
) -> list[tuple[Path, dict[str, Any]]]:
    """The documents of ``folder`` (not its subfolders) in the ``c-cma-es`` column whose options are ``base``
    (None or {}: the default column), without a divergence rule, whose file name the regular expression
    ``match`` finds, sorted by name."""
    found = []
    for path in sorted(folder.glob("*.json")):
        if not re.search(match, path.name):
            continue
        document = load_document(path) if not path.is_symlink() else None
        spec = (document or {}).get("spec", {})
        if spec.get("method") == METHOD and spec.get("divergence") is None:
            if options_dict(spec.get("options")) == (base or {}):
                found.append((path, document))
    return found


def stale(document: dict[str, Any]) -> bool:
    """Whether C12 can have changed the run (see the module docstring): it missed or hit after B/2."""
    hit = document.get("hit")
    return hit is None or hit > document["spec"]["budget"] / 2


def trial_spec(spec: dict[str, Any], options: dict[str, Any]) -> RunSpec:
    """The run of ``spec`` (a document's) with ``options`` added to its optimiser options."""
    fields = {name: value for name, value in spec.items() if name != "options"}
    return RunSpec(**fields, options=tuple(sorted({**options_dict(spec.get("options")), **options}.items())))


def label_of(options: dict[str, Any]) -> str:
    """The file label of a set of options, as the study's keys write them (``name=value`` joined by ``-``)."""
    if not options:
        raise ValueError("options: expected at least one option for a trial, got {}")
    return "-".join(f"{name}={value}" for name, value in sorted(options.items()))


def outcome(document: dict[str, Any]) -> tuple[float, float]:
    """A run's rank key, smaller better: the episodes to the target (inf for a miss), then the final value."""
    hit = document.get("hit")
    return (math.inf if hit is None else float(hit), float(document["final"]))


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None  # a median run that missed: JSON's null


def _cell(pairs: list[tuple[dict[str, Any], dict[str, Any]]]) -> dict[str, Any]:
    base = [outcome(b) for b, _ in pairs]
    trial = [outcome(t) for _, t in pairs]
    both = [(b[0], t[0]) for b, t in zip(base, trial, strict=True) if math.isfinite(b[0] + t[0])]
    return {
        "runs": len(pairs),
        "hits": [sum(math.isfinite(o[0]) for o in base), sum(math.isfinite(o[0]) for o in trial)],
        "median_episodes": [_finite(statistics.median(o[0] for o in runs)) for runs in (base, trial)],
        "median_final": [statistics.median(o[1] for o in runs) for runs in (base, trial)],
        "better": sum(t < b for b, t in zip(base, trial, strict=True)),
        "worse": sum(t > b for b, t in zip(base, trial, strict=True)),
        "log_ratio_sum": sum(math.log(t / b) for b, t in both),
        "both_hit": len(both),
    }


def cells(
    folder: Path, options: dict[str, Any], base: dict[str, Any] | None = None
) -> tuple[list[dict[str, Any]], list[Any]]:
    """The cells of the study in ``folder``: each default run paired with its trial (runs without a trial
    yet are left out), and the distinct provenance records of the documents used."""
    grouped: dict[tuple[Any, ...], list[tuple[dict[str, Any], dict[str, Any]]]] = {}
    provenance: list[Any] = []
    for _, document in default_documents(folder, base):
        trial = load_document(folder / f"{trial_spec(document['spec'], options).key}.json")
        if trial is None:
            continue
        key = tuple(document["spec"][name] for name in CELL_FIELDS)
        grouped.setdefault(key, []).append((document, trial))
        for record in (document.get("provenance"), trial.get("provenance")):
            if record not in provenance:
                provenance.append(record)
    rows = [
        dict(zip(CELL_FIELDS, key, strict=True), **_cell(pairs)) for key, pairs in sorted(grouped.items())
    ]
    return rows, provenance


def _episodes(value: float | None, budget: int) -> str:
    return f"> {budget:,}" if value is None else f"{value:,.0f}"


def render_markdown(summary: dict[str, Any]) -> str:
    """The table of a trial's summary (the JSON ``render`` writes)."""
    rows = summary["cells"]
    base = summary.get("base") or {}
    column = f"the column `{label_of(base)}`" if base else "the default column"
    command = f"--study {summary['study']} --options '{json.dumps(summary['options'], sort_keys=True)}'"
    command += f" --base-options '{json.dumps(base, sort_keys=True)}'" if base else ""
    lines = [
        f"# `{METHOD}` with `{label_of(summary['options'])}` against {column}: the {summary['study']} study",
        "",
        f"Rendered by `benchmarks/default_trial.py render {command}` from the study's runs (`benchmarks/"
        f"{summary['study']}/runs/`). Per cell (the study's spec but the seed): the runs paired by seed, "
        "how many hit the target, the median episodes to it (a miss counts as more than the budget), the "
        "median final value (regret, or f for the unbounded functions), and in how many seeds the trial "
        "ranks better or worse (fewer episodes to the target, then a smaller final value).",
        "",
        "| function | p | z | N | budget | initial | runs | hits (base, trial) "
        "| median episodes (base) | median episodes (trial) | median final (base) "
        "| median final (trial) | better | worse |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for row in rows:
        base, trial = row["median_episodes"]
        final = row["median_final"]
        lines.append(
            f"| {row['function']} | {row['dim']} | {row['context_dim']} | {row['samples']} "
            f"| {row['budget']:,} | {row['initial']} | {row['runs']} | {row['hits'][0]}, {row['hits'][1]} "
            f"| {_episodes(base, row['budget'])} | {_episodes(trial, row['budget'])} "
            f"| {final[0]:.2e} | {final[1]:.2e} | {row['better']} | {row['worse']} |"
        )
    both = sum(row["both_hit"] for row in rows)
    ratio = math.exp(sum(row["log_ratio_sum"] for row in rows) / both) if both else 1.0
    pairs = sum(row["runs"] for row in rows)
    partial = summary.get("base_runs", pairs) - pairs
    if partial:
        lines += [
            "",
            f"**Partial: {partial} of the column's {summary['base_runs']} runs have no trial yet.**",
        ]
    mean = f"{ratio:.3f}" if both else "—"
    lines += [
        "",
        f"In all: {pairs} pairs in {len(rows)} cells; the trial ranks better in "
        f"{sum(row['better'] for row in rows)} and worse in {sum(row['worse'] for row in rows)}; it hits the "
        f"target in {sum(row['hits'][1] for row in rows)} runs against the base column's "
        f"{sum(row['hits'][0] for row in rows)}; over the {both} pairs where both hit, the geometric mean of "
        f"the trial's episodes to the target over the base column's is {mean}.",
        "",
    ]
    return "\n".join(lines)


def run_trial(
    folder: Path,
    options: dict[str, Any],
    workers: int = 1,
    refresh: bool = True,
    base: dict[str, Any] | None = None,
    match: str = "",
) -> int:
    """Compute the trial of every default document in ``folder`` (cached ones are kept); with ``refresh``
    first compute the :func:`stale` default documents again, keeping each one's file where its values and
    final value come out the same (so only a changed run changes its file). Returns how many changed."""
    from benchmarks.study_runner import run_all

    documents = default_documents(folder, base, match)
    changed = 0
    if refresh:
        old = {
            RunSpec(**document["spec"]): (path, document) for path, document in documents if stale(document)
        }
        print(f"refreshing {len(old)} default documents that C12 can have changed")
        after = run_all(list(old), folder, workers=workers, recompute=True)
        for (path, document), new in zip(old.values(), after, strict=True):
            if (new["values"], new["final"]) == (document["values"], document["final"]):
                store_document(path, document)  # the same run: keep its file (and provenance) as committed
            else:
                changed += 1
        print(f"{changed} of them changed")
    run_all([trial_spec(document["spec"], options) for _, document in documents], folder, workers=workers)
    return changed


def _render(study: str, options: dict[str, Any], base: dict[str, Any], out: Path) -> Path:
    rows, provenance = cells(HERE / study / "runs", options, base)
    label = label_of(options) if not base else f"{label_of(options)}-vs-{label_of(base)}"
    summary = {"study": study, "options": options, "base": base, "label": label, "cells": rows}
    summary["base_runs"] = len(default_documents(HERE / study / "runs", base))
    summary["provenance"] = provenance
    out.mkdir(parents=True, exist_ok=True)
    text = json.dumps(summary, indent=1, sort_keys=True, allow_nan=False)
    write_text(out / f"{study}-{label}.json", text + "\n")
    write_text(out / f"{study}-{label}.md", render_markdown(summary))
    return out / f"{study}-{label}.md"


def main(argv: Sequence[str] | None = None) -> int:
    """Run or render a trial of a candidate default."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("action", choices=("run", "render"))
    parser.add_argument("--study", required=True, choices=STUDIES)
    parser.add_argument("--options", required=True, type=json_object, help="the candidate's options (JSON)")
    parser.add_argument(
        "--base-options",
        type=json_object,
        default={},
        help="the column the trial is measured against, by its options (JSON; {}: the default column)",
    )
    parser.add_argument("--match", default="", help="run: only the runs whose file name this regex finds")
    parser.add_argument("--workers", type=int, default=1, help="run: processes (default 1)")
    parser.add_argument(
        "--no-refresh", dest="refresh", action="store_false", help="run: leave the default column as it is"
    )
    parser.add_argument("--out", type=Path, default=OUT, help=f"render: folder (default {OUT})")
    args = parser.parse_args(argv)
    if not args.options:
        parser.error("--options: expected at least one option for a trial, got {}")
    if args.action == "run":
        folder = HERE / args.study / "runs"
        run_trial(folder, args.options, args.workers, args.refresh, args.base_options, args.match)
    else:
        print(f"wrote {_render(args.study, args.options, args.base_options, args.out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
