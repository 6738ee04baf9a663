r"""Continuation of harmonic-balance orbits: the branch's unknowns are the Fourier
coefficients of the orbit's state and the parameter.

``z = (c / s, p)``: the coefficients ``c`` ``(2H+1, n)`` of the whole state (``HarmonicBalance``'s
full balance) over the state scale ``s`` at the start, and the parameter over its start value.
The residual is the balance's, ``R(c; p)`` (``HarmonicBalance.residual``); the corrector is
Newton on ``[R; t·(z - z_pred)] = 0`` as for shooting (``problem._corrector``); the next
tangent is the null vector of ``[∂R/∂c, ∂R/∂p]``; the multipliers come from the monodromy at
the orbit's state or from ``∂R/∂c`` by Hill's method (``HarmonicBalance.stability``), so the
fold, period-doubling and Neimark–Sacker test functions of the shooting branch apply
unchanged (``events``).  The driver here answers the
same requests as ``driver._Driver`` (``_follow`` serves both): its orbits have no Poincaré
section to move, and its unknowns are rescaled state by state to the orbit's size.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.status import Status
from .._integration.flow import Config, state_scale
from .._periodic.harmonic import (
    HarmonicBalance,
    fourier_matrices,
    newton_solve,
    steady_from_series,
)
from .._systems.base import AbstractSystem
from .._systems.forcing import AbstractPeriodicForcing
from .driver import _Driver
from .problem import _scale_at, _set_value, bordered_newton


class _BalanceProblem(eqx.Module):
    """The harmonic balance in the continuation's scaled unknowns ``z = (c / s, p)``."""

    system: AbstractSystem
    forcing: AbstractPeriodicForcing
    s0: jax.Array
    pscale: jax.Array
    balance: HarmonicBalance
    cfg: Config
    parameter: str = eqx.field(static=True)
    n: int = eqx.field(static=True, default=1)

    def at(self, p):
        """(system, forcing) at the scaled parameter ``p``."""
        return _set_value(self.system, self.forcing, self.parameter, p * self.pscale)

    def series(self, z):
        """The coefficients ``(2H+1, n)`` of the scaled state at ``z``."""
        return z[:-1].reshape(2 * self.balance.harmonics + 1, -1)

    def residual(self, z):
        sysp, forcp = self.at(z[-1])
        return self.balance.residual(sysp, forcp, self.series(z), self.s0).reshape(-1)


@eqx.filter_jit
def _balance_corrector(prob, z_pred, t_prev, tol, newton_steps, patient=False):
    """``problem.bordered_newton`` on the balance's residual from ``z_pred``, its steps by
    the balance's own ``newton_solve`` (a ``patient`` first orbit: the whole budget);
    returns the point, its tangent, its ``SteadyState`` (multipliers as the balance's
    ``stability`` asks) and its internal state at ``t = 0``."""
    m = z_pred.shape[0] - 1

    def evaluate(z):
        J, r = jax.jacfwd(lambda v: (prob.residual(v),) * 2, has_aux=True)(z)
        bad = ~jnp.all(jnp.isfinite(r)) | ~jnp.all(jnp.isfinite(J))
        return (jnp.where(jnp.isfinite(J), J, 0.0), jnp.where(jnp.isfinite(r), r, 0.0),
                jnp.asarray(Status.SUCCESS), bad)

    z, J, t, status, res, k = bordered_newton(evaluate, z_pred, t_prev, tol, newton_steps,
                                              patient, solve=newton_solve,
                                              patient_growth=jnp.inf)
    sysp, forcp = prob.at(z[-1])
    c = prob.series(z) * prob.s0
    # Hill's method on the balance's Jacobian in the unknowns (a diagonal rescaling of the
    # states leaves its eigenvalues as they are), or the monodromy at the orbit's state
    mult = prob.balance.multipliers(sysp, forcp, c / state_scale(sysp, forcp),
                                    lambda: J[:, :m], prob.cfg)
    ss = steady_from_series(sysp, forcp, c, mult, status, res, k)
    x0 = fourier_matrices(prob.balance.harmonics, 1)[0][0] @ c
    return z, t, ss, x0


class _NoSection(eqx.Module):
    """A balance orbit's stand-in for ``orbit.Section``: no contact walls to move away
    from, and its state at ``t = 0``."""

    at_zero: np.ndarray
    least_clearance: float = np.inf
    best_clearance: float = np.inf
    clearance: float = np.inf


class _BalanceDriver:
    """``driver._Driver``'s requests answered for harmonic-balance orbits."""

    locate = _Driver.locate

    def __init__(self, prob, method, bounds):
        self.prob, self.method = prob, method
        self.lo, self.hi = (b / float(prob.pscale) for b in bounds)

    def solve(self, z_pred, t_prev, patient=False):
        z, t, ss, x0 = _balance_corrector(self.prob, jnp.asarray(z_pred), jnp.asarray(t_prev),
                                          self.method.tol, self.method.newton_steps,
                                          jnp.asarray(patient))
        ss = jax.tree_util.tree_map(np.asarray, ss)
        x0 = np.asarray(x0)
        return dict(z=np.asarray(z), t=np.asarray(t), ss=ss, sec=_NoSection(at_zero=x0),
                    xi=x0, x0=x0, mult=np.asarray(ss.multipliers),
                    ok=int(ss.status) == Status.SUCCESS)

    def resection(self, point):
        """No section to move: ``point`` itself (a generator, as ``_Driver.resection``)."""
        return point
        yield  # noqa: B901 (a generator of no requests)

    def rescale(self, point):
        """Rescale the unknowns to the orbit at ``point``: each state's coefficients over the
        larger of its state scale there and its largest coefficient, so that steps and
        tolerances measure changes relative to the orbit's size as it grows through a
        resonance (``_Driver.rescale`` for shooting).  Returns ``point`` in the new
        unknowns."""
        s_old = np.asarray(self.prob.s0)
        c = np.asarray(self.prob.series(jnp.asarray(point["z"]))) * s_old
        sc = np.asarray(_scale_at(self.prob, jnp.asarray(point["z"][-1])))
        s_new = np.maximum(sc, np.max(np.abs(c), axis=0))
        self.prob = eqx.tree_at(lambda q: q.s0, self.prob, jnp.asarray(s_new))
        tc = np.asarray(self.prob.series(jnp.asarray(point["t"]))) * s_old / s_new
        z = np.append((c / s_new).reshape(-1), point["z"][-1])
        t = np.append(tc.reshape(-1), point["t"][-1])
        return dict(point, z=z, t=t / np.linalg.norm(t))

    def first(self, x0, p0, direction, cfg):
        """The first orbit: the balance from ``x0`` (scaled internal state) warmed up over a
        few periods, corrected at the scaled parameter ``p0`` with the whole Newton budget."""
        sysp, forcp = self.prob.at(jnp.asarray(p0))
        c = self.prob.balance.first_series(sysp, forcp, jnp.asarray(x0), cfg)
        z = np.append(np.asarray(c).reshape(-1), p0)
        e = np.zeros_like(z)
        e[-1] = 1.0 if direction == "up" else -1.0
        return self.solve(z, e, True)
