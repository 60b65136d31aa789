"""MuJoCo's OpenGL backend: chosen before mujoco is imported, and renders refused rather than aborted.

MuJoCo picks its OpenGL backend from ``MUJOCO_GL`` once, when ``mujoco`` is imported; the default, GLFW,
needs a display. On a headless Linux machine a GLFW render fails with a clear error the first time, and a
second attempt aborts the interpreter (exit code 134, a C++ ``__cxa_guard_acquire`` abort). So:

* :func:`choose_gl_backend` runs before the MuJoCo envs import ``mujoco``. Headless (Linux without
  ``DISPLAY`` or ``WAYLAND_DISPLAY``) and with ``MUJOCO_GL`` unset, it tries EGL, then OSMesa, each in a
  subprocess (a backend that crashes cannot take this process down), and sets ``MUJOCO_GL`` to the first
  that creates a context. Child processes (vector envs, Ray workers) inherit the choice. An explicit
  ``MUJOCO_GL`` is never changed.
* :func:`import_mujoco` is how the MuJoCo envs import ``mujoco``: after :func:`choose_gl_backend`, and
  with a short ``RuntimeError`` of this module's own, naming ``MUJOCO_GL``, when ``MUJOCO_GL=osmesa`` or
  ``egl`` names a library that is not installed (mujoco's import fails deep inside PyOpenGL otherwise).
* :func:`check_rendering` runs before every render that would create a GL context. It raises the same
  ``RuntimeError`` every time when rendering cannot work: headless with GLFW (``MUJOCO_GL`` unset with no
  working backend, or set to ``glfw``), or after a first attempt failed in this process.

This module imports neither mujoco nor OpenGL at import time.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from types import ModuleType

__all__ = [
    "GL_HELP",
    "check_rendering",
    "choose_gl_backend",
    "headless",
    "import_mujoco",
    "is_gl_error",
    "probe_backend",
    "record_failure",
]

#: Backends tried, in order, on a headless machine.
HEADLESS_BACKENDS = ("egl", "osmesa")
#: The Debian packages of each headless backend's library.
_PACKAGES = {"egl": "libegl1 libegl-mesa0 libgbm1 libgl1-mesa-dri", "osmesa": "libosmesa6"}
#: What the probe subprocess runs: create, activate and free a 1x1 context.
PROBE = "import mujoco; c = mujoco.GLContext(1, 1); c.make_current(); c.free()"
#: The backends that need a display (mujoco's names for GLFW).
_DISPLAY_BACKENDS = ("", "glfw", "glx", "enable", "enabled", "on", "true", "1")
GL_HELP = (
    "no OpenGL context can be created for rendering. On a headless machine install EGL (Debian packages "
    "libegl1 libegl-mesa0 libgbm1 libgl1-mesa-dri) or OSMesa (libosmesa6) and leave MUJOCO_GL unset (the "
    "first that works is chosen) or set MUJOCO_GL=egl or MUJOCO_GL=osmesa before mujoco is imported"
)

_probed: dict[str, str | None] = {}  # "choice" -> the backend chosen (None: none worked), once per process
_failure: list[str] = []  # the first failed render's message; later renders raise it again


def headless() -> bool:
    """Linux without a display (``DISPLAY`` and ``WAYLAND_DISPLAY`` unset or empty)."""
    has_display = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    return sys.platform.startswith("linux") and not has_display


def probe_backend(backend: str, timeout: float = 60.0) -> bool:
    """Whether ``MUJOCO_GL=backend`` creates a context, tried in a subprocess (never in this one)."""
    env = {**os.environ, "MUJOCO_GL": backend}
    env.pop("PYOPENGL_PLATFORM", None)  # mujoco sets it to match the backend
    try:
        done = subprocess.run(
            [sys.executable, "-c", PROBE], env=env, capture_output=True, timeout=timeout, check=False
        )
    except (OSError, subprocess.SubprocessError):
        return False
    return done.returncode == 0


def choose_gl_backend() -> str | None:
    """Set ``MUJOCO_GL`` to a working headless backend if it is unset on a headless machine; call it
    before ``mujoco`` is imported. Returns the backend in effect (None: mujoco's default)."""
    current = os.environ.get("MUJOCO_GL")
    if current is not None or not headless() or "mujoco" in sys.modules:
        return current  # the user's choice, a display, or too late: mujoco has chosen already
    if "choice" not in _probed:
        _probed["choice"] = next((b for b in HEADLESS_BACKENDS if probe_backend(b)), None)
        if _probed["choice"] is not None:
            os.environ["MUJOCO_GL"] = _probed["choice"]
    return _probed["choice"]


def import_mujoco(required: bool = True) -> ModuleType | None:
    """``mujoco``, imported after :func:`choose_gl_backend` (None if not installed and not ``required``).

    Raises
    ------
    RuntimeError
        ``MUJOCO_GL`` names a backend (``osmesa``, ``egl``) whose library cannot be loaded: mujoco selects
        it on import, so it cannot be imported at all (the message names the cause).
    ImportError
        mujoco is not installed (``pip install creps-gym[mujoco]``).
    """
    choose_gl_backend()  # MuJoCo reads MUJOCO_GL once, when it is imported
    if not required and "mujoco" not in sys.modules and importlib.util.find_spec("mujoco") is None:
        return None
    try:
        import mujoco
    except Exception as exc:  # e.g. PyOpenGL's AttributeError for a missing libOSMesa
        error = _backend_error(exc)
        if error is None:  # mujoco not installed (the extra is missing), or not a backend failure
            raise
        raise error from None  # short: the cause is in the message, not a 40-line traceback before it
    return mujoco


def _backend_error(exc: Exception) -> RuntimeError | None:
    backend = os.environ.get("MUJOCO_GL", "")
    if backend.lower().strip() not in HEADLESS_BACKENDS:
        return None  # not a backend library this module can name
    if isinstance(exc, ImportError) and exc.name == "mujoco":
        return None
    packages = _PACKAGES[backend.lower().strip()]
    return RuntimeError(
        f"MUJOCO_GL={backend}: mujoco cannot be imported, the {backend} library does not load "
        f"({type(exc).__name__}: {exc}); install it (Debian: {packages}) or unset MUJOCO_GL (then the "
        "first backend that works is chosen)"
    )


def check_rendering() -> None:
    """Raise ``RuntimeError`` (the same one every time) if a render would fail or abort the interpreter."""
    if _failure:
        raise RuntimeError(_failure[0])
    backend = os.environ.get("MUJOCO_GL", "").lower().strip()
    if headless() and backend in _DISPLAY_BACKENDS:
        tried = "; EGL and OSMesa did not work here" if _probed.get("choice", "") is None else ""
        setting = f"MUJOCO_GL={backend}" if backend else "MUJOCO_GL unset"
        raise RuntimeError(f"{GL_HELP} (no display and {setting}, i.e. GLFW{tried})")


def record_failure(exc: BaseException) -> RuntimeError:
    """Remember a failed render so that later renders raise at once; returns the error to raise."""
    if not _failure:
        _failure.append(f"{GL_HELP} ({type(exc).__name__}: {exc})")
    return RuntimeError(_failure[0])


def is_gl_error(exc: BaseException) -> bool:
    """Whether ``exc`` comes from creating or using a GL context (mujoco's, PyOpenGL's, GLFW's, EGL's)."""
    module = type(exc).__module__.split(".")[0].lower()
    return module in ("mujoco", "opengl", "glfw") or any(k in str(exc) for k in ("OpenGL", "EGL", "GLFW"))
