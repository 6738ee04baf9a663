"""Inputs orders of magnitude away from the system's own scales: warned about before any
computation, since they are usually a unit slip (a gap in millimetres given as metres)."""

from __future__ import annotations

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.checks import is_traced
from .forcing import AbstractPeriodicForcing

# a clearance this many times the linear response's largest displacement is never reached
# (contacts only take energy out of that response)
FAR = 100.0


def scale_warnings(system, forcing) -> list:
    """Messages about inputs far from the scales of ``system`` under ``forcing``: a forcing
    frequency more than ``FAR`` times the fastest rate of the system's linearised dynamics
    (``stiffness_rate``: every mode and contact left far below, the response a vanishing
    inertial one); a contact clearance more than ``FAR`` times the largest displacement of
    the linear response (the system's own ``linear_guess``: its displacements and their
    rates at ``t = 0``), so that no wall is ever touched.  Empty for a forcing that is not
    periodic, or traced values."""
    if not isinstance(forcing, AbstractPeriodicForcing):
        return []
    return _frequency_warnings(system, forcing) + _clearance_warnings(system, forcing)


def _frequency_warnings(system, forcing) -> list:
    rate, omega = system.stiffness_rate(), forcing.omega
    if is_traced(rate) or is_traced(omega):
        return []
    rate, omega = float(rate), float(omega)
    if not (np.isfinite(rate) and rate > 0.0) or omega <= FAR * rate:
        return []
    return [f"omega = {omega:.4g} rad/s is {omega / rate:.2g} times the fastest rate of the "
            f"system ({rate:.3g} 1/s): far above every mode and contact, the response is "
            f"a vanishing inertial one. Frequencies are angular, in rad/s (2π f for f in Hz)."]


def _clearance_warnings(system, forcing) -> list:
    if any(is_traced(a) for a in jax.tree_util.tree_leaves((system, forcing))):
        return []
    if jax.eval_shape(lambda: system.penetrations(system.rest_state())).size == 0:
        return []                                    # no contact: nothing to compile
    pen, motion = _linear_motion(system, forcing)
    motion = np.asarray(motion)
    amp = float(np.max(motion)) if motion.size else 0.0
    gap = float(np.max(-np.asarray(pen)))
    if not (np.isfinite(amp) and amp > 0.0) or gap <= FAR * amp:
        return []
    return [f"a contact clearance of {gap:.3g} m is {gap / amp:.2g} times the largest "
            f"displacement of the linear response ({amp:.3g} m at omega = "
            f"{float(forcing.omega):.4g} rad/s): the walls will not be reached. Lengths are "
            f"in metres (a gap of 1 mm is gap=1e-3)."]


@eqx.filter_jit
def _linear_motion(system, forcing):
    """The contacts' penetrations at rest, and the amplitude of each displacement in the
    linear response (the system's own ``linear_guess``: its displacements and their rates
    at ``t = 0``; the amplitude of ``x = a sin(ωt + φ)`` is ``sqrt(x² + (ẋ/ω)²)``), in one
    compiled call rather than operation by operation."""
    pen = system.penetrations(system.rest_state())
    s0 = system.linear_guess(forcing)
    x = system.outputs(s0)
    xdot = system.outputs(system.vector_field(0.0, s0, forcing))
    return pen, jnp.sqrt(x**2 + (xdot / forcing.omega) ** 2)


def warn_scales(system, forcings, where: str) -> None:
    """Issue the ``scale_warnings`` of ``system`` under ``forcings`` (one forcing, or
    several: a sweep's frequencies; each kind of warning only where it holds for all of
    them, worded for the last) as ``UserWarning``s naming ``where``."""
    forcings = forcings if isinstance(forcings, (list, tuple)) else [forcings]
    if not all(isinstance(f, AbstractPeriodicForcing) for f in forcings):
        return
    for check in (_frequency_warnings, _clearance_warnings):
        texts = []
        for forcing in forcings:
            texts = check(system, forcing)
            if not texts:
                break
        for text in texts:
            warnings.warn(f"{where}: {text}", UserWarning, stacklevel=3)
