"""``python -m creps_gym.cli``: the ``creps-gym`` console script.

``-m`` puts the current directory first on ``sys.path``; ``creps_gym/__init__.py`` drops it before any
other import can search it. Dropped here again in case it was kept (``--import MODULE`` looks there last).
"""

from __future__ import annotations

import os
import sys


def _drop_cwd_from_path() -> None:
    """``python -m creps_gym.cli`` puts the current directory first on ``sys.path``: drop it, so that no
    file there (or in a run directory the user works in) shadows a module; ``--import`` looks there last."""
    if not getattr(sys.flags, "safe_path", False) and sys.path and sys.path[0] in ("", os.getcwd()):
        del sys.path[0]


if __name__ == "__main__":
    _drop_cwd_from_path()
    from creps_gym.cli import main

    sys.exit(main())
