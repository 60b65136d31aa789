"""What a study's report says about its runs, and the Markdown blocks it keeps current.

:func:`summarise` sums up a cell's runs, :func:`invocation_timing` and :func:`timing_text` say how long the
computation took, how complete the study is and where its runs were computed, and :func:`update_block`
rewrites a generated block of the results index or a study README.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.provenance import provenance, provenance_text
from benchmarks.study_tools import load_document, write_text

__all__ = ["invocation_timing", "summarise", "timing_text", "update_block"]


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
    (with ``packages``' versions, as :func:`benchmarks.study_runner.run_all`).
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
