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
``checkpoint.npz``        the last checkpoint (format ``creps_gym.run/3``: ``.npz`` arrays + one embedded
                          JSON document, never pickle), replaced atomically (temporary file + rename; the
                          run's own temporaries left by a killed process are removed when the run
                          resumes). It holds the optimiser's and the loop's state, not the history (that
                          is in the log: :mod:`creps_gym.runner.rundir.recovery`), and records the run's
                          :func:`~creps_gym.runner.rundir.checkpoint.config_fingerprint`: another
                          run's is refused
``run.lock``              the live writer's process id (see :mod:`creps_gym.runner.rundir.session`)
``best_policy.npz``       the best evaluated mean policy, ``policy.npz`` the final one
                          (:mod:`creps_gym.runner.rundir.policies`; ``creps_gym.load_policy(folder)``)
``history.json`` / .csv   the final :class:`~creps_gym.runner.history.History` (written at the end)
``iohanalyzer.csv``       the evaluations in IOHanalyzer's CSV layout (written at the end)
``learning_curve.png``    the plot written by ``creps-gym run`` (when matplotlib is installed)
========================= ===========================================================================

A run directory is untrusted input: a damaged file raises :class:`RunDirError` (a ``ValueError``) naming
the file and what to do, and ``config.json`` is checked by
:func:`creps_gym.runner.rundir.references.check_trusted`. Every file is read and written through
:mod:`creps_gym.runner.rundir.files`: only regular files, never through a link, with bounded reads. The log's
lines are described in :mod:`creps_gym.runner.rundir.log_chain`.
"""

from __future__ import annotations

import functools
import json
import os
import platform
import re
import sys
import warnings
from dataclasses import replace
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from creps_gym.errors import RunDirError, RunDirWarning
from creps_gym.optimizers.base import load_state, save_state
from creps_gym.runner.config import RunConfig
from creps_gym.runner.history import History, IterationRecord
from creps_gym.runner.ioh import iohanalyzer_text
from creps_gym.runner.rundir import files
from creps_gym.runner.rundir.checkpoint import checkpoint_document, config_fingerprint, open_checkpoint
from creps_gym.runner.rundir.log_chain import log_line, parse_log, record_chain
from creps_gym.runner.rundir.recovery import RESTART, read_history
from creps_gym.runner.rundir.references import check_trusted
from creps_gym.runner.rundir.session import RunLock

__all__ = ["RESTART", "RunDir", "package_versions"]


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
    LOCK = "run.lock"
    BEST_POLICY, POLICY = "best_policy.npz", "policy.npz"
    FILES = (CONFIG, VERSIONS, LOG, CHECKPOINT, HISTORY_JSON, HISTORY_CSV, IOH, PLOT, BEST_POLICY, POLICY)
    #: The run's own temporary files: ``.NAME.PID.tmp`` (:func:`creps_gym._files.replace_atomically`) and
    #: ``checkpoint.npzXXXXXXXX.tmp`` (``save_state``'s before it used it). Other ``*.tmp`` files are the
    #: user's and are never touched.
    TEMPORARY = re.compile(
        r"^(\.(" + "|".join(map(re.escape, FILES)) + r")\.\d+|" + re.escape(CHECKPOINT) + r"\w+)\.tmp$"
    )

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.lock = RunLock(self.path / self.LOCK)
        self._fingerprint: str | None = None

    @classmethod
    def owns(cls, path: str | os.PathLike[str]) -> bool:
        """Whether ``path`` is a run directory's own file: a run file's name (or a run's temporary) in a
        folder that holds a ``config.json``, ``checkpoint.npz`` or ``log.jsonl`` (outputs never go there)."""
        path = Path(path)
        own = path.name in (*cls.FILES, cls.LOCK) or cls.TEMPORARY.match(path.name) is not None
        return own and any(os.path.lexists(path.parent / n) for n in (cls.CONFIG, cls.CHECKPOINT, cls.LOG))

    def file(self, name: str) -> Path:
        """Path of one of the files."""
        return self.path / name

    def damaged(self, name: str, error: BaseException | str, advice: str) -> RunDirError:
        """The error for a damaged file: names the file, what is wrong and what to do."""
        what = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
        return RunDirError(f"{self.file(name)}: damaged or not written by creps_gym ({what}); {advice}")

    @classmethod
    def create(
        cls, path: str | os.PathLike[str], config: RunConfig, meta: dict[str, Any], *, overwrite: bool = False
    ) -> RunDir:
        """Start a new run directory (an empty or new folder, or a run with ``overwrite``) and lock it.

        A folder that holds other files than a run's raises ``FileExistsError``, and so does one that holds
        a run (or the files of one without its ``config.json``) unless ``overwrite`` is True: then the
        run's files (those listed in the module docstring, and nothing else) are deleted first.
        """
        run_dir = cls(path)
        try:
            if run_dir.path.exists() and not run_dir.path.is_dir():
                raise NotADirectoryError(f"out: expected a directory, got the file {run_dir.path}")
            run_dir.path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            if isinstance(exc, NotADirectoryError) and exc.errno is None:
                raise
            raise files.os_failure(run_dir.path, exc, "create it", "choose another path") from None
        run_dir.lock.acquire()
        try:
            run_dir._check_new(overwrite)
            run_dir.remove_temporaries()
            for name in cls.FILES:
                try:
                    run_dir.file(name).unlink(missing_ok=True)
                except OSError as exc:  # e.g. a folder of that name
                    raise files.os_failure(run_dir.file(name), exc, "delete it") from None
        except BaseException:
            run_dir.lock.release()
            raise
        document = {"config": config.to_dict(), "meta": meta}
        run_dir.write_file(cls.CONFIG, json.dumps(document, indent=1, allow_nan=False) + "\n")
        run_dir.write_file(cls.VERSIONS, json.dumps(package_versions(), indent=1) + "\n")
        return run_dir

    def write_file(self, name: str, data: str | bytes) -> None:
        """Replace the file ``name`` atomically (:func:`creps_gym.runner.rundir.files.write_run_file`)."""
        files.write_run_file(self.file(name), data.encode() if isinstance(data, str) else data)

    def _check_new(self, overwrite: bool) -> None:
        entries = sorted(
            p.name for p in self.path.iterdir() if p.name != self.LOCK and not self.TEMPORARY.match(p.name)
        )
        foreign = [name for name in entries if name not in self.FILES]
        if self.CONFIG in entries:
            if not overwrite:
                raise FileExistsError(
                    f"out: expected a new or empty directory, got {self.path} which holds a run "
                    "(continue it with `resume`, pass overwrite=True to replace it, or choose another "
                    "directory)"
                )
        elif foreign:
            raise FileExistsError(
                f"out: expected a new or empty directory (or a run to overwrite), got {self.path} which "
                f"holds other files ({', '.join(foreign[:5])}{', ...' if len(foreign) > 5 else ''}); choose "
                "another directory"
            )
        elif entries and not overwrite:
            raise FileExistsError(
                f"out: expected a new or empty directory, got {self.path} which holds {', '.join(entries)} "
                f"but no {self.CONFIG} (the rest of a run); pass overwrite=True to delete them, or choose "
                "another directory"
            )

    @classmethod
    def open(cls, path: str | os.PathLike[str]) -> RunDir:
        """An existing run directory (``FileNotFoundError`` naming the path if it is not one)."""
        run_dir = cls(path)
        try:
            os.stat(run_dir.path)
        except FileNotFoundError:
            raise FileNotFoundError(
                f"run directory: expected a folder with {cls.CONFIG}, got {run_dir.path}, which does not "
                "exist"
            ) from None
        except OSError as exc:  # e.g. a name too long
            raise files.os_failure(run_dir.path, exc, "open it", "check the path") from None
        if not files.check_regular(run_dir.file(cls.CONFIG)):  # a link or a FIFO is refused
            extra = ""
            if run_dir.file(cls.CHECKPOINT).exists():
                extra = f" ({cls.CHECKPOINT} without its {cls.CONFIG} cannot be matched with a configuration)"
            raise FileNotFoundError(
                f"run directory: expected a folder with {cls.CONFIG}, got {run_dir.path}{extra}"
            )
        return run_dir

    def document(self) -> dict[str, Any]:
        """``config.json``'s content ``{"config": ..., "meta": ...}`` (:class:`RunDirError` if damaged)."""
        try:
            data = files.read_run_file(self.file(self.CONFIG)).decode("utf-8")
            document = files.json_document(data, self.CONFIG)
            if not isinstance(document, dict) or not isinstance(document.get("config"), dict):
                raise ValueError("expected a JSON object with a 'config' object")
            if not isinstance(document.get("meta", {}), dict):
                raise ValueError(f"expected a 'meta' object, got {type(document['meta']).__name__}")
        except (OSError, ValueError) as exc:
            raise self.damaged(self.CONFIG, exc, "restore it from a backup or start a new run") from None
        return document

    def config(self) -> RunConfig:
        """The run's configuration, checked by :func:`~creps_gym.runner.rundir.references.check_trusted`.

        Its ``ray_address`` is None: ``config.json`` records the cluster a run was started on, but a run
        directory never chooses the Ray cluster a resumed run joins (connecting to a cluster lets it run
        code in this process, and clusters come and go). A resume joins ``RAY_ADDRESS``'s cluster, or an
        initialised Ray, else starts a local one; the history is the same on any of them.
        """
        data = dict(self.document()["config"])
        data.setdefault("context_draws", "reset")  # written before batched draws (format 2): its stream
        try:
            config = RunConfig.from_dict(data)
        except (TypeError, ValueError) as exc:
            if isinstance(exc, RunDirError):
                raise
            raise self.damaged(self.CONFIG, exc, "restore it from a backup or start a new run") from None
        check_trusted(config, str(self.file(self.CONFIG)))
        return replace(config, ray_address=None)

    def fingerprint(self) -> str:
        """The :func:`~creps_gym.runner.rundir.checkpoint.config_fingerprint` of ``config.json``'s config.

        It imports nothing (unlike :meth:`config`, it does not check the names in it).
        """
        data = dict(self.document()["config"])
        data.setdefault("context_draws", "reset")
        try:
            return config_fingerprint(RunConfig.from_dict(data))
        except (TypeError, ValueError) as exc:
            raise self.damaged(self.CONFIG, exc, "restore it from a backup or start a new run") from None

    # -- log -------------------------------------------------------------------------------------------------
    def append_log(self, entry: dict[str, Any], *, log_crc: int | None = None) -> None:
        """Append one JSON line, ending with the ``crc32`` of the rest, so damage is found.

        An iteration record passes ``log_crc``, the checksum of the iterations before it: the line then
        gets its ``"chain"`` (:func:`record_chain`). A line cut by a crash is closed first so it stays one
        bad line.
        """
        if log_crc is not None:
            if self._fingerprint is None:
                self._fingerprint = self.fingerprint()
            entry = {**entry, "chain": record_chain(self._fingerprint, log_crc, entry)}
        files.append_run_file(self.file(self.LOG), log_line(entry))

    def read_log(
        self, damaged: list[int] | None = None, chains: dict[int, int | None] | None = None
    ) -> tuple[list[IterationRecord], list[dict[str, Any]]]:
        """Iteration records (last copy of each, in order) and events.

        Damaged lines are never skipped silently: their (1-based) numbers are appended to ``damaged`` when
        it is given, else a :class:`RunDirWarning` names them. ``chains`` gets each kept record's
        ``"chain"`` (None if its line has none).
        """
        path = self.file(self.LOG)
        try:
            data = files.read_run_file(path)
        except FileNotFoundError:
            data = b""
        records, events, bad, found = parse_log(data, self.LOG)
        if chains is not None:
            chains.update(found)
        if damaged is not None:
            damaged.extend(bad)
        elif bad:
            warnings.warn(f"{path}: damaged lines {bad} were skipped", RunDirWarning, stacklevel=2)
        return [records[k] for k in sorted(records)], events

    def remove_temporaries(self) -> list[Path]:
        """Delete the run's own temporaries (:attr:`TEMPORARY`) left by a writer killed before its rename.

        Call it only with the lock held: then any such file belongs to a dead writer. Returns the files.
        """
        stale = sorted(p for p in self.path.iterdir() if self.TEMPORARY.match(p.name))
        for path in stale:
            try:
                path.unlink(missing_ok=True)
            except OSError as exc:  # e.g. a folder of that name
                raise files.os_failure(path, exc, "delete this temporary file") from None
        return stale

    # -- checkpoint ------------------------------------------------------------------------------------------
    def save_checkpoint(
        self, state: dict[str, Any], optimizer_state: dict[str, Any], config: RunConfig
    ) -> Path:
        """Write the runner's state, the optimiser's ``state_dict()`` and ``config``'s fingerprint."""
        flat = checkpoint_document(state, optimizer_state, config)
        path = self.file(self.CHECKPOINT)
        files.check_regular(path)
        try:
            save_state(flat, path)
            os.chmod(path, os.lstat(self.file(self.CONFIG)).st_mode & 0o777)  # one mode for the run's files
        except OSError as exc:
            raise files.os_failure(path, exc, "write it") from None
        return path

    def load_checkpoint(
        self, config: RunConfig | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]] | None:
        """``(runner state, optimiser state)`` of the last checkpoint, or None if there is none yet.

        With ``config``, a checkpoint written under another configuration (another seed, env, dimension,
        optimiser, ...) raises :class:`RunDirError`, and so does a damaged one. A checkpoint of an older
        format is upgraded to the current form here, once
        (:func:`~creps_gym.runner.rundir.checkpoint.open_checkpoint`).
        """
        path = self.file(self.CHECKPOINT)
        try:
            stream = files.open_binary(path)
        except FileNotFoundError:
            return None
        try:
            with stream:
                flat = load_state(stream)
        except Exception as exc:  # an untrusted file: every way of failing to parse it is damage
            raise self.damaged(self.CHECKPOINT, exc, RESTART) from None
        damaged = functools.partial(self.damaged, self.CHECKPOINT, advice=RESTART)
        return open_checkpoint(flat, config, str(path), RESTART, damaged)

    # -- results ---------------------------------------------------------------------------------------------
    def write_results(self, history: History, *, only_changed: bool = False) -> list[str]:
        """Write ``history.json``, ``history.csv`` and ``iohanalyzer.csv``; returns the names written.

        With ``only_changed``, a file whose content is already right is left alone (a missing, truncated or
        damaged one is rewritten).
        """
        texts = {
            self.HISTORY_JSON: history.json_text(),
            self.HISTORY_CSV: history.csv_text(),
            self.IOH: iohanalyzer_text([history]),
        }
        written = []
        for name, text in texts.items():
            if only_changed and self._holds(name, text):
                continue
            self.write_file(name, text)
            written.append(name)
        return written

    def _holds(self, name: str, text: str) -> bool:
        """Whether the file ``name`` holds ``text`` (for JSON: the same document, keys in any order)."""
        try:
            found = files.read_run_file(self.file(name)).decode("utf-8")
            if name.endswith(".json"):
                return files.json_document(found, name) == json.loads(text)
            return found == text
        except (OSError, ValueError):
            return False

    def read_history(self) -> History:
        """The run's history: see :func:`creps_gym.runner.rundir.recovery.read_history`."""
        return read_history(self)
