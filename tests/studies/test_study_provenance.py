"""Reproduction you can trust (issue 31, item 8): ``--quick`` computes, ``--render-only`` re-renders, and
every committed study says which versions and CPU computed it (:mod:`benchmarks.provenance`)."""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

import pytest
from helpers import EXTRAS, no_figure, study_in_process

from benchmarks import numeric_stack, provenance, study_runner

pytestmark = EXTRAS  # the studies need matplotlib and pycma, and record the full environment's BLAS

REPO = Path(__file__).resolve().parents[2]
BENCHMARKS = REPO / "benchmarks"


def test_a_provenance_record_names_the_versions_the_cpu_the_blas_and_the_commit() -> None:
    record = provenance.provenance(("cma", "no-such-distribution"))
    assert provenance.is_recorded(record)
    packages = record["packages"]
    assert set(packages) >= {"python", "numpy", "scipy", "gymnasium", "cma"}
    assert packages["numpy"] == importlib.import_module("numpy").__version__
    assert packages["no-such-distribution"] == "not installed"
    assert record["cpu"] and record["cpu_count"] >= 1 and record["blas"]["library"]
    assert record["creps_gym_commit"] is None or len(record["creps_gym_commit"].split("-")[0]) == 40
    assert not provenance.is_recorded(provenance.unrecorded())
    assert not provenance.is_recorded({**record, "packages": {"python": "3.11"}})  # numpy & co missing
    text = provenance.provenance_text([record, record, None, provenance.unrecorded()])
    assert f"- 2 runs: python {packages['python']}, numpy {packages['numpy']}" in text
    assert "- 2 runs: computed before provenance was recorded" in text
    assert "- 1 run: computed before" in provenance.provenance_text([None])
    assert record["simd"] == numeric_stack.numpy_simd() and f", numpy SIMD {record['simd'][0]}" in text
    older = {key: value for key, value in record.items() if key != "simd"}  # recorded before the SIMD
    assert "numpy SIMD" not in provenance.provenance_text([older])  # level: its text is as it was


def test_the_committed_stack_is_pinned_only_where_its_kernels_run() -> None:
    x86 = {"AVX2", "FMA3"}
    avx512 = numeric_stack.pinned_environment(x86 | {"AVX512F"}, ["X86_V3", "X86_V4", "AVX512_ICL"])
    assert avx512 == {"OPENBLAS_CORETYPE": "Haswell", "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL"}
    older_names = numeric_stack.pinned_environment(x86, ["AVX2", "AVX512F", "AVX512_SKX"])
    assert older_names["NPY_DISABLE_CPU_FEATURES"] == "AVX512F AVX512_SKX"  # numpy before 2.4
    assert numeric_stack.pinned_environment(x86, ["X86_V3"]) == {"OPENBLAS_CORETYPE": "Haswell"}
    later = numeric_stack.pinned_environment(x86, ["X86_V3", "X86_V4", "AVX10_2"])  # a target yet to come
    assert later["NPY_DISABLE_CPU_FEATURES"] == "X86_V4 AVX10_2"
    assert numeric_stack.pinned_environment({"AVX", "SSE42"}, ["AVX"]) == {}  # no AVX2: Haswell cannot run
    assert numeric_stack.pinned_environment({"ASIMD", "NEON"}, ["ASIMDHP"]) == {}  # not x86-64
    # Asked of a fresh process without numpy's feature variables (this suite's processes have them): the
    # CPU's own targets and features, so on an AVX-512 CPU the targets above X86_V3 too.
    targets, features = numeric_stack._numpy_cpu()
    assert set(targets) >= set(numeric_stack.numpy_simd()) and features
    if "AVX512F" in features:
        assert any(name == "X86_V4" or name.startswith("AVX512") for name in targets), targets


def test_the_stack_differences_name_each_field_that_differs() -> None:
    live = {
        "numpy": importlib.import_module("numpy").__version__,
        "scipy": importlib.import_module("scipy").__version__,
    }
    blas = numeric_stack.blas()
    simd = numeric_stack.numpy_simd()
    assert numeric_stack.differences(live, blas, simd) == []
    found = numeric_stack.differences({**live, "numpy": "1.0"}, {**blas, "architecture": "Zen"}, ["SSE2"])
    assert found == [
        f"numpy: 1.0 there, {live['numpy']} here",
        f"BLAS architecture: Zen there, {blas['architecture']} here",
        f"numpy SIMD: SSE2 there, {' '.join(simd)} here",
    ]
    assert numeric_stack.differences(live, {"library": blas["library"]}, simd) == (
        []
        if blas["architecture"] == "Haswell"
        else [f"BLAS architecture: Haswell there, {blas['architecture']} here"]
    )  # a record without an architecture was computed on the committed machine's


@pytest.mark.slow
def test_quick_computes_every_run_again_and_render_only_redraws_the_cached_ones(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """In process (the scripts' runs by path and ``-m``: test_benchmark_scripts.py), drawing no figure: this
    test checks the cache, ``results.md`` and ``timing.json``."""
    monkeypatch.setattr(importlib.import_module("benchmarks.functions.run"), "plot_function", no_figure)
    cache, out = tmp_path / "cache", tmp_path / "out"
    args = ["--quick", "--functions", "Sphere", "--context-dims", "1", "--seeds", "1", "--dim", "3"]
    args += ["--methods", "creps-cma-old", "cma-fixed", "--budget", "600", "--workers", "1"]
    args += ["--cache", str(cache), "--out", str(out)]
    study_in_process("functions", *args)
    paths = sorted(cache.glob("*.json"))
    assert len(paths) == 2
    for path in paths:
        assert provenance.is_recorded(json.loads(path.read_text())["provenance"])
    assert provenance.is_recorded(json.loads((out / "timing.json").read_text())["provenance"])
    numpy_version = importlib.import_module("numpy").__version__
    assert (
        f"- 2 runs: python {sys.version.split()[0]}, numpy {numpy_version}"
        in (out / "results.md").read_text()
    )
    tampered = {**json.loads(paths[0].read_text()), "final": 1234.5, "provenance": None}
    paths[0].write_text(json.dumps(tampered))
    study_in_process("functions", *args, "--render-only")  # reads the cache as it is
    assert "1 run: computed before provenance was recorded" in (out / "results.md").read_text()
    (out / "timing.json").unlink()
    log = study_in_process("functions", *args)  # --quick: computes both runs again, reading no cached one
    assert "0 runs cached" in log and "2 to compute" in log
    assert json.loads((out / "timing.json").read_text())["computed"] == 2  # not "read from the cache"
    again = json.loads(paths[0].read_text())
    assert again["final"] != 1234.5 and provenance.is_recorded(again["provenance"])
    assert "computed before provenance" not in (out / "results.md").read_text()


def test_quick_and_full_keep_their_runs_apart() -> None:
    """A --quick invocation recomputes its runs in runs/quick/, never the documents --full renders."""
    module = importlib.import_module("benchmarks.functions.run")
    assert module.parse_args(["--quick"]).cache == BENCHMARKS / "functions" / "runs" / "quick"
    assert module.parse_args(["--full"]).cache == BENCHMARKS / "functions" / "runs"
    assert module.parse_args(["--quick", "--cache", "elsewhere"]).cache == Path("elsewhere")


#: Committed renderings of the studies that share ``benchmarks/study_runner.py``, and whether all their runs
#: must carry a provenance record (True: computed since it existed). The others were computed before; their
#: README says so, and which of their figures reproduce bit for bit.
STUDY_RENDERINGS = [
    ("functions", ["--quick"], False),
    ("functions", ["--full"], False),
    ("scaling", ["--quick"], True),
    ("scaling", ["--full"], False),
    ("scaling", ["--full", "--max-interpolation", "0.2", "--baselines"], False),
    ("scaling", ["--full", "--no-z", "--max-interpolation", "0.2", "--baselines"], False),
    ("ccmaes", ["--quick"], False),
    ("ccmaes", ["--full"], False),
]


@pytest.mark.parametrize(
    ("study", "flags", "recorded"),
    STUDY_RENDERINGS,
    ids=[f"{s} {' '.join(f)}" for s, f, _ in STUDY_RENDERINGS],
)
@pytest.mark.slow
def test_every_committed_study_records_the_versions_and_cpu_of_its_runs(
    study: str, flags: list[str], recorded: bool
) -> None:
    module = importlib.import_module(f"benchmarks.{study}.run")
    args = module.parse_args(flags)
    specs = (
        module.make_specs(args)
        if hasattr(module, "make_specs")
        else [s for _, s in module.column_specs(args, str)]
    )
    documents = study_runner.run_all(specs, args.cache, workers=1, compute=False, log=str)
    assert documents, f"no committed runs for {study} {flags}"
    records = [d.get("provenance") for d in documents]
    for record in records:
        assert record is None or provenance.is_recorded(record)  # present means complete
    if recorded:
        assert all(provenance.is_recorded(r) for r in records)
        timing = json.loads((args.out / "timing.json").read_text())
        assert not timing["computed"] or provenance.is_recorded(timing["provenance"])
    else:
        readme = (BENCHMARKS / study / "README.md").read_text(encoding="utf-8")
        assert "recorded before provenance" in readme
    assert provenance.provenance_text(records) in (args.out / "results.md").read_text(encoding="utf-8")


def test_compare_runs_tells_identical_runs_from_those_that_part(tmp_path: Path, capsys) -> None:
    from benchmarks import compare_runs

    document = {"values": [3.0, 2.0, 1.0], "episodes": [50, 100, 150], "hit": None, "final": 1.0}
    for cache, last in (("a", 1.0), ("b", 1.5)):
        (tmp_path / cache).mkdir()
        (tmp_path / cache / "same.json").write_text(json.dumps(document))
        parted = {**document, "values": [3.0, 2.0, last], "final": last}
        (tmp_path / cache / "parted.json").write_text(json.dumps(parted))
    assert compare_runs.main([str(tmp_path / "a"), str(tmp_path / "b")]) == 1
    out = capsys.readouterr().out
    assert "same: same" in out and "1 of 2 runs bit-identical" in out
    assert "parted: differ from curve point 2 of 3 (relative difference 5.0e-01); hit None / None" in out
    assert "- 2 runs: computed before provenance was recorded" in out
    assert compare_runs.main([str(tmp_path / "a"), str(tmp_path / "a")]) == 0


@pytest.mark.parametrize("suffix", ["_quick", ""])
def test_the_reacher_study_renders_its_table_from_its_results_json(suffix: str) -> None:
    from benchmarks.reacher import run as reacher

    path = BENCHMARKS / "reacher" / f"results{suffix}.json"
    if not path.exists():  # full results computed before results.json existed: the README says so
        assert suffix == "", "the quick results must be recorded (python benchmarks/reacher/run.py --quick)"
        readme = (BENCHMARKS / "reacher" / "README.md").read_text(encoding="utf-8")
        assert "recorded before provenance" in readme
        return
    document = json.loads(path.read_text(encoding="utf-8"))
    assert provenance.is_recorded(document["provenance"])
    committed = (BENCHMARKS / "reacher" / f"results{suffix}.md").read_text(encoding="utf-8")
    assert reacher.report_text(document) == committed
    assert len(document["fig4b"]["params"]) == 25
