"""Movement representations shared by the planar reacher and the episodic wrappers.

:class:`DiscreteDMP` integrates discrete Dynamic Movement Primitives (Ijspeert et al., 2013) for a whole
batch of weight vectors at once; see :mod:`creps_gym.movement.dmp` for the equations and the integrator.
"""

from creps_gym.movement.dmp import DiscreteDMP, DMPConfig, DMPTrajectory, step_spectral_radius

__all__ = ["DMPConfig", "DMPTrajectory", "DiscreteDMP", "step_spectral_radius"]
