"""Result codes shared by simulations, steady-state solves and sweeps.

Under ``vmap`` nothing can raise, so every result carries an integer ``status`` per lane;
``0`` is success and everything else names what went wrong.  ``describe(code)`` gives the
text and what to try (``hint(code)``); ``name(code)`` the code's name (``"MAX_STEPS"``).
"""

import dataclasses
import enum

import diffrax
import jax.numpy as jnp
import numpy as np


class Status(enum.IntEnum):
    """The result codes in the ``status`` field of every result (a trajectory, a steady
    state, each point of a sweep or a branch, each lane of an attractor map).  Under ``vmap``
    nothing can raise, so each lane carries its code; a failed point never spoils the others,
    and its measured fields are NaN.

    | code | name | meaning |
    |---|---|---|
    | 0 | ``SUCCESS`` | success |
    | 1 | ``MAX_STEPS`` | the integrator exhausted ``max_steps`` |
    | 2 | ``SOLVER_FAILED`` | the integrator failed otherwise (step size collapse, NaN state) |
    | 3 | ``NO_CONVERGENCE`` | Newton or marching did not converge within its budget |
    | 4 | ``NOT_PERIODIC`` | no period-``n`` orbit with ``n <= n_max`` (quasi-periodic, chaotic) |
    | 5 | ``NONFINITE`` | the result held NaN or inf |

    [`describe`][absorber_jax.describe] gives the meaning of a code and what to try.

    ```python
    ss = aj.steady_state(system, forcing)
    if ss.status != aj.Status.SUCCESS:
        print(aj.describe(ss.status))
    ```
    """

    SUCCESS = 0
    MAX_STEPS = 1  # the integrator exhausted max_steps
    SOLVER_FAILED = 2  # the integrator failed otherwise (step size collapse, nonfinite state)
    NO_CONVERGENCE = 3  # Newton / marching did not converge within its budget
    NOT_PERIODIC = 4  # no period-n orbit with n <= n_max was found (quasi-periodic, chaotic)
    NONFINITE = 5  # the result held NaN or inf


_TEXT = {
    Status.SUCCESS: "success",
    Status.MAX_STEPS: "integrator reached max_steps",
    Status.SOLVER_FAILED: "integrator failed (step size collapse or nonfinite state)",
    Status.NO_CONVERGENCE: "no convergence within the iteration budget",
    Status.NOT_PERIODIC: "response is not periodic with period <= n_max forcing periods",
    Status.NONFINITE: "nonfinite result",
}

# what to try, per failure code
_HINT = {
    Status.MAX_STEPS: "raise max_steps (steps per forcing period), or loosen rtol/atol; for "
                      "stiff contacts or stiff friction bristles use an implicit solver "
                      "(solver='kvaerno5')",
    Status.SOLVER_FAILED: "use an implicit solver (solver='kvaerno5') for stiff contacts, "
                          "tighten rtol/atol, or check the parameters for nonphysical values "
                          "(zero or negative masses, huge stiffnesses)",
    Status.NO_CONVERGENCE: "march onto the orbit instead (method=aj.Marching()), give another "
                           "guess (a neighbouring converged state, or a sweep with "
                           "direction='up'/'down'), raise newton_steps, or tighten the "
                           "integration tolerance (rtol) so that the period map is smooth "
                           "enough for Newton",
    Status.NOT_PERIODIC: "the response may be quasi-periodic or chaotic: see aj.attractors "
                         "(window statistics and Lyapunov exponent) or aj.bifurcation_diagram; "
                         "or raise n_max / max_periods if it settles slowly",
    Status.NONFINITE: "the solution blew up: check the parameters (an unstable linear part, "
                      "a negative damping, a huge force), tighten rtol/atol or use an "
                      "implicit solver (solver='kvaerno5')",
}


def _code(code) -> Status:
    return Status(int(np.asarray(code)))


def name(code) -> str:
    """The name of a status code (``"SUCCESS"``, ``"MAX_STEPS"``, ...)."""
    return _code(code).name


def hint(code) -> str:
    """What to try after a failure with this code (``""`` for success)."""
    return _HINT.get(_code(code), "")


def describe(code, *, hint: bool = True) -> str:
    """Human-readable meaning of a status code; for a failure, followed by what to try
    (``"<meaning>; try: <what>"``) unless ``hint=False``."""
    c = _code(code)
    text = _TEXT[c]
    if hint and c in _HINT:
        text += "; try: " + _HINT[c]
    return text


def flag_attributes() -> dict:
    """CF-style attributes of a status array: ``flag_values`` (the codes) and
    ``flag_meanings`` (their names, lower case, space separated)."""
    return {"flag_values": np.array([int(s) for s in Status], dtype=np.int64),
            "flag_meanings": " ".join(s.name.lower() for s in Status)}


# the per-point measurements of a steady-state result (SteadyState fields): meaningless at a
# failed point, where they are set to NaN (``nan_where_failed``)
MEASURED = ("amplitude", "rms", "harmonic", "absorber_amplitude", "absorber_rms", "impacts",
            "contact_fraction",
            "dof_amplitude", "dof_rms", "dof_harmonic", "multipliers")


def nan_where_failed(result, fields=MEASURED):
    """``result`` (a batched steady-state result with a ``status`` array; host-side numpy)
    with ``fields`` set to NaN wherever ``status != 0``: a failed point has no amplitude
    (neither zero nor the statistics of a trial iterate), nor Floquet multipliers.  Fields
    with components (per degree of freedom, multipliers) have a trailing axis beyond
    ``status``'s shape; ``state`` (the last iterate at a failed point), ``residual`` and
    ``iterations`` are kept as diagnostics."""
    failed = np.asarray(result.status) != Status.SUCCESS
    changes = {}
    for field in fields:
        a = np.asarray(getattr(result, field))
        a = a.astype(np.result_type(a.dtype, float))
        mask = failed.reshape(failed.shape + (1,) * (a.ndim - failed.ndim))
        changes[field] = np.where(mask, np.nan, a)
    return dataclasses.replace(result, **changes)


def from_diffrax(result):
    """Map a diffrax ``RESULTS`` value to a ``Status`` code (jit-compatible)."""
    ok = result == diffrax.RESULTS.successful
    maxed = result == diffrax.RESULTS.max_steps_reached
    return jnp.where(ok, Status.SUCCESS, jnp.where(maxed, Status.MAX_STEPS, Status.SOLVER_FAILED))
