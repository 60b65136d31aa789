"""docs/optimizers.md documents every option of every registered optimiser, with the code's default."""

from __future__ import annotations

import ast
import dataclasses
import re
from pathlib import Path

import pytest

from creps_gym.optimizers.registry import optimizer_class, optimizer_names

DOC = Path(__file__).resolve().parents[2] / "docs" / "optimizers.md"
# the sections whose option tables document a config class (a subclass: its parent's sections too)
SECTIONS = {
    "CREPSConfig": ["## Configuration"],
    "CREPSCMAConfig": ["## Configuration"],
    "CCMAESConfig": ["## Contextual CMA-ES ("],
    "SurrogateConfig": ["## Contextual CMA-ES (", "## Surrogate-assisted contextual CMA-ES"],
    "CBOConfig": ["## Contextual Bayesian optimisation ("],
}
_NOT_OPTIONS = {"n_params", "n_context_dims"}  # positional arguments


def _config_classes() -> dict[str, type]:
    classes = {getattr(optimizer_class(name), "config_class", None) for name in optimizer_names()}
    return {cls.__name__: cls for cls in classes if cls is not None}  # the adapters have none


def _rows(heading: str) -> dict[str, str]:
    """Option name -> its default cell, from the option tables of the section starting with ``heading``."""
    text = DOC.read_text(encoding="utf-8")
    start = text.index(f"\n{heading}")
    end = text.find("\n## ", start + 1)
    rows = {}
    for line in text[start : end if end > 0 else None].splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if len(cells) != 3 or not cells[0].startswith("`") or cells[0].startswith("`option"):
            continue
        names = re.findall(r"`(\w+)`", cells[0])
        defaults = [d.strip().strip("`") for d in cells[1].split(", ")]
        for index, name in enumerate(names):
            rows[name] = defaults[index] if len(defaults) == len(names) else cells[1]
    return rows


def test_every_config_class_has_its_sections():
    assert set(_config_classes()) <= set(SECTIONS), "add the new optimiser's doc section to SECTIONS"


@pytest.mark.parametrize("name", sorted(SECTIONS))
def test_every_option_is_documented_with_its_default(name):
    config = _config_classes()[name]
    rows = {option: default for heading in SECTIONS[name] for option, default in _rows(heading).items()}
    options = [f for f in dataclasses.fields(config) if f.init and f.name not in _NOT_OPTIONS]
    missing = [f.name for f in options if f.name not in rows]
    assert not missing, f"docs/optimizers.md lacks {missing} of {name}"
    checked = 0
    for option in options:
        try:
            documented = ast.literal_eval(rows[option.name])
        except (ValueError, SyntaxError):
            continue  # a default in words
        assert documented == option.default, (name, option.name, rows[option.name], option.default)
        checked += 1
    assert checked >= len(options) // 2, (name, checked)
