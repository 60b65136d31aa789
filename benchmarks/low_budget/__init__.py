"""The low-budget studies (issue 44): ``run.py`` (the 50–500 episode study of item 5: ``study.py``,
``report.py``), ``compare.py`` (regret after a fixed episode budget), ``gp_backends.py`` (the GP's cost
against scikit-learn's), ``active_contexts.py`` (active context choice against uniform draws) and
``reach.py`` (what the low-dimensional kicks can reach at all)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_output_arguments(parser: argparse.ArgumentParser) -> None:
    """``--out`` (the results' JSON) and ``--render-only`` (redraw the table from it), as both take."""
    parser.add_argument("--out", type=Path, required=True, help="the results' JSON (read with --render-only)")
    parser.add_argument("--render-only", action="store_true", help="only write the table next to --out")
