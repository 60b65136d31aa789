r"""Bring the committed ``c-cma-es`` study runs to the restart defaults of issue 33.

Since issue 33, ``c-cma-es`` (and ``c-cma-es-surrogate``, which shares its config) keeps the best mean policy
a restart leaves (``keep_best=True``, C10) and restarts with the other baseline loss
(``restart_baseline_loss="other"``, C11). Both act only from a run's first restart on, so a run that never
restarted is the same under the old and the new defaults. This script is how the committed documents were
brought over, and how to do it again after the next change that acts only at a restart:

    python benchmarks/restart_defaults.py list --study functions     # the documents it would touch
    python benchmarks/restart_defaults.py pin --study scaling        # rename them to the former defaults
    python benchmarks/restart_defaults.py pin --study functions --copy \
        --match '^runs/(Sphere-p15-z1|Rosenbrock-p15-z3)-c-cma-es-s'
    python benchmarks/restart_defaults.py pin --study contextual_bbo --copy --all \
        --match '/[A-Za-z]+-c-cma-es-s\d'

    python benchmarks/restart_defaults.py recompute --study functions --workers 2

* ``pin``: a document computed with the former defaults is, bit for bit, the run of the same spec with those
  defaults as options (:data:`FORMER`: ``keep_best=False``, and ``restart_baseline_loss="squared"``, which is
  the former None for the squared baseline every such run used). ``pin`` writes it under that spec and key
  (``--copy`` keeps the original too, for a "before" column). Nothing is computed.
* ``recompute``: computes the documents again with the study's own code (``run_all``, the same worker and
  cache folder), replacing them, and prints how many changed.

A document is touched when its method is one of :data:`METHODS` and its options set neither ``restarts=0``
nor both changed options; for the contextual BBO study, which records each run's restarts, only when it
restarted. The other studies do not record restarts, so every such document is touched.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

if not __package__:  # run by path: the repository root first on sys.path (see benchmarks/__init__.py)
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from benchmarks.study_options import RESTART_PIN, options_dict
from benchmarks.study_tools import RunSpec, load_document, store_document

__all__ = [
    "FORMER",
    "METHODS",
    "STUDIES",
    "affected",
    "computed_at",
    "documents",
    "main",
    "pin",
    "pinned",
    "recompute",
]

HERE = Path(__file__).resolve().parent
METHODS = ("c-cma-es", "c-cma-es-surrogate")
#: The former defaults of the changed options, as options (``"squared"``: the former None with the squared
#: baseline loss, the only one the touched runs used): ``study_options.RESTART_PIN``, which the studies use.
FORMER = RESTART_PIN
STUDIES = ("functions", "ccmaes", "scaling", "contextual_bbo")
#: The column label of a contextual BBO document pinned to the former defaults.
FORMER_LABEL = "former-restarts"


def affected(document: dict[str, Any], recorded: bool = True) -> bool:
    """Whether the new restart defaults can change ``document`` (see the module docstring); with
    ``recorded=False`` also when it records that it never restarted (every run of the former defaults)."""
    spec = document.get("spec", {})
    options = options_dict(spec.get("options"))
    if spec.get("method") not in METHODS or options.get("restarts") == 0:
        return False
    if {name for name, _ in FORMER} <= set(options):
        return False
    return not recorded or document.get("restarts", 1) > 0  # recorded by the contextual BBO study only


def documents(study: str, match: str = "", recorded: bool = True) -> list[Path]:
    """The touched documents of ``study`` whose path in the study's folder (``runs/...``, quick folders
    included) the regular expression ``match`` finds (for ``recorded`` see :func:`affected`)."""
    if study not in STUDIES:
        raise ValueError(f"study: expected one of {STUDIES}, got {study!r}")
    found = []
    for path in sorted((HERE / study / "runs").rglob("*.json")):
        name = path.relative_to(HERE / study).as_posix()
        if "partial" in path.parts or not re.search(match, name) or path.is_symlink():
            continue
        document = load_document(path)
        if document is not None and affected(document, recorded):
            found.append(path)
    return found


def _protocol_spec(spec: dict[str, Any]) -> Any:
    from benchmarks.contextual_bbo.protocol import ProtocolSpec

    fields = dict(spec, options=tuple(sorted(options_dict(spec.get("options")).items())))
    return ProtocolSpec(**{name: fields[name] for name in ("function", "method", "seed", "options", "label")})


def _spec_of(study: str, document: dict[str, Any]) -> Any:
    if study == "contextual_bbo":
        return _protocol_spec(document["spec"])
    return RunSpec(**document["spec"])


def pinned(study: str, document: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """The key and document of ``document`` under its spec with the former defaults as options."""
    spec = document["spec"]
    options = dict(sorted({**options_dict(spec.get("options")), **dict(FORMER)}.items()))
    if study == "contextual_bbo":
        label = f"{spec['label'] or spec['method']}-{FORMER_LABEL}"
        new_spec = dict(spec, options=options, label=label)
        return _protocol_spec(new_spec).key, {**document, "spec": new_spec}
    run_spec = RunSpec(**dict(spec, options=tuple(options.items())))
    new_spec = dict(spec, options=[list(pair) for pair in run_spec.options])
    return run_spec.key, {**document, "spec": new_spec}


def pin(study: str, paths: Iterable[Path], copy: bool) -> int:
    """Write each document under its pinned key (beside the original with ``copy``, else instead of it)."""
    count = 0
    for path in paths:
        document = load_document(path)
        if document is None:
            raise ValueError(f"{path}: expected a run document, got an unreadable file")
        key, new = pinned(study, document)
        store_document(path.with_name(f"{key}.json"), new)
        if not copy:
            path.unlink()
        count += 1
    return count


def computed_at(path: Path, commit: str) -> bool:
    """Whether the document at ``path`` records that creps_gym's commit ``commit`` computed it."""
    provenance = (load_document(path) or {}).get("provenance")
    return isinstance(provenance, dict) and provenance.get("creps_gym_commit") == commit


def recompute(study: str, paths: Sequence[Path], workers: int) -> tuple[int, int]:
    """Compute ``paths`` again with the study's own worker; returns (changed, total)."""
    from benchmarks.study_runner import run_all

    worker: Any = None
    if study == "contextual_bbo":
        from benchmarks.contextual_bbo.protocol import run_protocol

        worker = run_protocol
    changed = 0
    by_folder: dict[Path, list[Path]] = {}
    for path in paths:
        by_folder.setdefault(path.parent, []).append(path)
    for folder, chosen in by_folder.items():
        before = {path.stem: load_document(path) for path in chosen}
        specs = [_spec_of(study, document) for document in before.values() if document is not None]
        extra = {"worker": worker} if worker is not None else {}
        results = run_all(specs, folder, workers=workers, recompute=True, **extra)
        for spec, result in zip(specs, results, strict=True):
            old = before[spec.key] or {}
            changed += old.get("values") != result.get("values") or old.get("final") != result.get("final")
    return changed, len(paths)


def main(argv: Sequence[str] | None = None) -> int:
    """List, pin or recompute the touched documents of a study."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("action", choices=("list", "pin", "recompute"))
    parser.add_argument("--study", required=True, choices=STUDIES)
    parser.add_argument("--match", default="", help="a regular expression their path must match")
    parser.add_argument("--copy", action="store_true", help="pin: keep the original document too")
    parser.add_argument("--workers", type=int, default=1, help="recompute: processes (default 1)")
    parser.add_argument(
        "--all", action="store_true", help="also the runs that record that they never restarted"
    )
    parser.add_argument(
        "--skip-commit", default=None, help="recompute: skip the documents this commit computed (a resume)"
    )
    args = parser.parse_args(argv)
    paths = documents(args.study, args.match, recorded=not args.all)
    if args.skip_commit:
        paths = [path for path in paths if not computed_at(path, args.skip_commit)]
    if args.action == "list":
        for path in paths:
            print(path.relative_to(HERE))
        seconds = sum(float((load_document(path) or {}).get("seconds", 0.0)) for path in paths)
        print(f"{len(paths)} documents, {seconds:,.0f} s recorded")
    elif args.action == "pin":
        print(f"pinned {pin(args.study, paths, args.copy)} documents of {args.study}")
    else:
        changed, total = recompute(args.study, paths, args.workers)
        print(f"recomputed {total} documents of {args.study}: {changed} changed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
