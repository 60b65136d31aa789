"""Context selectors: what a run practises (see ``docs/contexts.md``).

A :class:`ContextSelector` chooses every iteration's training contexts and is told their returns and the
optimiser's diagnostics; the runner uses it instead of the env's sampler (``run(...,
context_selector="bandit")``, ``creps-gym run --context-selector bandit``). Evaluation always stays on the
env's own test contexts.

Modules: :mod:`.base` (the protocol, the adapters of the fixed samplers), :mod:`.bandit` (learning
progress over grid cells, D-UCB), :mod:`.progress` (a kernel estimate of learning progress, no partition),
:mod:`.active` (where the optimiser's model expects to learn most), :mod:`.registry` (names, options).
"""

from creps_gym.selectors.active import ActiveContextSelector
from creps_gym.selectors.bandit import LearningProgressBandit, cell_index, ducb_index
from creps_gym.selectors.base import (
    BetaSelector,
    ContextSelector,
    EnvSelector,
    FixedSelector,
    SamplerSelector,
    UniformSelector,
)
from creps_gym.selectors.progress import KernelProgressSelector
from creps_gym.selectors.registry import (
    SELECTORS,
    ArcsineSelector,
    check_options,
    make_selector,
    selector_names,
)

__all__ = [
    "SELECTORS",
    "ActiveContextSelector",
    "ArcsineSelector",
    "BetaSelector",
    "ContextSelector",
    "EnvSelector",
    "FixedSelector",
    "KernelProgressSelector",
    "LearningProgressBandit",
    "SamplerSelector",
    "UniformSelector",
    "cell_index",
    "check_options",
    "ducb_index",
    "make_selector",
    "selector_names",
]
