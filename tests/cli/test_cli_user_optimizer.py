"""Your own optimiser from the command line (issue 31, item 3), through real ``creps-gym`` processes.

The module is the one ``docs/writing_an_adapter.md`` shows, and the commands are the guide's, so the guide
cannot rot. ``--import`` is applied before any name is checked, in ``run``, ``resume``, ``plot`` and
``export``; the current directory is searched for it last, and never otherwise.
"""

from __future__ import annotations

import csv
import re
import shlex
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest
from helpers import EXTRAS, cli_command

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "writing_an_adapter.md"
SECTION = GUIDE.read_text().split("## Your own optimiser from the command line", 1)[1].split("\n## ", 1)[0]
MODULE = re.search(r"```python\n(.*?)```", SECTION, flags=re.DOTALL).group(1)
COMMANDS = [
    shlex.split(line.split("#", 1)[0])[1:]
    for line in re.search(r"```bash\n(.*?)```", SECTION, flags=re.DOTALL)
    .group(1)
    .replace("\\\n", "")
    .splitlines()
]
#: A module that shadows scipy and leaves a mark when it is imported.
SHADOW = "open(__file__ + '.imported', 'w').close()\nraise ImportError('the shadow scipy.py was imported')\n"


def cli(*args, cwd, timeout=180):
    return subprocess.run(cli_command(*args), capture_output=True, text=True, cwd=cwd, timeout=timeout)


def _workspace(tmp_path: Path) -> Path:
    (tmp_path / "my_search.py").write_text(MODULE)
    (tmp_path / "scipy.py").write_text(SHADOW)  # must never be imported: cwd is searched last, for --import
    return tmp_path


@pytest.fixture(scope="module")
def _ran_once(tmp_path_factory: pytest.TempPathFactory) -> Path:
    work = _workspace(tmp_path_factory.mktemp("workspace"))
    run = cli(*COMMANDS[0][:-2], "--out", "runs/x", "--iterations", "3", "--no-plot", cwd=work)
    assert run.returncode == 0, run.stderr
    return work


@pytest.fixture
def ran(_ran_once: Path, tmp_path: Path) -> Path:
    """A workspace in which the guide's ``run`` (with ``--import``) ran 3 iterations into ``runs/x``, in a
    process of its own: a copy, in ``tmp_path``, of the one computed once per module (the run folder names
    no absolute path). A ``scipy.py.imported`` mark the run left would be copied too."""
    shutil.copytree(_ran_once, tmp_path, dirs_exist_ok=True)
    return tmp_path


@EXTRAS  # `plot` needs matplotlib
@pytest.mark.slow
def test_the_guide_module_is_short_and_its_commands_run_resume_plot_and_export(tmp_path):
    work = _workspace(tmp_path)
    code = [
        line for line in MODULE.splitlines() if line.strip() and not line.lstrip().startswith(('"""', "#"))
    ]
    assert len(code) <= 25, len(code)  # the "20-line adapter" of the issue, checkpoints included
    assert [command[0] for command in COMMANDS] == ["run", "resume", "plot", "export"]
    outputs = []
    for command in COMMANDS:
        result = cli(*command, *(["--no-plot"] if command[0] in ("run", "resume") else []), cwd=work)
        assert result.returncode == 0, (command, result.stderr)
        outputs.append(result.stdout)
    assert all("iterations 40, episodes 320" in out and "stop: iterations" in out for out in outputs[:2])
    assert (work / "my-search.png").stat().st_size > 0
    with open(work / "my-search.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    assert rows and {row["algorithm_id"] for row in rows} == {"my-search"}
    assert not (work / "scipy.py.imported").exists()


@pytest.mark.slow
def test_without_import_every_command_refuses_the_run_and_names_the_flag(ran):
    """In processes: a user's optimiser registered by one command must not be known to the next."""
    work = ran
    for command in (
        ["resume", "runs/x"],
        ["plot", "runs/x", "-o", "x.png"],
        ["export", "runs/x", "-o", "x.csv"],
    ):
        result = cli(*command, cwd=work)
        assert result.returncode == 3 and "--import MODULE" in result.stderr, (command, result.stderr)
    unknown = cli(*[a for a in COMMANDS[0] if a not in ("--import", "my_search")], cwd=work)
    assert unknown.returncode == 2 and "argument --optimizer: expected one of [" in unknown.stderr
    assert "got 'my-search'" in unknown.stderr and "Traceback" not in unknown.stderr
    assert not (work / "scipy.py.imported").exists()


@EXTRAS  # `plot` needs matplotlib
@pytest.mark.slow
def test_a_run_folder_never_puts_its_files_on_the_path(ran):
    work = ran
    folder = work / "runs" / "x"
    (folder / "scipy.py").write_text(SHADOW)
    (folder / "my_search.py").write_text(MODULE.replace("my-search", "folder-search"))
    inside = cli("resume", ".", "--no-plot", cwd=folder)  # python -m puts the folder first on sys.path
    assert inside.returncode == 3 and "--import MODULE" in inside.stderr, inside.stderr
    outside = cli("plot", "runs/x", "-o", "x.png", "--import", "my_search", cwd=work)
    assert outside.returncode == 0, outside.stderr  # the cwd's module, not the folder's
    assert not (folder / "scipy.py.imported").exists() and not (work / "scipy.py.imported").exists()


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.slow
def test_ctrl_c_names_the_run_folder_and_resume_with_import_finishes_the_run(tmp_path):
    work = _workspace(tmp_path)
    args = [*COMMANDS[0][:-2], "--out", "runs/long run", "--iterations", "1000000", "--max-time", "3"]
    args += ["--checkpoint-every", "1", "--no-plot", "--no-progress"]
    # As a terminal's Ctrl-C finds it: a test run started in the background (`cmd &` in a script) inherits
    # SIGINT ignored, and the command rightly leaves an ignored SIGINT alone.
    process = subprocess.Popen(
        cli_command(*args), cwd=work, stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint
    )
    checkpoint = work / "runs" / "long run" / "checkpoint.npz"
    deadline = time.monotonic() + 120
    while not checkpoint.exists() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    assert "interrupted; `creps-gym resume 'runs/long run'` continues from the last checkpoint" in stderr
    resumed = cli("resume", "runs/long run", "--import", "my_search", "--no-plot", cwd=work)
    assert resumed.returncode == 0 and "stop: max_time" in resumed.stdout, resumed.stderr
