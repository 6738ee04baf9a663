"""Result codes shared by simulations, steady-state solves and sweeps.

Under ``vmap`` nothing can raise, so every result carries an integer ``status`` per lane;
``0`` is success and everything else names what went wrong.  ``describe(code)`` gives the
text.
"""

import enum

import diffrax
import jax.numpy as jnp


class Status(enum.IntEnum):
    SUCCESS = 0
    MAX_STEPS = 1  # the integrator exhausted max_steps
    SOLVER_FAILED = 2  # the integrator failed otherwise (step size collapse, nonfinite state)
    NO_CONVERGENCE = 3  # Newton / marching did not converge within its budget
    NOT_PERIODIC = 4  # no period-n orbit with n <= n_max was found (quasi-periodic, chaotic)
    NONFINITE = 5  # the result held NaN or inf


_TEXT = {
    Status.SUCCESS: "success",
    Status.MAX_STEPS: "integrator reached max_steps (raise max_steps, or use an implicit solver)",
    Status.SOLVER_FAILED: "integrator failed (step size collapse or nonfinite state)",
    Status.NO_CONVERGENCE: "no convergence within the iteration budget",
    Status.NOT_PERIODIC: "response is not periodic with period <= n_max forcing periods",
    Status.NONFINITE: "nonfinite result",
}


def describe(code) -> str:
    """Human-readable meaning of a status code."""
    return _TEXT[Status(int(code))]


def from_diffrax(result):
    """Map a diffrax ``RESULTS`` value to a :class:`Status` code (jit-compatible)."""
    ok = result == diffrax.RESULTS.successful
    maxed = result == diffrax.RESULTS.max_steps_reached
    return jnp.where(ok, Status.SUCCESS, jnp.where(maxed, Status.MAX_STEPS, Status.SOLVER_FAILED))
