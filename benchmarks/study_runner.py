"""Running a study: its runs in a process pool, its command line, its report and the READMEs it updates.

:func:`run_study` is what every study's ``main`` calls: it runs the specs through :func:`run_all` (cached runs
are read, the others computed by :func:`benchmarks.study_tools.execute` with the study's baseline runners),
writes the report from the cached documents, and updates the results index (``docs/results/README.md``) and
the study README's generated block.
The helpers around it pick the methods a study can run (:func:`available_methods`), summarise a cell's runs
(:func:`summarise`) and say what computed the report (:func:`command_flags`, :func:`timing_text`).
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import shutil
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.provenance import provenance, provenance_text
from benchmarks.study_tools import (
    Baselines,
    RunSpec,
    cached_result,
    execute,
    load_document,
    store_document,
    write_text,
)
from creps_gym.optimizers import optimizer_names

__all__ = [
    "NEUTRAL_OPTIONS",
    "add_mode_options",
    "add_output_options",
    "available_methods",
    "command_flags",
    "invocation_timing",
    "resolve_outputs",
    "run_all",
    "run_study",
    "summarise",
    "timing_text",
    "update_block",
]


def run_all(
    specs: Iterable[RunSpec],
    cache_dir: str | os.PathLike[str],
    workers: int = 2,
    worker: Callable[[RunSpec, Path], dict[str, Any]] = execute,
    log: Callable[[str], None] = print,
    compute: bool | Callable[[RunSpec], bool] = True,
    recompute: bool = False,
    packages: Sequence[str] | Callable[[RunSpec], Sequence[str]] = ("cma",),
) -> list[dict[str, Any]]:
    """Results of the specs, in order: cached ones are read, the others computed in a process pool.

    Every computed document gets this process's ``provenance`` (:func:`benchmarks.provenance.provenance`:
    package versions, CPU, BLAS, creps_gym's commit) before it is stored.

    Parameters
    ----------
    specs : iterable of RunSpec
    cache_dir : path-like
        One ``<key>.json`` per run; created if missing.
    workers : int
        Processes (1 runs in this process, which is what the tests use).
    worker : callable
        ``(RunSpec, checkpoint_dir) -> result document`` (a module-level function, so the pool can send
        it). ``checkpoint_dir`` is ``cache_dir/partial/<key>``; it is removed, with the same run's
        checkpoints under other budgets, once the run's document is stored.
    log : callable
        Receives one progress line per computed run.
    compute : bool or callable
        False: compute nothing and return only the cached results (to render a partial study); a predicate
        ``compute(spec)``: compute only the missing runs it accepts (the results leave the others out).
    recompute : bool
        Compute every run, reading no cached document (a ``--quick`` invocation reproduces its results);
        the new documents replace the cached ones.
    packages : sequence of str, or callable
        Distributions the computed runs use besides the core ones, whose versions the provenance records
        (default pycma, which the studies' baselines use; a study on MuJoCo or a GP library adds them), or
        ``packages(spec)``: each run's own.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers: expected an integer >= 1, got {workers!r}")
    cache = Path(cache_dir)
    cache.mkdir(parents=True, exist_ok=True)
    specs = list(specs)
    results, todo = _cached_and_missing(specs, cache, compute, recompute)
    if not compute:
        log(f"{len(specs) - len(todo)} runs cached in {cache}, {len(todo)} missing (not computed)")
        return [results[spec.key] for spec in specs if spec.key in results]
    skipped = 0
    if callable(compute):
        chosen = [spec for spec in todo if compute(spec)]
        skipped, todo = len(todo) - len(chosen), chosen
    log(
        f"{len(specs) - len(todo) - skipped} runs cached in {cache}, {len(todo)} to compute with {workers} "
        f"worker(s)" + (f", {skipped} missing left out" if skipped else "")
    )

    partial = cache / "partial"
    record = _provenance_by_packages(packages)
    running = {spec.key for spec in todo}

    def done(spec: RunSpec, document: dict[str, Any], count: int) -> None:
        document = {**document, "provenance": record(spec)}
        store_document(cache / f"{spec.key}.json", document)
        running.discard(spec.key)
        for stale in partial.glob(f"{spec.prefix}-b*-n{spec.samples}"):  # this run, under any budget ...
            if stale.name not in running:  # ... but one this call is still computing
                shutil.rmtree(stale, ignore_errors=True)
        results[spec.key] = document
        outcome = f"hit at {document['hit']}" if document["hit"] is not None else f"final {document['final']}"
        log(f"[{count}/{len(todo)}] {spec.key}: {outcome} ({document['seconds']:.1f} s)")

    if workers == 1:
        for count, spec in enumerate(todo, 1):
            done(spec, worker(spec, partial / spec.key), count)
    elif todo:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = {pool.submit(worker, spec, partial / spec.key): spec for spec in todo}
            for count, future in enumerate(as_completed(futures), 1):
                done(futures[future], future.result(), count)
    return [results[spec.key] for spec in specs if spec.key in results]


def _cached_and_missing(
    specs: list[RunSpec], cache: Path, compute: bool | Callable[[RunSpec], bool], recompute: bool
) -> tuple[dict[str, dict[str, Any]], list[RunSpec]]:
    """:func:`run_all`'s cached results by key, and the specs it would compute (each key once, in order)."""
    results: dict[str, dict[str, Any]] = {}
    missing: list[RunSpec] = []
    names = os.listdir(cache)
    for spec in specs:
        fresh = recompute and (compute is True or (callable(compute) and compute(spec)))
        cached = None if fresh else cached_result(cache, spec, names)
        if cached is not None:
            results[spec.key] = cached
        elif spec.key not in {s.key for s in missing}:
            missing.append(spec)
    return results, missing


def _provenance_by_packages(
    packages: Sequence[str] | Callable[[RunSpec], Sequence[str]],
) -> Callable[[RunSpec], dict[str, Any]]:
    """A run's provenance record: one per package list (``packages``, or ``packages(spec)``), made when
    first needed."""
    records: dict[tuple[str, ...], dict[str, Any]] = {}

    def record(spec: RunSpec) -> dict[str, Any]:
        names = tuple(packages(spec) if callable(packages) else packages)
        if names not in records:
            records[names] = provenance(names)
        return records[names]

    return record


def available_methods(
    methods: Iterable[str], baselines: Baselines, log: Callable[[str], None] = print
) -> list[str]:
    """The methods a study can run now: registered optimisers and ``baselines``; the others are skipped
    with a message (a study lists optimisers that may not be registered yet, e.g. ``c-cma-es``)."""
    methods, known = list(methods), set(optimizer_names()) | set(baselines)
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


def _what_to_compute(args: Any) -> bool | Callable[[RunSpec], bool]:
    """:func:`run_all`'s ``compute`` for a study's arguments: nothing with ``--render-only``, else every
    missing run, or only those of ``args.compute_methods`` where it names some."""
    chosen = getattr(args, "compute_methods", None)
    if chosen and not args.render_only:
        return lambda spec: spec.method in chosen
    return not args.render_only


def _all_packages(
    packages: Sequence[str] | Callable[[RunSpec], Sequence[str]], specs: Sequence[RunSpec]
) -> Sequence[str]:
    """Every package the specs' runs record (``packages``, or the union of ``packages(spec)``)."""
    return sorted({name for spec in specs for name in packages(spec)}) if callable(packages) else packages


def invocation_timing(
    out: str | os.PathLike[str],
    wall: float,
    computed: int,
    total: int,
    packages: Sequence[str] = ("cma",),
) -> dict[str, Any]:
    """Wall time of the last invocation that computed runs, kept in ``out/timing.json``.

    An invocation that only reads the cache (to re-render) keeps the stored timing, so the reports always
    state how long the computation took. A computing invocation records its ``provenance`` there too
    (with ``packages``' versions, as :func:`run_all`).
    """
    path = Path(out) / "timing.json"
    stored = load_document(path) if computed == 0 else None
    if stored is not None:
        return {**stored, "expected": total}  # this invocation's run count, for the completeness check
    timing = {"wall_seconds": round(wall, 1), "computed": computed, "total": total, "cores": os.cpu_count()}
    if computed:
        timing["provenance"] = provenance(packages)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps(timing) + "\n")
    return timing


def timing_text(timing: dict[str, Any], documents: Sequence[dict[str, Any]]) -> str:
    """Markdown on the time taken, on how complete the study is (see :func:`invocation_timing`) and where
    the runs shown were computed (their provenance records)."""
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
    return text + "\n\n" + provenance_text(d.get("provenance") for d in documents)


def add_mode_options(parser: argparse.ArgumentParser, quick: str, full: str) -> None:
    """``--quick``/``--full`` (into ``mode``), with their help texts."""
    mode = parser.add_mutually_exclusive_group()
    quick += ", computing every run again (a reproduction; --render-only redraws the committed runs)"
    mode.add_argument("--quick", action="store_const", dest="mode", const="quick", help=quick)
    mode.add_argument("--full", action="store_const", dest="mode", const="full", help=full)


def add_output_options(parser: argparse.ArgumentParser, study_dir: Path, out: str) -> None:
    """Add ``--workers``, ``--render-only``, ``--cache`` (default: see :func:`resolve_outputs`) and ``--out``
    (help text ``out``)."""
    parser.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    parser.add_argument(
        "--render-only", action="store_true", help="compute nothing: render the runs already cached"
    )
    parser.add_argument(
        "--cache",
        type=Path,
        help="per-run JSON (committed; default runs/quick/ with --quick, which computes every run again, "
        "else runs/, where runs already cached are reused)",
    )
    parser.add_argument("--out", type=Path, help=out)


def resolve_outputs(
    args: argparse.Namespace, argv: Sequence[str] | None, study_dir: Path, label: str
) -> None:
    """Set ``args.flags`` (see :func:`command_flags`), ``args.index`` (the results index, or None with
    ``--out``), ``args.out`` (default ``docs/results/<study>/<label>``) and ``args.cache`` (default
    ``<study>/runs/quick`` for ``--quick``, whose runs are computed again by every invocation, so that they
    never replace the documents a ``--full`` rendering reads, and ``<study>/runs`` otherwise)."""
    results = study_dir.parents[1] / "docs" / "results"
    if args.cache is None:
        args.cache = study_dir / "runs" / "quick" if args.mode == "quick" else study_dir / "runs"
    args.flags = command_flags(argv, args.mode)
    args.index = results / "README.md" if args.out is None else None
    args.out = args.out or results / study_dir.name / label


#: Options that change where or how fast a study runs, not its results, with their argument counts (None:
#: every argument up to the next option): the reported command leaves them out.
NEUTRAL_OPTIONS = {"--render-only": 0, "--workers": 1, "--cache": 1, "--out": 1, "--compute-methods": None}


def command_flags(argv: Sequence[str] | None, mode: str) -> str:
    """The options of a study's command line (``sys.argv[1:]`` if ``argv`` is None) that determine its
    results, i.e. without :data:`NEUTRAL_OPTIONS`; ``--<mode>`` when none is left."""
    given = sys.argv[1:] if argv is None else list(argv)
    kept, skip = [], 0
    for arg in given:
        name, has_value, _ = arg.partition("=")
        if skip and not (skip < 0 and arg.startswith("--")):
            skip -= 1
        elif name in NEUTRAL_OPTIONS:
            count = NEUTRAL_OPTIONS[name]
            skip = 0 if has_value else (-1 if count is None else count)  # -1: until the next option
        else:
            skip = 0
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
    packages: Sequence[str] | Callable[[RunSpec], Sequence[str]] = ("cma",),
) -> int:
    """Run (or resume) ``specs``, write the report, and update the results index and the study README.

    ``baselines`` maps the study's baseline method names to their runners (see :func:`execute`).
    ``title`` names the study in the index (e.g. "Function study"), ``script`` is its command's path,
    ``figures_marker`` is the line where the generated table's figures start (the README gets the text
    above it), ``readme`` is the study README with a generated ``results-<mode>`` block, and ``packages``
    the distributions whose versions the computed runs' provenance records (see :func:`run_all`).
    """
    start = time.perf_counter()
    worker = functools.partial(execute, baselines=baselines)
    compute = _what_to_compute(args)
    recompute = args.mode == "quick"  # a quick study is a reproduction: it computes every run again

    names = os.listdir(args.cache) if args.cache.is_dir() else []

    def read_back(spec: RunSpec) -> bool:  # a cached run this invocation reads rather than computes
        fresh = recompute and bool(compute) and (compute is True or compute(spec))
        return not fresh and cached_result(args.cache, spec, names) is not None

    cached_before = sum(map(read_back, specs))
    documents = run_all(
        specs,
        args.cache,
        workers=args.workers,
        worker=worker,
        compute=compute,
        recompute=recompute,
        packages=packages,
    )
    if not documents:
        print(f"no cached runs in {args.cache}: nothing to render")
        return 1
    wall = time.perf_counter() - start
    computed = 0 if args.render_only else len(documents) - cached_before
    timing = invocation_timing(args.out, wall, computed, len(specs), _all_packages(packages, specs))
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
