"""JAX's persistent compilation cache, on by default, so that a compiled program is paid for
once per machine rather than once per process.

On import, ``absorber_jax`` points JAX's compilation cache (``jax_compilation_cache_dir``)
at ``$ABSORBER_JAX_CACHE_DIR``, else ``$XDG_CACHE_HOME/absorber_jax/jax``, else
``~/.cache/absorber_jax/jax``: every program that took JAX at least
``jax_persistent_cache_min_compile_time_secs`` (1 s by default) to compile is written there
and read back by later processes, which then pay only the tracing.  It is left alone when
the user has set a cache directory already; ``ABSORBER_JAX_CACHE=0`` (or ``off``) before
the import, or ``disable_compilation_cache`` before the first computation, turns it off.

JAX does not write executables that hold host callbacks, and equinox's runtime checks
(``eqx.error_if``) become host callbacks in their default ``EQX_ON_ERROR=raise`` mode.  The
library reports failures through result codes instead (``throw`` options are checked on the
host after the compiled call), so where the user has not chosen a mode it sets equinox's to
``nan``: a check that fails inside a compiled program returns NaN, which the library flags as
``NONFINITE``.  ``EQX_ON_ERROR=raise`` in the environment restores equinox's raising checks
(and the programs holding them are then compiled in every process).
"""

from __future__ import annotations

import os
import pathlib
import sys

import jax

_OFF = ("0", "off", "false", "no")
_STATE = {"dir": None}


def default_cache_dir() -> pathlib.Path:
    """``$ABSORBER_JAX_CACHE_DIR``, else ``$XDG_CACHE_HOME/absorber_jax/jax``, else
    ``~/.cache/absorber_jax/jax``."""
    explicit = os.environ.get("ABSORBER_JAX_CACHE_DIR")
    if explicit:
        return pathlib.Path(explicit).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return pathlib.Path(base) / "absorber_jax" / "jax"


def enable_compilation_cache(path=None) -> pathlib.Path | None:
    """Point JAX's persistent compilation cache at ``path`` (default
    ``default_cache_dir``); returns the directory, or ``None`` when it cannot be
    created (read-only home: the cache stays off, nothing else changes)."""
    where = pathlib.Path(path).expanduser() if path is not None else default_cache_dir()
    try:
        where.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", str(where))
    _STATE["dir"] = where
    return where


def disable_compilation_cache() -> None:
    """Stop writing and reading the persistent compilation cache in this process."""
    jax.config.update("jax_compilation_cache_dir", None)
    _STATE["dir"] = None


def compilation_cache_dir() -> pathlib.Path | None:
    """The directory of the persistent compilation cache in use, or ``None``."""
    current = jax.config.jax_compilation_cache_dir
    return pathlib.Path(current) if current else None


def quiet_runtime_checks() -> None:
    """equinox's runtime checks in ``nan`` mode unless the user chose a mode (module
    docstring)."""
    if "EQX_ON_ERROR" in os.environ:
        return
    os.environ["EQX_ON_ERROR"] = "nan"
    errors = sys.modules.get("equinox._errors")
    if errors is not None and getattr(errors, "EQX_ON_ERROR", None) == "raise":
        errors.EQX_ON_ERROR = "nan"     # equinox imported first: its mode is read at trace


def setup_on_import() -> None:
    """What ``import absorber_jax`` does: the cache on (module docstring) unless switched
    off or already configured by the user."""
    if os.environ.get("ABSORBER_JAX_CACHE", "1").strip().lower() in _OFF:
        return
    quiet_runtime_checks()
    if jax.config.jax_compilation_cache_dir:
        return
    enable_compilation_cache()
