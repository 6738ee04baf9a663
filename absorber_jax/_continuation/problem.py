"""The extended system of a continuation (the period map and the parameter as one
unknown vector, scaled), its tangent, corrector, Jacobian and defect."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp

from .._core.status import Status
from .._integration.flow import (
    Config,
    accurate_tangents,
    integrate_periods,
    period_map,
    state_scale,
)
from .._periodic.orbit import (
    SAMPLES_PER_PERIOD,
    finish_orbit,
    has_rigid_walls,
)
from .._systems.base import AbstractSystem
from .._systems.forcing import AbstractPeriodicForcing
from .._systems.params import get_param, replace_params
from .constants import CLOSURE, FORCING_PARAMETERS, PATIENT_GROWTH


class _Problem(eqx.Module):
    """The shooting residual in the continuation's scaled unknowns ``z = (x, p)``, ``x``
    the orbit's state on the Poincaré section ``section`` samples (of
    ``SAMPLES_PER_PERIOD`` a forcing period) after ``t = 0``."""

    system: AbstractSystem
    forcing: AbstractPeriodicForcing
    s0: jax.Array
    pscale: jax.Array
    cfg: Config
    parameter: str = eqx.field(static=True)
    n: int = eqx.field(static=True)
    section: jax.Array = eqx.field(default_factory=lambda: jnp.asarray(0))

    def at(self, p):
        """(system, forcing) at the scaled parameter ``p``."""
        return _set_value(self.system, self.forcing, self.parameter, p * self.pscale)

    def in_section(self, p):
        """(system, forcing seen from the section) at the scaled parameter ``p``."""
        sysp, forcp = self.at(p)
        phase = 2 * jnp.pi * self.section / SAMPLES_PER_PERIOD
        return sysp, forcp.at_phase(phase)

    def _in_flow(self, z):
        """(system, forcing from the section) at ``z``'s parameter, the flow's state scale
        there and ``z``'s state in it (flow states ``y`` are ``y * sc / s0`` in the
        unknowns)."""
        sysp, forcp = self.in_section(z[-1])
        sc = state_scale(sysp, forcp)
        return sysp, forcp, sc, z[:-1] * self.s0 / sc

    def residual(self, z):
        sysp, forcp, sc, x = self._in_flow(z)
        xn, st = period_map(sysp, forcp, x, self.n, self.cfg)
        return xn * sc / self.s0 - z[:-1], st

    def samples(self, z, periods):
        """The unknowns' states after each ``n`` forcing periods for ``periods`` times from
        ``z`` (at its parameter), and the integrator's status."""
        sysp, forcp, sc, x = self._in_flow(z)
        ys, st = integrate_periods((sysp, forcp), x, 0.0, self.n * forcp.period, periods,
                                   self.cfg.over_periods(self.n))
        return ys * sc / self.s0, st


def _set_value(system, forcing, name, value):
    if name == "omega":
        return system, forcing.with_omega(value)
    if name == "amplitude":
        return system, forcing.with_amplitude(value)
    return replace_params(system, {name: value}, check=False), forcing


def _get_value(system, forcing, name):
    if name in FORCING_PARAMETERS:
        return float(getattr(forcing, name))

    return float(get_param(system, name))


def _evaluate(prob, z):
    def f(z):
        r, st = prob.residual(z)
        return r, (r, st)

    J, (r, st) = jax.jacfwd(f, has_aux=True)(z)
    bad = (st != Status.SUCCESS) | ~jnp.all(jnp.isfinite(r)) | ~jnp.all(jnp.isfinite(J))
    return jnp.where(jnp.isfinite(J), J, 0.0), jnp.where(jnp.isfinite(r), r, 0.0), st, bad


def _lstsq(A, b):
    return jnp.linalg.lstsq(A, b)[0]


def _tangent(J, t_prev, solve=_lstsq):
    """Unit null vector of ``J`` (``n × (n+1)``) oriented along ``t_prev`` (the bordered
    system solved by ``solve(A, b)``)."""
    A = jnp.concatenate([J, t_prev[None]], axis=0)
    e = jnp.zeros(A.shape[0]).at[-1].set(1.0)
    t = solve(A, e)
    t = t / jnp.linalg.norm(t)
    return t * jnp.where(t @ t_prev < 0, -1.0, 1.0)


def bordered_newton(evaluate, z_pred, t_prev, tol, newton_steps, patient, *,
                    solve=_lstsq, patient_growth=PATIENT_GROWTH):
    """The continuation's corrector, for any residual: Newton on
    ``[R(z); t_prev·(z - z_pred)] = 0`` from ``z_pred``, ``evaluate(z) -> (∂R/∂z, R,
    status, bad)``, each bordered step solved by ``solve(A, b)``.  Returns ``(z, J, t,
    status, residual, steps)``: the point, the Jacobian there, the new tangent, the
    [`Status`][absorber_jax.Status], ``max |R|`` and the Newton steps taken.

    It stops where a step's residual is within ``tol`` (after at least one step: a
    predictor within tolerance would otherwise be kept with an error of order tol), where
    the budget ``newton_steps`` is spent, where the evaluation failed, or where the
    residual has not halved over the last two steps: outside Newton's basin, the step is
    better halved and tried again than the budget spent, which a batch of branches
    (band_continuation) would wait for.  Over two steps, not one: on strongly unstable orbits
    the residual often grows at the second step and then falls quadratically (the
    Kelvin-Voigt scene of scripts/benchmark_hard_contacts.py at 28.47 rad/s, |mu| = 50:
    4e-3, 1.8e-4, 3.2e-4, 2.9e-6, 1.3e-8), and a one-step test there halved the arclength
    step every other point.  A first orbit (``patient``: its guess may be far) is given up
    only where the residual has grown ``patient_growth`` times over the least so far.

    Converged, it takes one more Newton step with the Jacobian at hand, not evaluated
    again (the residual is nonlinear in the parameter even on a linear structure, and a
    residual just below tol can mean a state error of tol / (1 - |μ|) on a lightly damped
    orbit; the step leaves ~tol²); the tangent is read off that Jacobian, a step of order
    tol away."""

    def newton_step(z, J, r):
        A = jnp.concatenate([J, t_prev[None]], axis=0)
        rhs = -jnp.concatenate([r, (t_prev @ (z - z_pred))[None]])
        return solve(A, rhs)

    def body(c):
        # ``k`` Newton steps taken before this evaluation; the first pass evaluates the
        # predictor itself (its step is zero: ``J`` and ``r`` start at zero), so the
        # Jacobian's evaluation is traced and compiled once, not twice
        z, J, r, st, bad, k, res_prev, res_prev2, res_min, done = c
        z = z + newton_step(z, J, r)
        J, r, st, bad = evaluate(z)
        res = jnp.max(jnp.abs(r))
        stalled = jnp.where(patient, res > patient_growth * res_min,
                            (k >= 2) & (res > 0.5 * res_prev2))
        done = bad | ((k >= 1) & (res <= tol)) | (k >= newton_steps) | stalled
        return z, J, r, st, bad, k + 1, res, res_prev, jnp.minimum(res, res_min), done

    n = z_pred.shape[0] - 1
    inf = jnp.asarray(jnp.inf)
    z, J, r, st, bad, k, _, _, _, _ = jax.lax.while_loop(
        lambda c: ~c[-1], body,
        (z_pred, jnp.zeros((n, n + 1)), jnp.zeros(n), jnp.asarray(Status.SUCCESS),
         jnp.asarray(False), jnp.asarray(0), inf, inf, inf, jnp.asarray(False)))
    res = jnp.max(jnp.abs(r))
    ok = ~bad & (res <= tol)
    z = jnp.where(ok, z + newton_step(z, J, r), z)
    status = jnp.where(st != Status.SUCCESS, st,
                       jnp.where(bad, Status.NONFINITE,
                                 jnp.where(ok, Status.SUCCESS, Status.NO_CONVERGENCE)))
    return z, J, _tangent(J, t_prev, solve), status, res, k - 1


@eqx.filter_jit
def _corrector(prob, z_pred, t_prev, tol, newton_steps, patient=False):
    """``bordered_newton`` on the shooting residual ``Φ(z) - x`` from ``z_pred``; returns the
    point, the new tangent, the point's ``SteadyState`` (its iterations included, its
    multipliers the eigenvalues of the last Jacobian's state block plus the identity), its
    ``Section`` and the state scale at its parameter value.

    Every Jacobian is integrated with steps controlled on the tangents too
    (``_integration.flow.accurate_tangents``): forward mode through steps chosen for the
    state alone differentiates the discrete flow, whose Jacobian across a stiff contact is
    off by up to ~1e-3 in the multipliers; the tangent-controlled one costs about the same
    per evaluation (Kelvin–Voigt 2e4 scene at 44 rad/s: 21 vs 22 ms), so the last Newton
    iterate's Jacobian gives the tangent and the multipliers with no further solve, and one
    integrator is compiled instead of two.

    With rigid impacts a point is solved only where the orbit statistics' own integration
    closes on it within ``CLOSURE`` times ``tol`` (``finish_orbit(closure=...)``): the
    last Newton step, not evaluated again, may cross a grazing, where the period map jumps
    (the hard rigid scene of scripts/benchmark_rigid_impacts.py at 21.98212 rad/s: a
    residual of 4e-7 before it, 2.4e-3 after).  A compliant contact's period map is
    smooth, and its two integrations may differ by more than that at a loose ``rtol`` on
    a strongly unstable orbit."""
    prob = dataclasses.replace(prob, cfg=accurate_tangents(prob.cfg))
    z, J, t, status, res, k = bordered_newton(lambda z: _evaluate(prob, z), z_pred, t_prev,
                                              tol, newton_steps, patient)
    n = z_pred.shape[0] - 1
    mult = jnp.linalg.eigvals(J[:, :n] + jnp.eye(n))
    sysp, forcp = prob.in_section(z[-1])
    sc = state_scale(sysp, forcp)
    ss, sec = finish_orbit(sysp, forcp, z[:-1] * prob.s0 / sc, prob.n, prob.cfg, status, res, k,
                           n_cap=prob.n, multipliers=mult, section=prob.section,
                           closure=(sc / prob.s0, CLOSURE * tol)
                           if has_rigid_walls(sysp) else None)
    return z, t, ss, sec, sc


@eqx.filter_jit
def _scale_at(prob, p):
    return state_scale(*prob.at(p))


@eqx.filter_jit
def _scale_in_section(prob, p):
    """The flow's state scale at scaled parameter ``p`` seen from ``prob``'s section."""
    return state_scale(*prob.in_section(p))


@eqx.filter_jit
def _jacobian(prob, z):
    return _evaluate(prob, z)[0]


@eqx.filter_jit
def _defect_vector(prob, z):
    """``Φ(x) - x`` of the period-``prob.n`` map at ``z`` (scaled), NaN where the
    integration failed."""
    r, st = prob.residual(z)
    return jnp.where(st == Status.SUCCESS, r, jnp.nan)
