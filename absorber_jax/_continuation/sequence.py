r"""Periodic orbits of hybrid systems with a fixed sequence of events (multiple shooting
over the segments between impacts): how a branch of rigid-impact orbits is entered where a
new impact is born at a grazing orbit.

Near a grazing orbit the period map ``Φ`` of a rigid-impact system is not smooth: a flight
that reaches the wall at speed ``w`` has a saltation of order ``1/w``, and ``w`` grows like
the square root of the distance to grazing, so Newton on ``Φ(x) = x`` started at the grazing
orbit does not converge to the orbits with the new impact (A. B. Nordmark, *Non-periodic
motion caused by grazing incidence in an impact oscillator*, J. Sound Vib. 145 (1991) 279).

With the sequence of events held fixed the problem is smooth.  The unknowns are the state
``x₀`` on the section (``t = 0`` of the forcing seen from it) and the event times
``0 < t₁ < … < t_K < nT`` as fractions ``θ_k = t_k / nT`` of the response period.  Segment
``k`` flows in the mode ``m_k`` of the hybrid orbit from ``t_k`` to ``t_{k+1}`` (rescaled to
``τ ∈ [0, 1]``: ``dx/dτ = (t_{k+1} - t_k) f_{m_k}(t_k + τ(t_{k+1} - t_k), x)``, so the event
times enter as parameters of smooth flows); at ``t_{k+1}`` the switching function of ``m_k``
vanishes and ``system.next_mode`` applies the jump (Newton's law of restitution, the
sticking and release projections).  The ``N + K`` equations

    g_{m_k}(t_{k+1}, x(t_{k+1}⁻)) = 0  (k = 0 … K-1),     x(nT) - x₀ = 0

in the ``N + K`` unknowns are solved by Newton with Jacobians by forward-mode AD (the
sequence's multiple shooting of COCO's hybrid toolbox, H. Dankowicz, F. Schilder, *Recipes
for Continuation*, SIAM, 2013, ch. 8).  At a grazing orbit with a new zero-speed impact
inserted at the apex of the grazing flight, this system is regular: its solutions a small
parameter step away, on the side where the new impact's speed points into the wall, are the
orbits with the impact born, from which shooting goes on.

Sequences are padded to ``SLOTS`` events (padded event times pinned to ``θ = 1``: segments
of zero length), so one compilation serves every sequence of a system.
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.status import Status
from .._integration.flights import exact_flight
from .._integration.flow import Config, closed_form_flights, state_scale
from .._integration.stickslip import hybrid_solve

# events a sequence of one response period may hold (padded up to this)
SLOTS = 32
# tolerances of the segments' flows and of Newton's residual (scaled states)
FLOW_TOL = 1e-12
NEWTON_TOL = 1e-10
NEWTON_STEPS = 20
# integrator steps allowed to one segment (at most a response period at FLOW_TOL)
SEGMENT_STEPS = 4096


@eqx.filter_jit
def event_log(system, forcing, x, t1, cfg: Config):
    """The hybrid orbit of ``system`` from scaled state ``x`` at ``t = 0`` to ``t1``:
    ``(times, modes, status)``, segment ``k`` in mode ``modes[k]`` ending at ``times[k]``
    (``inf`` past the last event), ``SLOTS + 1`` of each (a mode may be an array: one
    entry per contact of a structure)."""
    _, _, status, _, _, _, (times, modes) = hybrid_solve(
        system, forcing, x, 0.0, t1, None, solver=cfg.solver, rtol=FLOW_TOL, atol=FLOW_TOL,
        max_steps=cfg.max_steps, scale=state_scale(system, forcing),
        max_segments=SLOTS + 1, log=True,
        closed_form=cfg.closed_form)
    return times, modes, status


def _flow(system, forcing, scale, x, ta, tb, mode, solver, max_steps):
    """Scaled state ``x`` at ``ta`` carried to ``tb`` in ``mode`` (no events): the matrix
    exponential of the affine mode where the flights are in closed form
    (``_integration.flights``; ``solver=None``), else a diffrax solve."""
    if solver is None:
        y = exact_flight(system, forcing, mode, scale, x, ta, tb - ta)
        return y, jnp.all(jnp.isfinite(y))

    def rate(tau, y, args):
        return (tb - ta) * system.mode_rate(ta + tau * (tb - ta), y * scale, forcing,
                                            mode) / scale

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(rate), solver, 0.0, 1.0, None, x,
        stepsize_controller=diffrax.PIDController(rtol=FLOW_TOL, atol=FLOW_TOL),
        max_steps=max_steps, throw=False, adjoint=diffrax.ForwardMode())
    return sol.ys[-1], sol.result == diffrax.RESULTS.successful


def _residual(u, system, forcing, n, modes, active, solver, max_steps, with_rates=False):
    """The sequence's equations at unknowns ``u = (x₀ scaled, θ)``; whether every flow
    succeeded and every jump led into the sequence's next mode; and (``with_rates``, else
    zeros) each event's switch rate times the response period."""
    system = system.prepared()
    scale = state_scale(system, forcing)
    period = n * forcing.period
    N = scale.shape[0]
    x0, theta = u[:N], u[N:]
    starts = jnp.concatenate([jnp.zeros(1, u.dtype), theta]) * period
    ends = jnp.concatenate([theta, jnp.ones(1, u.dtype)]) * period
    is_event = jnp.concatenate([active, jnp.zeros(1, bool)])

    def segment(carry, seg):
        x, fine = carry
        ta, tb, mode, next_m, event = seg
        y, ok = _flow(system, forcing, scale, x, ta, tb, mode, solver, max_steps)
        if with_rates:
            g, gdot = jax.jvp(lambda t, s: system.switch_function(t, s, forcing, mode),
                              (tb, y * scale), (jnp.ones_like(tb),
                                                system.mode_rate(tb, y * scale, forcing, mode)))
        else:
            g, gdot = system.switch_function(tb, y * scale, forcing, mode), jnp.zeros_like(tb)
        new, jumped = system.next_mode(tb, y * scale, forcing, mode)
        x = jnp.where(event, jumped / scale, y)
        fine = fine & ok & (~event | jnp.all(new == next_m))
        return (x, fine), (jnp.where(event, g, tb / period - 1.0), gdot * period)

    next_modes = jnp.concatenate([modes[1:], modes[-1:]])
    (x_end, fine), (g, gdot) = jax.lax.scan(segment, (x0, jnp.asarray(True)),
                                            (starts, ends, modes, next_modes, is_event))
    return jnp.concatenate([x_end - x0, g[:-1]]), (fine, gdot[:-1])


@eqx.filter_jit
def solve_sequence(system, forcing, n, u0, modes, active, cfg: Config):
    """Newton on the fixed-sequence equations from ``u0``: ``(u, status, residual, rates)``,
    ``rates`` the rate of each event's switching function as its segment reaches it, times
    the response period (dimensionless; positive: the switch crossed upwards, as the hybrid
    integration sees it)."""

    # flights in closed form where the configuration allows them (solver None)
    solver = None if closed_form_flights(system, forcing, cfg) else cfg.solver

    def f(u, with_rates=False):
        r, (fine, gdot) = _residual(u, system, forcing, n, modes, active, solver,
                                    SEGMENT_STEPS, with_rates)
        return r, (r, fine, gdot)

    N = u0.shape[0] - active.shape[0]

    def body(c):
        u, res_prev, _, k = c
        J, (r, fine, _) = jax.jacfwd(f, has_aux=True)(u)
        res = jnp.max(jnp.abs(r))
        u_new = u + jnp.linalg.solve(J, -r)
        theta = jnp.concatenate([jnp.zeros(1), u_new[N:], jnp.ones(1)])
        # a residual that grows, or event times out of order: outside Newton's basin
        good = (fine & jnp.all(jnp.isfinite(u_new)) & jnp.all(jnp.diff(theta) >= 0)
                & (res < 2.0 * res_prev))
        return jnp.where(good, u_new, u), res, good, k + 1

    def cond(c):
        _, res, good, k = c
        return good & (res > NEWTON_TOL) & (k < NEWTON_STEPS)

    u, res, good, _ = jax.lax.while_loop(
        cond, body, (u0, jnp.asarray(jnp.inf), jnp.asarray(True), jnp.asarray(0)))
    r, fine, rates = f(u, with_rates=True)[1]
    res = jnp.max(jnp.abs(r))
    status = jnp.where(good & fine & (res <= NEWTON_TOL), Status.SUCCESS,
                       Status.NO_CONVERGENCE)
    return u, status, res, rates


def _padded(theta, seg, K):
    """``K`` event times (over the period) and the ``K + 1`` modes of their segments padded
    to ``SLOTS`` events: ``(theta, modes, active)``."""
    pad = SLOTS - K
    theta = np.concatenate([theta, np.ones(pad)])
    seg = np.concatenate([seg, np.repeat(seg[-1:], pad, axis=0)])
    return theta, seg, np.arange(SLOTS) < K


def sequence_of(times, modes, period):
    """The event sequence of an orbit (``times``, ``modes`` from ``event_log``) as it is:
    ``(theta, modes, active)`` padded to ``SLOTS`` events, or ``None`` where it has more."""
    times, modes = np.asarray(times), np.asarray(modes)
    K = int(np.isfinite(times).sum())
    if K > SLOTS:
        return None
    return _padded(times[:K] / period, modes[:K + 1], K)


def sequence_with(times, modes, t_new, period):
    """The event sequence of an orbit (``times``, ``modes`` from ``event_log``) with one more
    event at ``t_new``, splitting the segment there into two of its mode: ``(theta, modes,
    active)`` padded to ``SLOTS`` events (``theta`` the event times over ``period``), or
    ``None`` where the orbit has more events than that."""
    times, modes = np.asarray(times), np.asarray(modes)
    K = int(np.isfinite(times).sum())
    if K + 1 > SLOTS:
        return None
    t = times[:K]
    j = int(np.searchsorted(t, t_new))
    theta = np.insert(t, j, t_new) / period
    seg = np.insert(modes[:K + 1], j, modes[j], axis=0)
    return _padded(theta, seg, K + 1)


def sequence_without(theta, seg, active, j):
    """The sequence ``(theta, seg, active)`` with its event ``j`` taken out, the segments
    before and after it merged into one: the orbit beyond a grazing impact, whose flight
    there turns just short of the wall.  ``None`` unless both segments run in the same mode
    (an impact in free flight that leaves the absorber free)."""
    theta, seg = np.asarray(theta), np.asarray(seg)
    K = int(np.sum(active))
    if not 0 <= j < K or not np.array_equal(seg[j], seg[j + 1]):
        return None
    return _padded(np.delete(theta[:K], j), np.delete(seg[:K + 1], j + 1, axis=0), K - 1)
