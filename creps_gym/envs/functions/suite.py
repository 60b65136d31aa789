"""The 15 concrete environments, one per function of the paper's Table 1, and their native vector envs.

Each ``<Name>Env`` is registered as ``creps_gym/<Name>-v0`` with ``<Name>VectorEnv`` as its
``vector_entry_point``; the class docstring is the env's manual (built from its :class:`FunctionSpec`).
"""

from __future__ import annotations

from creps_gym.envs.functions.env import BoundedFunctionEnv, ContextualFunctionVectorEnv, UnboundedFunctionEnv
from creps_gym.envs.functions.manual import manual
from creps_gym.envs.functions.specs import SPECS, FunctionSpec

__all__ = [
    "ENV_CLASSES",
    "CigTabEnv",
    "CigTabVectorEnv",
    "CigarEnv",
    "CigarVectorEnv",
    "DifferentPowersEnv",
    "DifferentPowersVectorEnv",
    "ParabolicRidgeEnv",
    "ParabolicRidgeVectorEnv",
    "PlaneEnv",
    "PlaneVectorEnv",
    "RastriginEnv",
    "RastriginVectorEnv",
    "RosenbrockEnv",
    "RosenbrockVectorEnv",
    "SharpRidgeEnv",
    "SharpRidgeVectorEnv",
    "ShiftedRotatedElliptic1e4Env",
    "ShiftedRotatedElliptic1e4VectorEnv",
    "ShiftedRotatedEllipticEnv",
    "ShiftedRotatedEllipticVectorEnv",
    "ShiftedSchwefelEnv",
    "ShiftedSchwefelVectorEnv",
    "ShiftedSphereEnv",
    "ShiftedSphereVectorEnv",
    "SphereEnv",
    "SphereVectorEnv",
    "TabletEnv",
    "TabletVectorEnv",
    "TwoAxesEnv",
    "TwoAxesVectorEnv",
]

_SPEC: dict[str, FunctionSpec] = {spec.name: spec for spec in SPECS}


class RosenbrockEnv(BoundedFunctionEnv):
    __doc__ = manual(_SPEC["Rosenbrock"])
    function = _SPEC["Rosenbrock"]


class RosenbrockVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`RosenbrockEnv`, registered as its ``vector_entry_point``."""

    single_env_class = RosenbrockEnv


class SphereEnv(BoundedFunctionEnv):
    __doc__ = manual(_SPEC["Sphere"])
    function = _SPEC["Sphere"]


class SphereVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`SphereEnv`, registered as its ``vector_entry_point``."""

    single_env_class = SphereEnv


class ShiftedSphereEnv(BoundedFunctionEnv):
    __doc__ = manual(_SPEC["ShiftedSphere"])
    function = _SPEC["ShiftedSphere"]


class ShiftedSphereVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`ShiftedSphereEnv`, registered as its ``vector_entry_point``."""

    single_env_class = ShiftedSphereEnv


class ShiftedSchwefelEnv(BoundedFunctionEnv):
    __doc__ = manual(_SPEC["ShiftedSchwefel"])
    function = _SPEC["ShiftedSchwefel"]


class ShiftedSchwefelVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`ShiftedSchwefelEnv`, registered as its ``vector_entry_point``."""

    single_env_class = ShiftedSchwefelEnv


class CigTabEnv(BoundedFunctionEnv):
    __doc__ = manual(_SPEC["CigTab"])
    function = _SPEC["CigTab"]


class CigTabVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`CigTabEnv`, registered as its ``vector_entry_point``."""

    single_env_class = CigTabEnv


class TabletEnv(BoundedFunctionEnv):
    __doc__ = manual(_SPEC["Tablet"])
    function = _SPEC["Tablet"]


class TabletVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`TabletEnv`, registered as its ``vector_entry_point``."""

    single_env_class = TabletEnv


class ShiftedRotatedEllipticEnv(BoundedFunctionEnv):
    __doc__ = manual(_SPEC["ShiftedRotatedElliptic"])
    function = _SPEC["ShiftedRotatedElliptic"]


class ShiftedRotatedEllipticVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`ShiftedRotatedEllipticEnv`, registered as its ``vector_entry_point``."""

    single_env_class = ShiftedRotatedEllipticEnv


class ShiftedRotatedElliptic1e4Env(BoundedFunctionEnv):
    __doc__ = manual(_SPEC["ShiftedRotatedElliptic1e4"])
    function = _SPEC["ShiftedRotatedElliptic1e4"]


class ShiftedRotatedElliptic1e4VectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`ShiftedRotatedElliptic1e4Env`, its ``vector_entry_point``."""

    single_env_class = ShiftedRotatedElliptic1e4Env


class DifferentPowersEnv(BoundedFunctionEnv):
    __doc__ = manual(_SPEC["DifferentPowers"])
    function = _SPEC["DifferentPowers"]


class DifferentPowersVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`DifferentPowersEnv`, registered as its ``vector_entry_point``."""

    single_env_class = DifferentPowersEnv


class PlaneEnv(UnboundedFunctionEnv):
    __doc__ = manual(_SPEC["Plane"])
    function = _SPEC["Plane"]


class PlaneVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`PlaneEnv`, registered as its ``vector_entry_point``."""

    single_env_class = PlaneEnv


class TwoAxesEnv(BoundedFunctionEnv):
    __doc__ = manual(_SPEC["TwoAxes"])
    function = _SPEC["TwoAxes"]


class TwoAxesVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`TwoAxesEnv`, registered as its ``vector_entry_point``."""

    single_env_class = TwoAxesEnv


class CigarEnv(BoundedFunctionEnv):
    __doc__ = manual(_SPEC["Cigar"])
    function = _SPEC["Cigar"]


class CigarVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`CigarEnv`, registered as its ``vector_entry_point``."""

    single_env_class = CigarEnv


class RastriginEnv(BoundedFunctionEnv):
    __doc__ = manual(_SPEC["Rastrigin"])
    function = _SPEC["Rastrigin"]


class RastriginVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`RastriginEnv`, registered as its ``vector_entry_point``."""

    single_env_class = RastriginEnv


class ParabolicRidgeEnv(UnboundedFunctionEnv):
    __doc__ = manual(_SPEC["ParabolicRidge"])
    function = _SPEC["ParabolicRidge"]


class ParabolicRidgeVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`ParabolicRidgeEnv`, registered as its ``vector_entry_point``."""

    single_env_class = ParabolicRidgeEnv


class SharpRidgeEnv(UnboundedFunctionEnv):
    __doc__ = manual(_SPEC["SharpRidge"])
    function = _SPEC["SharpRidge"]


class SharpRidgeVectorEnv(ContextualFunctionVectorEnv):
    """Native vector env of :class:`SharpRidgeEnv`, registered as its ``vector_entry_point``."""

    single_env_class = SharpRidgeEnv


_EnvPair = tuple[type[BoundedFunctionEnv | UnboundedFunctionEnv], type[ContextualFunctionVectorEnv]]

#: (env class, vector env class) of every function, in the paper's order (Fig. 1a-h, then Fig. 2a-g).
ENV_CLASSES: tuple[_EnvPair, ...] = (
    (RosenbrockEnv, RosenbrockVectorEnv),
    (SphereEnv, SphereVectorEnv),
    (ShiftedSphereEnv, ShiftedSphereVectorEnv),
    (ShiftedSchwefelEnv, ShiftedSchwefelVectorEnv),
    (CigTabEnv, CigTabVectorEnv),
    (TabletEnv, TabletVectorEnv),
    (ShiftedRotatedEllipticEnv, ShiftedRotatedEllipticVectorEnv),
    (ShiftedRotatedElliptic1e4Env, ShiftedRotatedElliptic1e4VectorEnv),
    (DifferentPowersEnv, DifferentPowersVectorEnv),
    (PlaneEnv, PlaneVectorEnv),
    (TwoAxesEnv, TwoAxesVectorEnv),
    (CigarEnv, CigarVectorEnv),
    (RastriginEnv, RastriginVectorEnv),
    (ParabolicRidgeEnv, ParabolicRidgeVectorEnv),
    (SharpRidgeEnv, SharpRidgeVectorEnv),
)
