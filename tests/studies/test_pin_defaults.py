"""``benchmarks/pin_defaults.py`` and ``study_options.pin_c3``: issue 45's default change (C3 → C3r) and
c-bo's refit default of 2026-11-30 carried over the committed study runs, which were computed with the
former defaults and are pinned to them."""

from __future__ import annotations

import json

import pytest

from benchmarks import pin_defaults
from benchmarks.contextual_bbo.protocol import ProtocolSpec
from benchmarks.study_options import C3_PIN, CBO_FIT_PIN, CBO_FLOOR_PIN, CBO_LOG_PIN, CBO_PINS, pin_c3
from benchmarks.study_tools import RunSpec


def test_the_pin_is_added_to_c_cma_es_only_and_never_over_a_chosen_ridge_centre():
    assert pin_c3("c-cma-es") == C3_PIN == (("ridge_centre", "zero"),)
    assert pin_c3("c-cma-es-surrogate", {"restarts": 0}) == (("restarts", 0), ("ridge_centre", "zero"))
    assert pin_c3("c-cma-es", [["ridge_centre", "old"]]) == (("ridge_centre", "old"),)
    assert pin_c3("creps-cma-old", (("epsilon", 1.0),)) == (("epsilon", 1.0),)


def test_a_document_keyed_by_its_options_is_renamed_to_the_pinned_key(tmp_path):
    spec = RunSpec("Sphere", 3, 1, "c-cma-es", 0, 1000, options=(("restarts", 0),))
    document = {"spec": {**spec.__dict__, "options": [["restarts", 0]]}, "hit": 7}
    path, new = pin_defaults.pinned("functions", tmp_path / f"{spec.key}.json", document)
    assert path.name == "Sphere-p3-z1-c-cma-es-restarts=0-ridge_centre=zero-s0-b1000-n50.json"
    assert new["spec"]["options"] == [["restarts", 0], ["ridge_centre", "zero"]] and new["hit"] == 7
    assert RunSpec(**dict(new["spec"], options=tuple(map(tuple, new["spec"]["options"])))).key == path.stem
    assert pin_defaults.pinned("functions", path, new) is None  # once only
    creps = {"spec": {**RunSpec("Sphere", 3, 1, "creps", 0, 1000).__dict__, "options": []}}
    assert pin_defaults.pinned("functions", tmp_path / "x.json", creps) is None


def test_a_labelled_or_recorded_document_keeps_its_key_and_file_name(tmp_path):
    protocol = {"function": "Sphere", "method": "c-cma-es", "seed": 3, "options": {}, "label": ""}
    path, new = pin_defaults.pinned("contextual_bbo", tmp_path / "a.json", {"spec": protocol})
    assert path.name == "a.json" and new["spec"]["label"] == "c-cma-es"
    options = tuple(new["spec"]["options"].items())
    pinned = ProtocolSpec(**{**new["spec"], "options": options})
    assert pinned.key == ProtocolSpec("Sphere", "c-cma-es", 3).key  # the label is the method's name
    low = {"method": {"optimizer": "c-cma-es-surrogate", "options": {}, "selector": None}}
    assert pin_defaults.pinned("low_budget", tmp_path / "b.json", low)[1]["method"]["options"] == {
        "ridge_centre": "zero"
    }
    kick = {"name": "c-cma-es", "options": {"c_m": 0.5}, "setting": {"options": {"c_m": 0.5}}}
    _, new = pin_defaults.pinned("kick", tmp_path / "c-cma-es-trial0.json", kick)
    assert new["options"] == new["setting"]["options"] == {"c_m": 0.5, "ridge_centre": "zero"}
    assert pin_defaults.pinned("kick", tmp_path / "c-cma-es-trial0.selector.json", {"setting": {}}) is None
    with pytest.raises(ValueError, match="study: expected one of"):
        pin_defaults.pinned("reacher", tmp_path / "d.json", {})


def test_a_low_budget_c_bo_run_gets_c_bos_pins_and_keeps_the_options_it_chose(tmp_path):
    """c-bo's pins (its refit data, its log scale and MES's floor) are added to every c-bo column's
    document (the library columns' too), beside the options the column sets; an option the run set itself
    keeps its value; a document with every pin is left alone, one pinned before the later pins gets them."""

    def low(options: dict, factory: str | None = None) -> dict:
        method = {"optimizer": "c-bo", "options": options, "selector": None}
        return {"method": method if factory is None else {**method, "factory": factory}}

    path = tmp_path / "a.json"
    pinned = pin_defaults.pinned("low_budget", path, low({"acquisition": "ucb"}))[1]["method"]["options"]
    assert pinned == {"acquisition": "ucb", **dict(CBO_PINS)}
    library = pin_defaults.pinned("low_budget", path, low({}, "benchmarks.low_budget.sklearn_cbo:SklearnCBO"))
    assert library[1]["method"]["options"] == dict(CBO_PINS)
    chosen = pin_defaults.pinned("low_budget", path, low({"fit_subset": "spread"}))[1]["method"]["options"]
    assert chosen == {
        "fit_points": 256,
        "fit_subset": "spread",
        "log_quantile": 0.5,
        "mes_floor": "candidates",
    }
    assert pin_defaults.pinned("low_budget", path, low(dict(CBO_PINS))) is None
    earlier = pin_defaults.pinned("low_budget", path, low(dict(CBO_FIT_PIN)))[1]["method"]["options"]
    assert earlier == dict(CBO_PINS) and dict(CBO_LOG_PIN) == {"log_quantile": 0.5}
    assert dict(CBO_FLOOR_PIN) == {"mes_floor": "candidates"}
    creps = {"method": {"optimizer": "creps", "options": {"epsilon": 1.0}, "selector": None}}
    assert pin_defaults.pinned("low_budget", path, creps) is None


@pytest.mark.parametrize("study", ["functions", "ccmaes", "scaling", "contextual_bbo", "low_budget", "kick"])
def test_every_committed_run_is_pinned(study):
    """No committed document of ``c-cma-es`` or its surrogate runs without an explicit ``ridge_centre``, and
    no low-budget c-bo run without its refit options: a default's change cannot make a study recompute or
    misread one."""
    assert pin_defaults.plan(study) == []


def test_write_renames_and_refuses_to_overwrite(tmp_path, monkeypatch):
    runs = tmp_path / "functions" / "runs"
    runs.mkdir(parents=True)
    spec = RunSpec("Sphere", 3, 1, "c-cma-es", 0, 1000)
    (runs / f"{spec.key}.json").write_text(json.dumps({"spec": {**spec.__dict__, "options": []}}))
    monkeypatch.setattr(pin_defaults, "HERE", tmp_path)
    for study in ("ccmaes", "scaling", "contextual_bbo", "low_budget"):
        (tmp_path / study / "runs").mkdir(parents=True)
    (tmp_path / "kick" / "results").mkdir(parents=True)
    assert pin_defaults.main(["--write"]) == 0
    assert [p.name for p in runs.iterdir()] == ["Sphere-p3-z1-c-cma-es-ridge_centre=zero-s0-b1000-n50.json"]
    (runs / f"{spec.key}.json").write_text(json.dumps({"spec": {**spec.__dict__, "options": []}}))
    with pytest.raises(ValueError, match="expected no document under the pinned key"):
        pin_defaults.main(["--write"])
