"""Execute every tutorial notebook in quick mode (``CREPS_GYM_QUICK=1``), as CI does, so they never rot.

The notebooks are generated and executed by ``notebooks/make_notebooks.py``: the committed files must have
its cell sources and carry the outputs of a full-mode run (so the figures show on the repository page).
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

NOTEBOOKS = Path(__file__).resolve().parents[2] / "notebooks"
NAMES = sorted(path.name for path in NOTEBOOKS.glob("*.ipynb"))


def _generator():
    spec = importlib.util.spec_from_file_location("make_notebooks", NOTEBOOKS / "make_notebooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_three_tutorials_exist() -> None:
    assert NAMES == ["01_quickstart.ipynb", "02_compare_optimisers.ipynb", "03_robot_tasks.ipynb"]


def _outputs(notebook) -> list:
    return [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.outputs]


def _check_executed(notebook, name: str, quick: bool) -> None:
    assert all(c.execution_count is not None for c in notebook.cells if c.cell_type == "code"), name
    outputs = _outputs(notebook)
    assert not [o for o in outputs if o.output_type == "error"]
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    assert f"quick mode: {quick}" in text
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert images, f"{name}: expected at least one figure in the outputs, got none"


@pytest.mark.parametrize("name", NAMES)
def test_committed_notebook_matches_its_generator_and_carries_full_mode_outputs(name: str) -> None:
    committed = nbformat.read(NOTEBOOKS / name, as_version=4)
    cells = _generator().NOTEBOOKS[name.removesuffix(".ipynb")]
    assert [c.source for c in committed.cells] == [c.source for c in cells]
    _check_executed(committed, name, quick=False)


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_notebook_runs_in_quick_mode(name: str) -> None:
    generator = _generator()
    notebook = generator.build(generator.NOTEBOOKS[name.removesuffix(".ipynb")])
    generator.execute(notebook, quick=True, timeout=120)  # CellExecutionError, naming the cell, on failure
    _check_executed(notebook, name, quick=True)


@pytest.mark.parametrize("name", NAMES)
def test_committed_outputs_hold_no_machine_path_or_warning(name: str) -> None:
    outputs = _outputs(nbformat.read(NOTEBOOKS / name, as_version=4))
    texts = [o.get("text", "") for o in outputs] + [o.get("data", {}).get("text/plain", "") for o in outputs]
    text = "".join(texts)
    assert not re.search(r"/root/|/home/|/Users/|/tmp/|site-packages|[A-Z]:\\", text), text
    assert "Warning" not in text and "WARN" not in text and "\x1b[" not in text, text


@pytest.mark.parametrize("name", NAMES)
def test_notebooks_use_only_current_env_versions(name: str) -> None:
    import gymnasium as gym

    import creps_gym  # noqa: F401  (registers the ids)

    source = "".join(c.source for c in _generator().NOTEBOOKS[name.removesuffix(".ipynb")])
    for env_name, version in re.findall(r"creps_gym/(\w+)-v(\d+)", source):
        newer = [i for i in gym.registry if re.fullmatch(rf"creps_gym/{env_name}-v(\d+)", i)]
        assert max(int(i.rsplit("-v", 1)[1]) for i in newer) == int(version), (env_name, version, newer)
