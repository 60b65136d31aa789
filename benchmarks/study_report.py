"""How a study's command line becomes its report: run (or resume) the specs, render, update the READMEs.

:func:`run_study` is what every study's ``main`` calls: it runs the specs through
:func:`benchmarks.study_tools.run_all` with the study's baseline runners, writes the report from the cached
documents, and updates the results index (``docs/results/README.md``) and the study README's generated block.
The helpers around it pick the methods a study can run (:func:`available_methods`), summarise a cell's runs
(:func:`summarise`) and say what computed the report (:func:`command_flags`, :func:`timing_text`).
"""

from __future__ import annotations

import functools
import json
import os
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.study_tools import (
    Baselines,
    RunSpec,
    cached_result,
    execute,
    load_document,
    run_all,
    write_text,
)
from creps_gym.optimizers import optimizer_names

__all__ = [
    "NEUTRAL_OPTIONS",
    "available_methods",
    "command_flags",
    "invocation_timing",
    "run_study",
    "summarise",
    "timing_text",
    "update_block",
]


def available_methods(
    methods: Iterable[str], baselines: Baselines, log: Callable[[str], None] = print
) -> list[str]:
    """The methods a study can run now: registered optimisers and ``baselines``; the others are skipped
    with a message (a study lists optimisers that may not be registered yet, e.g. ``c-cma-es``)."""
    known = set(optimizer_names()) | set(baselines)
    for method in methods:
        if method not in known:
            log(f"skipped method {method!r}: not a registered optimiser (nor a baseline) in this version")
    return [m for m in methods if m in known]


def summarise(documents: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Median episodes to the target over the runs that hit it, how many hit it, and the median final value.

    Returns
    -------
    dict
        ``hits`` (int), ``runs`` (int), ``median_hit`` (float or None), ``median_final`` (float or None),
        ``median_total`` (median episodes used).
    """
    hits = [d["hit"] for d in documents if d["hit"] is not None]
    finals = [d["final"] for d in documents if d["final"] is not None]
    return {
        "hits": len(hits),
        "runs": len(documents),
        "median_hit": float(np.median(hits)) if hits else None,
        "median_final": float(np.median(finals)) if finals else None,
        "median_total": float(np.median([d["total_episodes"] for d in documents])) if documents else None,
    }


def update_block(path: str | os.PathLike[str], name: str, text: str) -> Path:
    """Replace the text between ``<!-- name -->`` and ``<!-- /name -->`` in a Markdown file.

    The block is appended (with its markers) when the file lacks it; the file is created if missing.
    """
    path = Path(path)
    start, end = f"<!-- {name} -->", f"<!-- /{name} -->"
    old = path.read_text(encoding="utf-8") if path.exists() else ""
    block = f"{start}\n{text.strip()}\n{end}"
    if start in old and end in old:
        head, _, rest = old.partition(start)
        _, _, tail = rest.partition(end)
        new = head + block + tail
    else:
        new = old.rstrip("\n") + ("\n\n" if old else "") + block + "\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, new)
    return path


def invocation_timing(out: str | os.PathLike[str], wall: float, computed: int, total: int) -> dict[str, Any]:
    """Wall time of the last invocation that computed runs, kept in ``out/timing.json``.

    An invocation that only reads the cache (to re-render) keeps the stored timing, so the reports always
    state how long the computation took.
    """
    path = Path(out) / "timing.json"
    stored = load_document(path) if computed == 0 else None
    if stored is not None:
        return {**stored, "expected": total}  # this invocation's run count, for the completeness check
    timing = {"wall_seconds": round(wall, 1), "computed": computed, "total": total, "cores": os.cpu_count()}
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps(timing) + "\n")
    return timing


def timing_text(timing: dict[str, Any], documents: Sequence[dict[str, Any]]) -> str:
    """Markdown on the time taken and on how complete the study is (see :func:`invocation_timing`)."""
    cpu = sum(d["seconds"] for d in documents)
    if timing["computed"]:
        text = (
            f"Time taken: {timing['wall_seconds']:.0f} s wall on {timing['cores']} cores for the last "
            f"invocation that computed runs ({timing['computed']} of {timing['total']} runs computed, the "
            "others read from the cache)"
        )
    else:
        text = "Rendered from cached runs only (no invocation that computed runs has finished)"
    text += f"; per-run times summed over the {len(documents)} runs shown: {cpu:.0f} s."
    expected = timing.get("expected", timing["total"])
    if len(documents) < expected:
        text += f" **Partial: {len(documents)} of {expected} runs have finished.**"
    return text


#: Options that change where or how fast a study runs, not its results, with their argument counts: the
#: reported command leaves them out.
NEUTRAL_OPTIONS = {"--render-only": 0, "--workers": 1, "--cache": 1, "--out": 1}


def command_flags(argv: Sequence[str] | None, mode: str) -> str:
    """The options of a study's command line (``sys.argv[1:]`` if ``argv`` is None) that determine its
    results, i.e. without :data:`NEUTRAL_OPTIONS`; ``--<mode>`` when none is left."""
    given = sys.argv[1:] if argv is None else list(argv)
    kept, skip = [], 0
    for arg in given:
        name, has_value, _ = arg.partition("=")
        if skip:
            skip -= 1
        elif name in NEUTRAL_OPTIONS:
            skip = 0 if has_value else NEUTRAL_OPTIONS[name]
        else:
            kept.append(arg)
    return " ".join(kept) or f"--{mode}"


def run_study(
    args: Any,
    specs: Sequence[RunSpec],
    write_report: Callable[[Any, list[dict[str, Any]], dict[str, Any]], Path],
    *,
    baselines: Baselines,
    title: str,
    script: str,
    figures_marker: str,
    readme: Path,
) -> int:
    """Run (or resume) ``specs``, write the report, and update the results index and the study README.

    ``baselines`` maps the study's baseline method names to their runners (see :func:`execute`).
    ``title`` names the study in the index (e.g. "Function study"), ``script`` is its command's path,
    ``figures_marker`` is the line where the generated table's figures start (the README gets the text
    above it), and ``readme`` is the study README with a generated ``results-<mode>`` block.
    """
    start = time.perf_counter()
    cached_before = sum(cached_result(args.cache, spec) is not None for spec in specs)
    worker = functools.partial(execute, baselines=baselines)
    documents = run_all(specs, args.cache, workers=args.workers, worker=worker, compute=not args.render_only)
    if not documents:
        print(f"no cached runs in {args.cache}: nothing to render")
        return 1
    wall = time.perf_counter() - start
    computed = 0 if args.render_only else len(specs) - cached_before
    timing = invocation_timing(args.out, wall, computed, len(specs))
    table = write_report(args, documents, timing)
    print(f"wrote {table} and its figures in {wall:.0f} s")
    if args.index is not None:
        relative = table.relative_to(args.index.parent)
        how = (
            f"{timing['wall_seconds']:.0f} s wall on {timing['cores']} cores ({timing['computed']} runs "
            "computed, the others cached)."
            if timing["computed"]
            else "rendered from the cached runs (the computing invocation has not finished)."
        )
        label = getattr(args, "label", args.mode)  # a variant of a mode, e.g. "full-cap0.2"
        flags = getattr(args, "flags", f"--{args.mode}")
        update_block(
            args.index,
            f"{Path(script).parent.name}-{label}",
            f"- {title}, {label}: [{relative}]({relative}); command "
            f"`python {script} {flags}`: {len(documents)} of {len(specs)} runs, {how}",
        )
        body = table.read_text(encoding="utf-8").split(figures_marker)[0].split("\n", 1)[1]
        update_block(readme, f"results-{label}", body)
    return 0
