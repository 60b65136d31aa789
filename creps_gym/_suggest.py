"""The "did you mean" hint of an error message about a misspelt name (an env id, an optimiser, a
keyword). Imports only the standard library, so every layer may use it, the fast command line too."""

from __future__ import annotations

import difflib
from collections.abc import Sequence

__all__ = ["did_you_mean"]


def did_you_mean(text: str, choices: Sequence[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest choices (ids also match without their namespace), or ''."""
    by_key = {choice: choice for choice in choices}
    by_key.update({choice.split("/", 1)[1]: choice for choice in choices if "/" in choice})
    matches = difflib.get_close_matches(text, list(by_key), n=3, cutoff=0.6)
    if not matches and "/" in text:
        matches = difflib.get_close_matches(text.split("/", 1)[1], list(by_key), n=3, cutoff=0.6)
    suggestions = list(dict.fromkeys(by_key[m] for m in matches))
    if not suggestions:
        return ""
    return " (did you mean " + " or ".join(repr(s) for s in suggestions) + "?)"
