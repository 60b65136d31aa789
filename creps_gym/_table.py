# ruff: noqa: E501
"""What `creps-gym list` and `--help` print, without importing numpy, Gymnasium or any env.

Generated from the registries and RunConfig by `python -m creps_gym.listing --write`: do not edit.
ENVS rows: id, context, parameters, initial distribution, description, optional modules it needs.
REGISTRATIONS: the gymnasium.register keywords of every id (entry points are strings), which
`import creps_gym` registers as soon as Gymnasium is imported, without importing any env module.
"""

__all__ = ["BACKENDS", "ENVS", "OPTIMIZERS", "REGISTRATIONS", "RUN_DEFAULTS", "VECTOR_MODES"]

# fmt: off
ENVS = [['creps_gym/CigTab-v0', '[0, 3]', '[-5, 5]^15', 'N(0, 2.5^2)', 'CigTab: contextual version, x = theta + A s.', []],
 ['creps_gym/Cigar-v0', '[0, 3]', '[-5, 5]^15', 'N(0, 2.5^2)', 'Cigar: contextual version, x = theta + A s.', []],
 ['creps_gym/DifferentPowers-v0', '[0, 3]', '[-5, 5]^15', 'N(0, 2.5^2)', 'Different Powers: contextual version, x = theta + A s.', []],
 ['creps_gym/KickFlexibility-v0', '[0.15, 0.3]×[-0.15, 0.15]', '[-1, 1]^25', 'N(env-declared mean, 0.02^2)', 'Humanoid kick, flexibility task: kick the ball as far as possible from wherever it lies.', ['mujoco']],
 ['creps_gym/KickFlexibility-v1', '[0.15, 0.3]×[-0.15, 0.15]', '[-1, 1]^25', 'N(env-declared mean, 0.02^2)', 'Humanoid kick, flexibility task: kick the ball as far as possible from wherever it lies.', ['mujoco']],
 ['creps_gym/KickFlexibility-v2', '[0.15, 0.3]×[-0.15, 0.15]', '[-1, 1]^25', 'N(env-declared mean, 0.02^2)', 'Humanoid kick, flexibility task: kick the ball as far as possible from wherever it lies.', ['mujoco']],
 ['creps_gym/KickFlexibilityLowDim-v0', '[0.15, 0.3]×[-0.15, 0.15]', '[-1, 1]^6', 'N(0, 0.3^2)', "A fixed affine subspace θ = θ_ref + B u of a full env's parameters (see the module docstring).", ['mujoco']],
 ['creps_gym/KickFlexibilityLowDim-v1', '[0.15, 0.3]×[-0.15, 0.15]', '[-1, 1]^8', 'N(0, 0.3^2)', "A fixed affine subspace θ = θ_ref + B u of a full env's parameters (see the module docstring).", ['mujoco']],
 ['creps_gym/KickFlexibilityLowDim-v2', '[0.15, 0.3]×[-0.15, 0.15]', '[-1, 1]^4', 'N(0, 0.3^2)', "A fixed affine subspace θ = θ_ref + B u of a full env's parameters (see the module docstring).", ['mujoco']],
 ['creps_gym/KickPrecision-v0', '[3, 12]', '[-1, 1]^25', 'N(env-declared mean, 0.02^2)', 'Humanoid kick, precision task: kick a fixed ball to a target distance.', ['mujoco']],
 ['creps_gym/KickPrecision-v1', '[3, 12]', '[-1, 1]^25', 'N(env-declared mean, 0.02^2)', 'Humanoid kick, precision task: kick a fixed ball to a target distance.', ['mujoco']],
 ['creps_gym/KickPrecisionLowDim-v0', '[3, 12]', '[-1, 1]^6', 'N(0, 0.3^2)', "A fixed affine subspace θ = θ_ref + B u of a full env's parameters (see the module docstring).", ['mujoco']],
 ['creps_gym/KickPrecisionLowDim-v1', '[3, 12]', '[-1, 1]^7', 'N(0, 0.3^2)', "A fixed affine subspace θ = θ_ref + B u of a full env's parameters (see the module docstring).", ['mujoco']],
 ['creps_gym/KickPrecisionLowDim-v2', '[3, 12]', '[-1, 1]^3', 'N(0, 0.3^2)', "A fixed affine subspace θ = θ_ref + B u of a full env's parameters (see the module docstring).", ['mujoco']],
 ['creps_gym/ParabolicRidge-v0', '[0, 3]', '[-5, 5]^15', 'N(0, 2.5^2)', 'Parabolic Ridge: contextual version, x = theta + A s.', []],
 ['creps_gym/PlanarReacher-v0', '[0, 2]^2', '[-30, 30]^25', 'N(0, 15^2)', 'A 5-link planar arm, driven by joint-space DMPs, passes a via-point and reaches a fixed goal.', []],
 ['creps_gym/PlanarReacher-v1', '[0, 2]^2', '[-30, 30]^25', 'N(0, 1^2)', 'A 5-link planar arm, driven by joint-space DMPs, passes a via-point and reaches a fixed goal.', []],
 ['creps_gym/PlanarReacherLowDim-v0', '[0, 2]^2', '[-1, 1]^5', 'N(0, 0.3^2)', "A fixed affine subspace θ = θ_ref + B u of a full env's parameters (see the module docstring).", []],
 ['creps_gym/Plane-v0', '[0, 3]', '[-5, 5]^15', 'N(0, 2.5^2)', 'Plane: contextual version, x = theta + A s.', []],
 ['creps_gym/PointMazeGoal-v0', '[-2.25, 2.25]×[-1.25, 1.25]', '[-2.25, 2.25]×[-1.25, 1.25]×[-1, 1]^6', 'N(box centre, (width/4)^2)', 'A point mass steered to a goal in an open PointMaze arena by a tracked DMP reference.', ['mujoco', 'gymnasium_robotics']],
 ['creps_gym/Rastrigin-v0', '[0, 3]', '[-5, 5]^15', 'N(0, 2.5^2)', 'Rastrigin: contextual version, x = theta + A s.', []],
 ['creps_gym/ReacherTarget-v0', '[-0.2, 0.2]^2', '[-1, 1]^8', 'N(0, 0.5^2)', "Gymnasium's two-joint Reacher reaching a target with an open-loop DMP torque profile.", ['mujoco']],
 ['creps_gym/Rosenbrock-v0', '[0, 3]', '[-5, 5]^15', 'N(0, 2.5^2)', 'Rosenbrock: contextual version, x = theta + A s.', []],
 ['creps_gym/SharpRidge-v0', '[0, 3]', '[-5, 5]^15', 'N(0, 2.5^2)', 'Sharp Ridge: contextual version, x = theta + A s.', []],
 ['creps_gym/ShiftedRotatedElliptic-v0', '[0, 3]', '[-5, 5]^12×[-5.99059, 5]×[-5, 5]^2', 'N(box centre, (width/4)^2)', 'Shifted Rotated High-Conditioned Elliptic (condition 1e6): contextual version, x = theta + A s.', []],
 ['creps_gym/ShiftedRotatedElliptic1e4-v0', '[0, 3]', '[-5, 5]^12×[-5.99059, 5]×[-5, 5]^2', 'N(box centre, (width/4)^2)', 'Shifted Rotated High-Conditioned Elliptic, variant with condition 1e4: contextual version, x = theta + A s.', []],
 ['creps_gym/ShiftedSchwefel-v0', '[0, 3]', '[-5, 5]^12×[-5.99059, 5]×[-5, 5]^2', 'N(box centre, (width/4)^2)', "Shifted Schwefel's problem 1.2: contextual version, x = theta + A s.", []],
 ['creps_gym/ShiftedSphere-v0', '[0, 3]', '[-5, 5]^12×[-5.99059, 5]×[-5, 5]^2', 'N(box centre, (width/4)^2)', 'Shifted Sphere: contextual version, x = theta + A s.', []],
 ['creps_gym/Sphere-v0', '[0, 3]', '[-5, 5]^15', 'N(0, 2.5^2)', 'Sphere: contextual version, x = theta + A s.', []],
 ['creps_gym/Tablet-v0', '[0, 3]', '[-5, 5]^15', 'N(0, 2.5^2)', 'Tablet: contextual version, x = theta + A s.', []],
 ['creps_gym/TwoAxes-v0', '[0, 3]', '[-5, 5]^15', 'N(0, 2.5^2)', 'Two Axes: contextual version, x = theta + A s.', []]]
OPTIMIZERS = [['creps', 'Contextual REPS: KL-bounded weights, weighted ML mean and covariance (premature convergence)'],
 ['creps-cma-old', 'CREPS-CMA, old-mean variant: rank-mu covariance around the sampling mean (Eq. 16)'],
 ['creps-cma-current', 'CREPS-CMA, current-mean variant: rank-mu covariance around the new mean (Eq. 13)'],
 ['creps-cma-csa', 'CREPS-CMA with step-size control: CREPS weights and mean, CMA covariance and CSA'],
 ['c-cma-es', 'Contextual CMA-ES: rank weights on context-baselined returns, step-size control (CSA)'],
 ['c-cma-es-surrogate', 'C-CMA-ES with a linear-quadratic surrogate of the return, used while it ranks'],
 ['c-bo', 'Contextual Bayesian optimisation: a GP over (s, theta), MES or UCB at each s (50-500 episodes)'],
 ['cma', "pycma CMA-ES (non-contextual: ignores the context; extra 'adapters')"],
 ['nevergrad', "nevergrad optimiser, TwoPointsDE by default (non-contextual; extra 'adapters')"],
 ['optuna', "optuna TPE sampler, ask-and-tell (non-contextual; extra 'adapters')"]]
BACKENDS = ['auto', 'serial', 'vector', 'ray']
VECTOR_MODES = ['auto', 'native', 'sync', 'async']
RUN_DEFAULTS = {'eval_every': 1, 'eval_contexts': 16, 'context_draws': 'batch', 'backend': 'auto', 'workers': None, 'vector_mode': 'auto', 'retries': 2, 'max_episodes': None, 'target_regret': None, 'max_time': None, 'checkpoint_every': 10, 'initial_mean': None, 'initial_std': None, 'ray_address': None, 'context_selector': None, 'divergence': 1000.0}
REGISTRATIONS = [{'id': 'creps_gym/Rosenbrock-v0', 'entry_point': 'creps_gym.envs.functions.suite:RosenbrockEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:RosenbrockVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/Sphere-v0', 'entry_point': 'creps_gym.envs.functions.suite:SphereEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:SphereVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/ShiftedSphere-v0', 'entry_point': 'creps_gym.envs.functions.suite:ShiftedSphereEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:ShiftedSphereVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/ShiftedSchwefel-v0', 'entry_point': 'creps_gym.envs.functions.suite:ShiftedSchwefelEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:ShiftedSchwefelVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/CigTab-v0', 'entry_point': 'creps_gym.envs.functions.suite:CigTabEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:CigTabVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/Tablet-v0', 'entry_point': 'creps_gym.envs.functions.suite:TabletEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:TabletVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/ShiftedRotatedElliptic-v0', 'entry_point': 'creps_gym.envs.functions.suite:ShiftedRotatedEllipticEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:ShiftedRotatedEllipticVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/ShiftedRotatedElliptic1e4-v0', 'entry_point': 'creps_gym.envs.functions.suite:ShiftedRotatedElliptic1e4Env', 'vector_entry_point': 'creps_gym.envs.functions.suite:ShiftedRotatedElliptic1e4VectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/DifferentPowers-v0', 'entry_point': 'creps_gym.envs.functions.suite:DifferentPowersEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:DifferentPowersVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/Plane-v0', 'entry_point': 'creps_gym.envs.functions.suite:PlaneEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:PlaneVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/TwoAxes-v0', 'entry_point': 'creps_gym.envs.functions.suite:TwoAxesEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:TwoAxesVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/Cigar-v0', 'entry_point': 'creps_gym.envs.functions.suite:CigarEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:CigarVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/Rastrigin-v0', 'entry_point': 'creps_gym.envs.functions.suite:RastriginEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:RastriginVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/ParabolicRidge-v0', 'entry_point': 'creps_gym.envs.functions.suite:ParabolicRidgeEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:ParabolicRidgeVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/SharpRidge-v0', 'entry_point': 'creps_gym.envs.functions.suite:SharpRidgeEnv', 'vector_entry_point': 'creps_gym.envs.functions.suite:SharpRidgeVectorEnv', 'kwargs': {'dim': 15, 'context_dim': 1, 'instance': 0}},
 {'id': 'creps_gym/PlanarReacher-v0', 'entry_point': 'creps_gym.envs.reacher.planar:PlanarReacherEnv', 'vector_entry_point': 'creps_gym.envs.reacher.planar:PlanarReacherVectorEnv', 'kwargs': {'position_weight': 1.0, 'acceleration_weight': 1e-05, 'initial_std': 15.0}},
 {'id': 'creps_gym/PlanarReacher-v1', 'entry_point': 'creps_gym.envs.reacher.planar:PlanarReacherEnv', 'vector_entry_point': 'creps_gym.envs.reacher.planar:PlanarReacherVectorEnv', 'kwargs': {'position_weight': 1.0, 'acceleration_weight': 1e-05, 'initial_std': 1.0}},
 {'id': 'creps_gym/PlanarReacherLowDim-v0', 'entry_point': 'creps_gym.envs.reacher.subspace:make_low_dimensional_reacher', 'kwargs': {'full_id': 'creps_gym/PlanarReacher-v1', 'initial_std': 0.3}},
 {'id': 'creps_gym/KickPrecision-v0', 'entry_point': 'creps_gym.envs.kick.tasks:KickPrecisionEnv', 'vector_entry_point': 'creps_gym.envs.kick.tasks:KickPrecisionVectorEnv', 'kwargs': {'rolling_friction': 0.003, 'fall_penalty': 1.0}},
 {'id': 'creps_gym/KickPrecision-v1', 'entry_point': 'creps_gym.envs.kick.tasks:KickPrecisionEnv', 'vector_entry_point': 'creps_gym.envs.kick.tasks:KickPrecisionVectorEnv', 'kwargs': {'rolling_friction': 0.003, 'fall_penalty': 1.0, 'fall_grading': 30.0}},
 {'id': 'creps_gym/KickFlexibility-v0', 'entry_point': 'creps_gym.envs.kick.tasks:KickFlexibilityEnv', 'vector_entry_point': 'creps_gym.envs.kick.tasks:KickFlexibilityVectorEnv', 'kwargs': {'rolling_friction': 0.003, 'fall_penalty': 1.0}},
 {'id': 'creps_gym/KickFlexibility-v1', 'entry_point': 'creps_gym.envs.kick.tasks:KickFlexibilityEnv', 'vector_entry_point': 'creps_gym.envs.kick.tasks:KickFlexibilityVectorEnv', 'kwargs': {'rolling_friction': 0.003, 'fall_penalty': 1.0, 'forward_only': True}},
 {'id': 'creps_gym/KickFlexibility-v2', 'entry_point': 'creps_gym.envs.kick.tasks:KickFlexibilityEnv', 'vector_entry_point': 'creps_gym.envs.kick.tasks:KickFlexibilityVectorEnv', 'kwargs': {'rolling_friction': 0.003, 'fall_penalty': 1.0, 'forward_only': True, 'miss_weight': 1.0}},
 {'id': 'creps_gym/KickPrecisionLowDim-v0', 'entry_point': 'creps_gym.envs.kick.subspace:make_low_dimensional_kick', 'kwargs': {'full_id': 'creps_gym/KickPrecision-v1', 'initial_std': 0.3}},
 {'id': 'creps_gym/KickFlexibilityLowDim-v0', 'entry_point': 'creps_gym.envs.kick.subspace:make_low_dimensional_kick', 'kwargs': {'full_id': 'creps_gym/KickFlexibility-v2', 'initial_std': 0.3}},
 {'id': 'creps_gym/KickPrecisionLowDim-v1', 'entry_point': 'creps_gym.envs.kick.subspace:make_low_dimensional_kick', 'kwargs': {'full_id': 'creps_gym/KickPrecision-v1', 'initial_std': 0.3, 'names': ('amplitude', 'hip', 'ankle', 'duration', 'aim', 'lean', 'power')}},
 {'id': 'creps_gym/KickFlexibilityLowDim-v1', 'entry_point': 'creps_gym.envs.kick.subspace:make_low_dimensional_kick', 'kwargs': {'full_id': 'creps_gym/KickFlexibility-v2', 'initial_std': 0.3, 'names': ('amplitude', 'hip', 'ankle', 'duration', 'aim', 'lean', 'power', 'reach')}},
 {'id': 'creps_gym/KickPrecisionLowDim-v2', 'entry_point': 'creps_gym.envs.kick.subspace:make_low_dimensional_kick', 'kwargs': {'full_id': 'creps_gym/KickPrecision-v1', 'initial_std': 0.3, 'names': ('duration', 'aim', 'power')}},
 {'id': 'creps_gym/KickFlexibilityLowDim-v2', 'entry_point': 'creps_gym.envs.kick.subspace:make_low_dimensional_kick', 'kwargs': {'full_id': 'creps_gym/KickFlexibility-v2', 'initial_std': 0.3, 'names': ('aim', 'lean', 'power', 'reach')}},
 {'id': 'creps_gym/PointMazeGoal-v0', 'entry_point': 'creps_gym.wrappers.examples:PointMazeGoalEnv', 'vector_entry_point': 'creps_gym.wrappers.examples:PointMazeGoalVectorEnv'},
 {'id': 'creps_gym/ReacherTarget-v0', 'entry_point': 'creps_gym.wrappers.examples:ReacherTargetEnv', 'vector_entry_point': 'creps_gym.wrappers.examples:ReacherTargetVectorEnv'}]
# fmt: on
