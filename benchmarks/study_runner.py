"""Running a study: its runs in a process pool, and the invocation that runs, reports and indexes them.

:func:`run_study` is what every study's ``main`` calls: it runs the specs through :func:`run_all` (cached runs
are read, the others computed by :func:`benchmarks.study_tools.execute` with the study's baseline runners),
writes the report from the cached documents, and updates the results index (``docs/results/README.md``) and
the study README's generated block (:mod:`benchmarks.study_report`). :func:`available_methods` picks the
methods a study can run. The options every study's command line shares are in :mod:`benchmarks.study_cli`.
"""

from __future__ import annotations

import functools
import os
import shutil
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

from benchmarks.provenance import provenance
from benchmarks.study_report import invocation_timing, update_block
from benchmarks.study_tools import (
    Baselines,
    RunSpec,
    cached_result,
    execute,
    store_document,
)
from creps_gym.optimizers import optimizer_names

__all__ = ["available_methods", "run_all", "run_study"]


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
