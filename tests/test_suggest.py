"""The "did you mean" hint (creps_gym/_suggest.py): the closest names, an id also without its namespace."""

from __future__ import annotations

from creps_gym._suggest import did_you_mean

IDS = ["creps_gym/KickPrecision-v1", "creps_gym/KickFlexibility-v1", "creps_gym/Sphere-v0"]


def test_the_closest_names_are_suggested_and_a_far_one_gets_nothing() -> None:
    both = " (did you mean 'creps_gym/KickPrecision-v1' or 'creps_gym/KickFlexibility-v1'?)"  # closest first
    assert did_you_mean("creps_gym/KickPrecison-v1", IDS) == both
    assert did_you_mean("KickPrecison-v1", IDS) == " (did you mean 'creps_gym/KickPrecision-v1'?)"
    assert did_you_mean("other/Sphere-v0", IDS) == " (did you mean 'creps_gym/Sphere-v0'?)"
    assert did_you_mean("creps", ["creps", "creps-cma-old"]) == " (did you mean 'creps'?)"
    assert did_you_mean("zzzz", IDS) == ""
    assert did_you_mean("anything", []) == ""
