"""The project's benchmarks: speed scripts and the paper-reproduction studies (a package, not installed).

The studies (``functions/``, ``scaling/``, ``ccmaes/``) share :mod:`benchmarks.study_tools` and the baselines
of :mod:`benchmarks.baselines`, imported as ``benchmarks.<module>`` from the repository root. Run a study from
the repository root, either as a module or by its path::

    python -m benchmarks.functions.run --quick
    python benchmarks/functions/run.py --quick

Run by its path, Python puts the script's own folder first on ``sys.path`` instead of the repository root
that ``python -m`` puts there. Each study's ``run.py`` therefore starts with the same two lines, the only
``sys.path`` edit in the benchmarks: when it is not run as a module (``__package__`` is empty), it replaces
that first entry with the repository root, which is exactly what ``python -m`` would have put there.
"""
