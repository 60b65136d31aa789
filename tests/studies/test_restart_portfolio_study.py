"""The restart portfolio's table in ``benchmarks/functions/README.md`` is rendered from the committed runs."""

from __future__ import annotations

import shutil
from pathlib import Path

from benchmarks.functions import portfolio
from benchmarks.provenance import is_recorded
from benchmarks.study_runner import run_all
from benchmarks.study_tools import RunSpec


def test_the_committed_table_is_drawn_from_the_committed_runs(tmp_path: Path) -> None:
    readme = tmp_path / "README.md"
    shutil.copy(portfolio.HERE / "README.md", readme)
    assert portfolio.main(["--render-only", "--readme", str(readme)]) == 0
    assert readme.read_text(encoding="utf-8") == (portfolio.HERE / "README.md").read_text(encoding="utf-8")
    assert "not computed yet" not in readme.read_text(encoding="utf-8")


def test_every_run_is_committed_and_the_new_ones_record_their_provenance() -> None:
    specs = portfolio.make_specs()
    documents = run_all(specs, portfolio.HERE / "runs", workers=1, compute=False, log=str)
    cells = sum(len(portfolio.CELLS) if v[3] is None else len(v[3]) for v in portfolio.VARIANTS)
    assert len(documents) == len(specs) == cells * portfolio.SEEDS
    for document in documents:
        spec = RunSpec(**document["spec"])
        if not spec.options:  # the default's runs: computed again with the restart defaults of issue 33
            assert is_recorded(document["provenance"]), spec.key


def test_the_differ_column_counts_the_seeds_whose_curve_is_not_the_defaults() -> None:
    def document(values, hit):
        return {"hit": hit, "final": values[-1], "total_episodes": 50 * len(values), "values": values}

    default = [document([3.0, 2.0], None), document([3.0, 1e-6], 100)]
    other = [document([3.0, 1e-6], 100), document([3.0, 1e-6], 100)]
    row = portfolio._row("cell | variant", other, default)
    assert row == "| cell | variant | 2/2 | 100 | – | 1e-06 | 1 |"
    assert portfolio._row("cell | default", default, None) == "| cell | default | 1/2 | 100 | 100 | 2 | – |"
