"""Input validation shared by every public constructor and function.

Every check runs on concrete values *before* anything is compiled and raises a
``ValueError`` that names the field and the allowed range.  Values that are JAX tracers
(a module rebuilt inside ``jit``/``vmap``/``grad``) were validated when the concrete
module was built and are skipped here.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np


def as_float(x):
    """Field converter: a float64 (under x64) JAX scalar or array."""
    if isinstance(x, jax.core.Tracer):
        return x
    if isinstance(x, (bool, np.bool_)):
        raise ValueError(f"expected a real number, got the boolean {x!r}")
    try:
        return jnp.asarray(x, dtype=jnp.result_type(float))
    except (TypeError, ValueError) as e:
        raise ValueError(f"expected a real number, got {x!r}") from e


def is_traced(x) -> bool:
    return isinstance(x, jax.core.Tracer)


def _fmt_range(lo, hi, lo_open, hi_open):
    left = "(" if (lo_open or lo is None) else "["
    right = ")" if (hi_open or hi is None) else "]"
    lo_s = "-inf" if lo is None else f"{lo:g}"
    hi_s = "inf" if hi is None else f"{hi:g}"
    return f"{left}{lo_s}, {hi_s}{right}"


def check_scalar(owner: str, name: str, value, *, lo=None, hi=None, lo_open=False,
                 hi_open=False, scalar=True):
    """Raise ``ValueError`` unless ``value`` is a finite real in the given interval."""
    if is_traced(value):
        return
    arr = np.asarray(value)
    where = f"{owner}.{name}" if owner else name
    rng = _fmt_range(lo, hi, lo_open, hi_open)
    if scalar and arr.shape != ():
        raise ValueError(f"{where} must be a scalar in {rng}, got an array of shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise ValueError(f"{where} must be a real number in {rng}, got {value!r}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{where} must be finite, in {rng}; got {value!r}")
    bad = np.zeros(arr.shape, dtype=bool)
    if lo is not None:
        bad |= (arr <= lo) if lo_open else (arr < lo)
    if hi is not None:
        bad |= (arr >= hi) if hi_open else (arr > hi)
    if np.any(bad):
        shown = arr if arr.shape == () else arr[bad][0]
        raise ValueError(f"{where} must be in {rng}, got {float(shown):g}")


def positive(owner, name, value):
    check_scalar(owner, name, value, lo=0.0, lo_open=True)


def nonnegative(owner, name, value):
    check_scalar(owner, name, value, lo=0.0)


def check_time_grid(name: str, ts, *, t0=None, t1=None, strictly=True, min_len=1):
    """A 1-D, finite, sorted grid (the frequency grid of a sweep, the save times...)."""
    if ts is None or is_traced(ts):
        return
    arr = np.asarray(ts)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array, got shape {arr.shape}")
    if arr.size < min_len:
        raise ValueError(f"{name} must hold at least {min_len} value(s), got {arr.size}")
    if not np.issubdtype(arr.dtype, np.number) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must contain finite real numbers")
    d = np.diff(arr)
    if strictly and np.any(d <= 0):
        raise ValueError(f"{name} must be strictly increasing")
    if t0 is not None and arr[0] < t0 - 1e-12 * max(1.0, abs(t0)):
        raise ValueError(f"{name} must lie in [t0, t1] = [{t0:g}, {t1:g}], first value {arr[0]:g}")
    if t1 is not None and arr[-1] > t1 + 1e-12 * max(1.0, abs(t1)):
        raise ValueError(f"{name} must lie in [t0, t1] = [{t0:g}, {t1:g}], last value {arr[-1]:g}")


def check_state(name: str, y, size: int):
    if y is None or is_traced(y):
        return
    arr = np.asarray(y)
    if arr.shape != (size,):
        names = "x1, v1, x2, v2" + (", z" if size > 4 else "")
        raise ValueError(f"{name} must have shape ({size},) [{names}], got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")


def isfinite_scalar(x) -> bool:
    try:
        return math.isfinite(float(x))
    except Exception:  # noqa: BLE001
        return False


def require_x64(where: str):
    """absorber_jax runs in float64 only: with JAX's x64 mode switched off (float32) the
    smoothed contact laws lose their accuracy (a 1e-6 m smoothing length next to millimetre
    displacements is below float32 resolution) and shooting cannot converge to its
    tolerances, so we refuse rather than return degraded numbers."""
    if not jax.config.jax_enable_x64:
        raise ValueError(f"{where} needs float64: JAX's x64 mode is off (jax_enable_x64=False). "
                         "Importing absorber_jax enables it; re-enable it with "
                         "jax.config.update('jax_enable_x64', True)")
