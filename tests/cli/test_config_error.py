"""A configuration error carries the field it is about (``ConfigError.field``, issue 43 item 3): the CLI maps
the field to its flag, and no layer reads the message to find it."""

from __future__ import annotations

import pickle

import pytest
from helpers import SPHERE

from creps_gym.cli import main
from creps_gym.errors import ConfigError, ConfigTypeError
from creps_gym.runner.config import RunConfig

BASE = {"env": SPHERE, "optimizer": "creps", "iterations": 2, "samples": 10, "seed": 0}

CASES = [  # RunConfig keywords, the field named, the reason
    ({"samples": 1}, "samples", "expected an integer >= 2, got 1"),
    ({"eval_every": 0}, "eval_every", "expected an integer >= 1, got 0"),
    ({"backend": "gpu"}, "backend", "expected one of ['auto', 'serial', 'vector', 'ray'], got 'gpu'"),
    ({"max_time": -1.0}, "max_time", "expected a positive finite number or None, got -1.0"),
    ({"optimizer_options": {"seed": 1}}, "optimizer_options", "expected no 'seed', which the run sets"),
    ({"context_selector": "nope"}, "context_selector", "expected one of ["),
    ({"context_selector_options": {"cells": 4}}, "context_selector_options", "expected none without"),
    ({"initial_std": [0.0]}, "initial_std", "expected a number or a list of positive finite numbers"),
]


@pytest.mark.parametrize(("keywords", "field", "reason"), CASES)
def test_a_bad_run_config_value_names_its_field_and_keeps_its_message(keywords, field, reason):
    with pytest.raises(ConfigError) as caught:
        RunConfig(**{**BASE, **keywords})
    error = caught.value
    assert error.field == field and error.reason.startswith(reason)
    assert str(error) == f"{field}: {error.reason}"  # the message the Python API always gave
    copy = pickle.loads(pickle.dumps(error))
    assert (type(copy), copy.field, copy.reason, str(copy)) == (type(error), field, error.reason, str(error))


def test_a_wrong_type_is_both_a_config_error_and_a_type_error():
    with pytest.raises(ConfigTypeError) as caught:
        RunConfig(**{**BASE, "iterations": "2"})
    assert isinstance(caught.value, TypeError) and caught.value.field == "iterations"


def test_an_optimizer_option_error_keeps_the_optimizer_message_and_names_the_options(tmp_path):
    from creps_gym.runner.loop import Runner

    config = RunConfig(**{**BASE, "optimizer_options": {"epsilon": -1.0}})
    with pytest.raises(ConfigError) as caught:
        Runner(config, run_dir=tmp_path / "r")
    assert caught.value.field == "optimizer_options" and str(caught.value).startswith("epsilon: ")
    assert caught.value.reason == str(caught.value)
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize(
    ("flags", "expected"),
    [
        (["--max-episodes", "5"], "argument --max-episodes: expected at least one iteration's samples (10)"),
        (["--opt", "epsilon=-1"], "argument --opt: epsilon: expected"),
        (["--env-kwarg", "dimension=3"], "argument --env-kwarg: expected keywords of creps_gym/Sphere-v0"),
    ],
)
def test_the_cli_names_the_flag_of_the_field(tmp_path, capsys, flags, expected):
    argv = ["run", "--env", SPHERE, "--optimizer", "creps", "--iterations", "2", "--samples", "10"]
    argv += ["--seed", "0", "--out", str(tmp_path / "r"), "--no-plot", "--no-progress", *flags]
    assert main(argv) == 2
    assert f"creps-gym run: error: {expected}" in capsys.readouterr().err


def test_every_field_that_a_flag_sets_maps_to_that_flag():
    from dataclasses import fields

    from creps_gym.cli import build_parser
    from creps_gym.cli.run import _as_usage_error

    commands = next(a for a in build_parser()._actions if a.dest == "command")
    flags = {flag for action in commands.choices["run"]._actions for flag in action.option_strings}
    api_only = {"context_draws"}  # no flag: the Python API's
    for field in {f.name for f in fields(RunConfig)} - api_only:
        text = str(_as_usage_error(ConfigError(field, "expected x, got y")))
        flag = text.removeprefix("argument ").partition(":")[0]
        assert flag in flags, (field, text)
