"""The manual (class docstring) of each function env, in Gymnasium's section order.

Description, Context Space, Parameter Space, Return, Episode End, Arguments, Version History: the same text
for every function, filled in from its :class:`~creps_gym.envs.functions.specs.FunctionSpec`.
"""

from __future__ import annotations

import re
import textwrap

from creps_gym.envs.functions.specs import FunctionSpec

__all__ = ["manual"]

_NBSP = "\u00a0"

_TEMPLATE = """{spec.title}: contextual version, ``x = theta + A s``.

## Description
The paper's {spec.title} function (Abdolmaleki et al. 2019, section 5.1, Table 1, {spec.panel}) made
contextual: the agent chooses parameters theta for the context s, and the function is evaluated at
``x = theta + A s``.

    {spec.formula}

Reference: {spec.reference}. {optimum_text} {spec.note}

The instance (A ~ U[-1, 1]^(p x z){shift_text}) is drawn from the ``instance`` seed, see
:mod:`creps_gym.envs.functions.instance`: one instance is the same problem on every machine.

## Context Space
``Box(0.0, 3.0, (z,), float64)``: contexts are uniform in [0, 3]^z, drawn from the env's ``np_random`` on
``reset``; ``reset(options={{"context": s}})`` sets one. The observation is the context, and
``info["context"]`` carries it on reset and step.

## Parameter Space
``Box(low, high, (p,), float64)``: the paper's initial search region [-5, 5]^p, {box_text} Parameters
outside the box are evaluated as given.

## Return
The reward of the one step is ``-f(x)`` (maximised). {info_text}

## Episode End
Every episode is one step: ``terminated=True, truncated=False``. A step before the first reset, or a second
step before the next reset, raises ``RuntimeError`` (through ``gymnasium.make``'s order enforcing, a step
before the first reset raises ``gymnasium.error.ResetNeeded`` first); a wrong shape or a non-finite theta
raises ``ValueError``, and so does a finite theta whose return overflows (far outside the box, e.g.
theta = 1e200): no step returns ±inf or NaN. The paper's stopping target is {target_text}.

## Arguments
``gymnasium.make("creps_gym/{spec.name}-v0", dim=15, context_dim=1, instance=0)``

* ``dim`` (int >= 2): p, the number of parameters. The paper uses 15 (and 2 to 64 in Fig. 3).
* ``context_dim`` (int >= 0): z. The default is 1; the paper's text says both 1 and 3 (and 1 to 5 in
  Fig. 3). ``context_dim=0`` gives the non-contextual function: the context space is ``Box`` of shape
  (0,), every episode's optimum is the same theta*, and the optimisers run as plain (non-contextual)
  searches on it.
* ``instance`` (int >= 0): seed of A{seed_text}.

``gymnasium.make_vec("creps_gym/{spec.name}-v0", num_envs=n)`` gives the native vector env, which evaluates
the whole batch in one numpy call and reproduces the scalar env bit for bit.

## Version History
* v0: initial version.
"""

_BOUNDED_INFO = (
    'Step info: ``"regret"`` = f(x) - f_opt (exactly 0 at theta*(s)) and ``"optimal_params"`` = '
    'theta*(s), shape (p,); reset info: ``"optimal_params"``. The env implements '
    "``optimal_params(contexts)`` and ``regret(contexts, params)`` (the ``SupportsRegret`` protocol), "
    "``objective``, ``target_gap`` and ``solved``."
)
_UNBOUNDED_INFO = (
    'Step info: ``"target_gap"`` = f(x) - target (<= 0 once the target is met). The env does *not* '
    "implement ``optimal_params`` or ``regret`` (``isinstance(env, SupportsRegret)`` is False); it has "
    "``objective``, ``target_gap`` and ``solved``."
)


def _keep_code_together(text: str) -> str:
    """Join the words of each ````code```` span with no-break spaces, which ``textwrap`` does not split at."""
    return re.sub(r"``[^`]+``", lambda match: match.group(0).replace(" ", _NBSP), text)


def _flat(text: str) -> str:
    """One line, words separated by single spaces (no-break spaces kept)."""
    return re.sub(r"[ \n]+", " ", text).strip()


def _wrap(text: str, width: int = 106) -> str:
    """Re-flow each paragraph (headings, bullets, indented formulas kept), indented as a class docstring."""
    text = _keep_code_together(text)
    blocks = []
    for block in text.strip().split("\n\n"):
        if block.startswith("    "):
            blocks.append(textwrap.indent(block, "    "))
            continue
        heading = ""
        if block.startswith("## "):
            heading, _, block = block.partition("\n")
            heading = "    " + heading + "\n"
        items = block.split("\n* ")
        first = _flat(items[0])
        lines = (
            [textwrap.fill(first, width, initial_indent="    ", subsequent_indent="    ")] if first else []
        )
        lines += [
            textwrap.fill(_flat(item), width, initial_indent="    * ", subsequent_indent="      ")
            for item in items[1:]
        ]
        blocks.append(heading + "\n".join(lines))
    return "\n\n".join(blocks).strip().replace(_NBSP, " ") + "\n    "


def manual(spec: FunctionSpec) -> str:
    """The class docstring (manual) of the env of ``spec``, in Gymnasium's section order."""
    if spec.bounded:
        point = (
            "o" if spec.shifted else "({0}, ..., {0})".format(1 if spec.canonical_optimum == "ones" else 0)
        )
        optimum_text = (
            f"Minimum ``f_opt = 0`` at ``x* = {point}``, so ``theta*(s) = x* - A s`` is known exactly."
        )
        box_text = (
            "widened (with a margin of 1) wherever needed to contain theta*(s) for every context in the box."
        )
        info_text = _BOUNDED_INFO
        target_text = "a regret of at most 1e-5 (``env.target`` = f_opt + 1e-5)"
    else:
        optimum_text = "Unbounded below: there is no optimum, no theta*(s) and no regret."
        box_text = "as in the paper (there is no optimum to contain)."
        info_text = _UNBOUNDED_INFO
        target_text = "``f(x) <= -1e4`` (``env.target``)"
    shift_text = (", o ~ U[-4, 4]^p" if spec.shifted else "") + (
        ", R Haar-random orthogonal" if spec.rotated else ""
    )
    seed_text = (", o" if spec.shifted else "") + (" and R" if spec.rotated else "")
    return _wrap(
        _TEMPLATE.format(
            spec=spec,
            optimum_text=optimum_text,
            shift_text=shift_text,
            box_text=box_text,
            info_text=info_text,
            target_text=target_text,
            seed_text=seed_text,
        )
    )
