"""The run directory: everything a run writes, and what ``creps-gym resume`` reads back.

========================= ===========================================================================
file                      content
========================= ===========================================================================
``config.json``           the resolved :class:`~creps_gym.runner.config.RunConfig` and run metadata
``versions.json``         Python, creps_gym, gymnasium, numpy, scipy, mujoco, gymnasium-robotics, and the
                          adapters' libraries (cma, nevergrad, optuna) and ray versions, platform
``log.jsonl``             append-only log, one JSON object per line: an iteration record
                          (:meth:`IterationRecord.to_dict`) or an event (``{"event": "start" | "resume" |
                          "end", ...}``). After a resume, iterations done after the last checkpoint appear
                          again; :meth:`RunDir.read_log` keeps the last copy of each iteration.
``checkpoint.npz``        the last checkpoint (``.npz`` arrays + one embedded JSON document, never pickle),
                          replaced atomically (temporary file + rename; temporaries left by a killed
                          process are removed when the run resumes)
``history.json`` / .csv   the final :class:`~creps_gym.runner.history.History` (written at the end)
``iohanalyzer.csv``       the evaluations in IOHanalyzer's CSV layout (written at the end)
``learning_curve.png``    the plot written by ``creps-gym run`` (when matplotlib is installed)
========================= ===========================================================================
"""

from __future__ import annotations

import json
import os
import platform
import sys
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from creps_gym.optimizers.base import load_state, save_state
from creps_gym.runner.config import RunConfig
from creps_gym.runner.history import IterationRecord, atomic_write_text

__all__ = ["RunDir", "package_versions"]

CHECKPOINT_FORMAT = "creps_gym.run/1"


def package_versions() -> dict[str, str]:
    """Versions of Python and of the packages a run depends on ("not installed" where missing)."""
    found = {"python": sys.version.split()[0], "platform": platform.platform()}
    packages = ("creps-gym", "gymnasium", "numpy", "scipy", "mujoco", "gymnasium-robotics")
    for package in (*packages, "cma", "nevergrad", "optuna", "ray"):  # ... and the adapters' libraries
        try:
            found[package] = version(package)
        except PackageNotFoundError:
            found[package] = "not installed"
    return found


class RunDir:
    """A run directory (see the module docstring for its files)."""

    CONFIG = "config.json"
    VERSIONS = "versions.json"
    LOG = "log.jsonl"
    CHECKPOINT = "checkpoint.npz"
    HISTORY_JSON = "history.json"
    HISTORY_CSV = "history.csv"
    IOH = "iohanalyzer.csv"
    PLOT = "learning_curve.png"

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)

    def file(self, name: str) -> Path:
        """Path of one of the files."""
        return self.path / name

    @classmethod
    def create(
        cls, path: str | os.PathLike[str], config: RunConfig, meta: dict[str, Any], *, overwrite: bool = False
    ) -> RunDir:
        """Start a new run directory.

        A directory that already holds a run raises ``FileExistsError``, unless ``overwrite`` is True: then
        the run's files (those listed in the module docstring, and nothing else) are deleted first.
        """
        run_dir = cls(path)
        if run_dir.file(cls.CONFIG).exists():
            if not overwrite:
                raise FileExistsError(
                    f"out: expected a new or empty directory, got {run_dir.path} which holds a run "
                    "(continue it with `creps-gym resume`, pass --overwrite, or choose another directory)"
                )
            run_dir.remove_temporaries()
            for name in (cls.CONFIG, cls.VERSIONS, cls.LOG, cls.CHECKPOINT, cls.HISTORY_JSON, cls.HISTORY_CSV,
                         cls.IOH, cls.PLOT):  # fmt: skip
                run_dir.file(name).unlink(missing_ok=True)
        run_dir.path.mkdir(parents=True, exist_ok=True)
        atomic_write_text(run_dir.file(cls.VERSIONS), json.dumps(package_versions(), indent=1) + "\n")
        document = {"config": config.to_dict(), "meta": meta}
        atomic_write_text(run_dir.file(cls.CONFIG), json.dumps(document, indent=1, allow_nan=False) + "\n")
        return run_dir

    @classmethod
    def open(cls, path: str | os.PathLike[str]) -> RunDir:
        """An existing run directory (``FileNotFoundError`` naming the path if it is not one)."""
        run_dir = cls(path)
        if not run_dir.file(cls.CONFIG).is_file():
            raise FileNotFoundError(f"run directory: expected a folder with {cls.CONFIG}, got {run_dir.path}")
        return run_dir

    def document(self) -> dict[str, Any]:
        """The content of ``config.json``: ``{"config": ..., "meta": ...}``."""
        return json.loads(self.file(self.CONFIG).read_text(encoding="utf-8"))

    def config(self) -> RunConfig:
        """The run's configuration."""
        return RunConfig.from_dict(self.document()["config"])

    # -- log -------------------------------------------------------------------------------------------------
    def append_log(self, entry: dict[str, Any]) -> None:
        """Append one JSON line (flushed); a line cut by a crash is closed first so it stays one bad line."""
        path = self.file(self.LOG)
        prefix = ""
        if path.exists() and path.stat().st_size > 0:
            with open(path, "rb") as stream:
                stream.seek(-1, os.SEEK_END)
                prefix = "" if stream.read(1) == b"\n" else "\n"
        with open(path, "a", encoding="utf-8") as stream:
            stream.write(prefix + json.dumps(entry, allow_nan=False) + "\n")
            stream.flush()

    def read_log(self) -> tuple[list[IterationRecord], list[dict[str, Any]]]:
        """Iteration records (last copy of each, in order) and events; malformed lines are skipped."""
        records: dict[int, IterationRecord] = {}
        events: list[dict[str, Any]] = []
        path = self.file(self.LOG)
        lines = path.read_text(encoding="utf-8").splitlines() if path.exists() else []
        for line in lines:
            try:
                entry = json.loads(line)
                if "event" in entry:
                    events.append(entry)
                else:
                    record = IterationRecord.from_dict(entry)
                    records[record.iteration] = record
            except (ValueError, KeyError, TypeError):
                continue
        return [records[k] for k in sorted(records)], events

    def remove_temporaries(self) -> list[Path]:
        """Delete ``*.tmp`` files left by a writer killed before its rename; returns what was removed.

        Only one process may write a run directory at a time, so any temporary file found when a session
        starts belongs to a dead one.
        """
        stale = sorted(self.path.glob("*.tmp")) + sorted(self.path.glob(".*.tmp"))
        for path in stale:
            path.unlink(missing_ok=True)
        return stale

    # -- checkpoint ------------------------------------------------------------------------------------------
    def save_checkpoint(self, state: dict[str, Any], optimizer_state: dict[str, Any]) -> Path:
        """Write the runner's state and the optimiser's ``state_dict()`` atomically to ``checkpoint.npz``."""
        flat = {"format": CHECKPOINT_FORMAT, **state}
        flat.update({f"optimizer.{key}": value for key, value in optimizer_state.items()})
        path = save_state(flat, self.file(self.CHECKPOINT))
        os.chmod(path, self.file(self.CONFIG).stat().st_mode & 0o777)  # one mode for all the run's files
        return path

    def load_checkpoint(self) -> tuple[dict[str, Any], dict[str, Any]] | None:
        """``(runner state, optimiser state)`` of the last checkpoint, or None if there is none yet."""
        path = self.file(self.CHECKPOINT)
        if not path.exists():
            return None
        flat = load_state(path)
        if flat.get("format") != CHECKPOINT_FORMAT:
            raise ValueError(f"checkpoint: expected format {CHECKPOINT_FORMAT!r}, got {flat.get('format')!r}")
        prefix = "optimizer."
        optimizer_state = {k[len(prefix) :]: v for k, v in flat.items() if k.startswith(prefix)}
        state = {k: v for k, v in flat.items() if not k.startswith(prefix) and k != "format"}
        return state, optimizer_state
