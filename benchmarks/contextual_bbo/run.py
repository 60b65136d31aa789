"""The field's contextual benchmark (IJCAI 2017 / GECCO 2019 protocol) with our optimisers, beside the
published values.

    python benchmarks/contextual_bbo/run.py --quick    # 3 runs per cell
    python benchmarks/contextual_bbo/run.py --full     # 20 runs per cell, as published
    python benchmarks/contextual_bbo/run.py --full --render-only   # redraw from the committed runs

(or ``python -m benchmarks.contextual_bbo.run ...`` from the repository root). Each run's result is one JSON
document in ``runs/`` (committed; an interrupted study resumes run by run, since the quick mode's seeds are
the full mode's first ones, it reuses them). ``results.md`` is rendered from those documents and
``published.json`` only.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

# Run by path: the repository root first on sys.path, as `python -m` puts it (see benchmarks/__init__.py).
if not __package__:
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import matplotlib

matplotlib.use("Agg")

from benchmarks.contextual_bbo.problems import PROBLEMS
from benchmarks.contextual_bbo.protocol import ProtocolSpec, run_protocol
from benchmarks.contextual_bbo.report import load_published, plot_curves, render
from benchmarks.study_cli import add_mode_options, add_output_options, command_flags
from benchmarks.study_options import C3_PIN, RESTART_PIN, pin_c3
from benchmarks.study_report import invocation_timing, timing_text, update_block
from benchmarks.study_runner import run_all
from benchmarks.study_tools import write_text
from creps_gym.optimizers import optimizer_names

STUDY = Path(__file__).resolve().parent
SEEDS = {"quick": 3, "full": 20}
#: The surrogate with C3r and the detrended local baseline (Eq. C1d, h = 0.3 context standard deviations) and
#: a covariance allowed a condition of 1e20 (Different Powers' runs reach 1e14, the default's stop, while
#: still converging): issue 45's candidate for every cell of the published table.
C1D = (
    ("restarts", 0),
    ("ridge_centre", "old"),
    ("baseline_bandwidth", 0.3),
    ("baseline_detrend", True),
    ("max_condition", 1e20),
)
#: The same with a slower step-size adaptation (CSA's damping d_σ = 3 instead of 1.41 at p = 20, N = 50):
#: on Different Powers the default damping lets σ shrink until the θ part of the returns is below the local
#: baseline's error and the ranking stalls (docs/algorithms.md, the floor's third pass).
C1D_DSIGMA3 = (*C1D, ("d_sigma", 3.0))
#: The columns: (label, registry name, options). ``c-cma-es`` and ``c-cma-es-surrogate`` are the methods with
#: the defaults before issue 45, i.e. with the mean fit's ridge towards 0 (C3, ``ridge_centre="zero"``, as
#: every column without ``-c3r-``: the runs were computed with it; benchmarks/study_options.py);
#: ``c-cma-es-former-restarts`` is ``c-cma-es`` with its restart defaults before issue 33 (no kept best,
#: squared restarts); the ``-c3r-`` columns shrink the mean fit's step rather than its coefficients (Eq. C3r,
#: ``ridge_centre="old"``, the default since issue 45; ``c-cma-es-c3r`` is that default, with its restarts).
COLUMNS: tuple[tuple[str, str, tuple[tuple[str, object], ...]], ...] = (
    ("c-cma-es", "c-cma-es", C3_PIN),
    ("c-cma-es-former-restarts", "c-cma-es", pin_c3("c-cma-es", RESTART_PIN)),
    ("c-cma-es-no-restarts", "c-cma-es", (("restarts", 0), *C3_PIN)),
    ("c-cma-es-c3r", "c-cma-es", (("ridge_centre", "old"),)),
    ("c-cma-es-surrogate", "c-cma-es-surrogate", C3_PIN),
    ("c-cma-es-surrogate-no-restarts", "c-cma-es-surrogate", (("restarts", 0), *C3_PIN)),
    ("c-cma-es-c3r-no-restarts", "c-cma-es", (("restarts", 0), ("ridge_centre", "old"))),
    ("c-cma-es-surrogate-c3r-no-restarts", "c-cma-es-surrogate", (("restarts", 0), ("ridge_centre", "old"))),
    ("c-cma-es-surrogate-c3r-c1d-no-restarts", "c-cma-es-surrogate", C1D),
    ("c-cma-es-surrogate-c3r-c1d-dsigma3-no-restarts", "c-cma-es-surrogate", C1D_DSIGMA3),
)
#: Columns run on some functions only (column name -> functions): the surrogate on the Sphere and Rosenbrock,
#: without restarts on Rosenbrock (where its default restarts replace the converged search; issue 33).
ONLY = {"c-cma-es-surrogate": ("Sphere", "Rosenbrock"), "c-cma-es-surrogate-no-restarts": ("Rosenbrock",)}


def specs_for(mode: str, functions: Sequence[str], seeds: int | None = None) -> list[ProtocolSpec]:
    """Every run of the study: the columns × functions × seeds (registered methods only; a column of
    :data:`ONLY` on its functions only)."""
    known = set(optimizer_names())
    return [
        ProtocolSpec(function, method, seed, options, label)
        for label, method, options in COLUMNS
        if method in known
        for function in functions
        if function in ONLY.get(label or method, (function,))
        for seed in range(seeds or SEEDS[mode])
    ]


def with_partial_provenance(document: dict) -> dict:
    """A run written before the shared provenance record: what its ``environment`` field recorded."""
    env = document.get("environment")
    if "provenance" in document or not isinstance(env, dict):
        return document
    known = ", ".join(f"{name} {env[name]}" for name in ("python", "numpy", "scipy") if name in env)
    cpu = f"{env.get('cpu')} ({env.get('cores')} cores)"
    partial = f"recorded before the shared provenance record: {known}; CPU {cpu}"
    return {**document, "provenance": {"recorded": False, "partial": partial}}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_mode_options(parser, quick="3 runs per cell", full="20 runs per cell (the protocol)")
    add_output_options(parser, STUDY, "results folder (default benchmarks/contextual_bbo/results/<mode>)")
    parser.add_argument("--functions", nargs="+", default=list(PROBLEMS), choices=list(PROBLEMS))
    parser.add_argument("--seeds", type=int, help="runs per cell (default: 3 quick, 20 full)")
    args = parser.parse_args(argv)
    args.mode = args.mode or "quick"
    if args.cache is None:  # --quick computes its runs again, never replacing the documents --full reads
        args.cache = STUDY / "runs" / "quick" if args.mode == "quick" else STUDY / "runs"
    out = args.out or STUDY / "results" / args.mode
    out.mkdir(parents=True, exist_ok=True)
    specs = specs_for(args.mode, args.functions, args.seeds)
    start = time.perf_counter()
    cached = sum((args.cache / f"{spec.key}.json").exists() for spec in specs)
    recompute = args.mode == "quick" and not args.render_only
    documents = run_all(
        specs,
        args.cache,
        workers=args.workers,
        worker=run_protocol,
        compute=not args.render_only,
        recompute=recompute,
    )
    if not documents:
        print(f"no cached runs in {args.cache}: nothing to render")
        return 1
    documents = [with_partial_provenance(document) for document in documents]
    computed = 0 if args.render_only else len(documents) - cached
    timing = invocation_timing(out, time.perf_counter() - start, computed, len(specs))
    command = f"python benchmarks/contextual_bbo/run.py {command_flags(argv, args.mode)}"
    text = render(documents, load_published(), command, timing_text(timing, documents))
    write_text(out / "results.md", text)
    plot_curves(documents, out / "curves.png")
    if args.out is None:
        update_block(STUDY / "README.md", f"results-{args.mode}", text.split("\n", 1)[1])
    print(f"wrote {out / 'results.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
