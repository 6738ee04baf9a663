r"""Exact integration of hybrid (piecewise-smooth) systems: stick–slip friction, rigid impacts.

A hybrid system (an ``AbstractHybridSystem`` whose ``hybrid`` is true) has modes, each
with a smooth vector field (``system.mode_rate``) and a switching function
(``system.switch_function``) that leaves the mode where it crosses zero upwards;
``system.next_mode`` picks the next mode at the switch and projects the state onto it (a
slip ending in stick sets the relative velocity to exactly zero; an impact reverses the
relative velocity by Newton's law).  The exact Coulomb and Stribeck laws and the rigid
impact law (``Restitution``) are integrated this way: no smoothing length or contact
stiffness, so no stiff time scale enters (the ``eps -> 0`` and infinite-stiffness limits of
the smoothed and penalty laws).

Each segment is one diffrax solve that stops at the switching event (diffrax's event root
finder on the dense interpolant).  Derivatives through the event times are exact to first
order (the saltation of the flow):

- the event time is ``t* = t̄ - g(t̄, x̂) / ġ`` with ``t̄`` the located time (no tangent),
  ``x̂`` the state at ``t̄`` with its tangent at fixed time and ``ġ`` the rate of ``g``
  along the flow (no tangent): its value is ``t̄`` and its tangent the implicit-function
  derivative ``dt* = -(∂g/∂x dx + ∂g/∂p dp) / ġ``;
- the state leaving the segment is ``x̂ + f_old (t* - t̄)``, projected by ``next_mode``, and
  the next segment starts at the fixed time ``t̄`` from ``x_new - f_new (t* - t̄)``.

Together these give ``dx+ = P (dx- + f_old dt*) - f_new dt*``: the saltation matrix of the
switch (R. I. Leine, H. Nijmeijer, *Dynamics and Bifurcations of Non-Smooth Mechanical
Systems*, Springer, 2004), composed automatically by forward-mode AD (shooting's Jacobian,
the Floquet multipliers, design gradients).  The same shift moves save times and the final
time when they depend on parameters (the forcing period): diffrax itself never sees a time
tangent.
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from .._core.status import Status, from_diffrax
from .flights import closed_form_segment, in_closed_form
from .rootfind import AbstractWrappedRootFinder

# segments allowed per forcing period (stick–slip has 2 to 4; more means chattering)
SEGMENTS_PER_PERIOD = 32
# event location: bisection to |g| < EVENT_TOL (dimensionless) and a time bracket of
# EVENT_TOL s, then one Newton step no longer than POLISH_MAX s (a grazing switch, ġ ~ 0,
# must not send it far); an event whose switch residual stays above EVENT_CHECK fails
EVENT_TOL = 1e-10
POLISH_MAX = 1e-8
EVENT_CHECK = 1e-6


class _EventBisection(AbstractWrappedRootFinder):
    """Bisection on diffrax's event bracket (wraps ``optx.Bisection``), its direction
    detected per lane.

    A switch is an upcrossing, ``g(t_prev) <= 0 < g(t_next)``; but under ``vmap`` diffrax
    also runs the root find on lanes without an event, where the function is
    ``t_next - t`` (decreasing, root at ``t_next``).  optimistix's ``flip="detect"`` raises
    there (no sign change when evaluated at the end), so the direction is set here from the
    two end values without a check."""

    solver: optx.Bisection

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        state = self.solver.init(fn, y, args, options, f_struct, aux_struct, tags)
        lo, _ = fn(jnp.asarray(options["lower"], f_struct.dtype), args)
        hi, _ = fn(jnp.asarray(options["upper"], f_struct.dtype), args)
        return eqx.tree_at(lambda s: s.flip, state, lo > hi)

    def step(self, fn, y, args, options, state, tags):
        return self.solver.step(fn, y, args, options, state, tags)

    def terminate(self, fn, y, args, options, state, tags):
        return self.solver.terminate(fn, y, args, options, state, tags)

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        return self.solver.postprocess(fn, y, aux, args, options, state, tags, result)


def _sg(x):
    return jax.lax.stop_gradient(x)


def hybrid_solve(system, forcing, x0, t0, t1, ts, *, solver, rtol, atol, max_steps, scale,
                 max_segments, norm=optx.rms_norm, log=False, closed_form=False):
    """Integrate hybrid ``system`` from scaled state ``x0`` at ``t0`` to ``t1``.

    ``ts``: save times in ``[t0, t1]`` (or None).  Returns ``(ys at ts or None, state at
    t1, status, number of steps, number of segments, (impacts, time in contact [s]))``;
    all states scaled by ``scale``.  A start outside the modes' domain (a Newton iterate
    beyond a rigid wall) is first mapped into it (``system.admissible_state``).

    ``log``: also return the event log ``(times, modes)``, arrays of ``max_segments``:
    segment ``k`` runs in mode ``modes[k]`` and ends at ``times[k]`` (its switching
    event; ``inf`` for the segment that reaches ``t1`` and those never run).

    ``closed_form``: each segment's flight by the matrix exponential of its affine mode
    (``_integration.flights``; ``solver``, ``rtol`` and ``atol`` then unused) instead of a
    diffrax solve, where ``in_closed_form`` allows it (else ignored)."""

    def rate(t, x, mode):
        return system.mode_rate(t, x * scale, forcing, mode) / scale

    def switch(t, x, mode):
        return system.switch_function(t, x * scale, forcing, mode)

    t0b, t1b = _sg(t0), _sg(t1)
    x0 = system.admissible_state(t0b, x0 * scale, forcing) / scale
    mode0 = system.mode_of(t0b, _sg(x0) * scale, forcing)
    x0 = x0 - rate(t0b, x0, mode0) * (t0 - t0b)
    # The event is bracketed by diffrax's last step, and bisection on its dense interpolant
    # cannot leave the bracket (Newton failed on grazing switches, where ġ ~ 0 at a near
    # double root).  The switching functions are dimensionless (system.switch_function), so
    # one tolerance on their value serves every scale of motion; it cannot be much tighter:
    # late in a long run one rounding step of t moves g by |ġ| ulp(t) ~ 1e-12.  The located
    # time is then polished by one Newton step dt = -g/ġ below.
    root = _EventBisection(optx.Bisection(rtol=1e-14, atol=EVENT_TOL, flip=False))
    # rigid walls: no step longer than the system's limit, so that an excursion beyond a
    # wall shorter than one step (crossed and crossed back between the step's ends, near
    # grazing) stays shallow (see AbstractHybridSystem.event_step_limit)
    ctrl = diffrax.PIDController(rtol=rtol, atol=atol, norm=norm,
                                 dtmax=system.event_step_limit(forcing))
    ts_b = None if ts is None else _sg(ts)

    def diffrax_segment(t, x, mode, ys, start):
        term = diffrax.ODETerm(lambda t_, x_, a: rate(t_, x_, mode))
        event = diffrax.Event(lambda t, y, args, **kw: switch(t, y, mode) - start,
                              root_finder=root, direction=True)
        subs = [diffrax.SubSaveAt(t1=True)]
        if ts is not None:
            subs.append(diffrax.SubSaveAt(ts=jnp.clip(ts_b, t, t1b)))
        saveat = diffrax.SaveAt(subs=subs)
        sol = diffrax.diffeqsolve(term, solver, t, t1b, None, x, saveat=saveat,
                                  stepsize_controller=ctrl, max_steps=max_steps,
                                  throw=False, event=event, adjoint=diffrax.ForwardMode())
        hit = sol.event_mask
        # a located event counts even when the bisection ran out of iterations (rounding
        # of t kept |g| above its tolerance): the residual check in body decides
        search_out = sol.result == diffrax.RESULTS.promote(
            optx.RESULTS.nonlinear_max_steps_reached)
        ok = ((sol.result == diffrax.RESULTS.successful)
              | (sol.result == diffrax.RESULTS.event_occurred) | (hit & search_out))
        st = jnp.where(ok, Status.SUCCESS, from_diffrax(sol.result))
        t_end = _sg(sol.ts[0][-1])
        x_end = sol.ys[0][-1]
        # the state at the located time with its tangent at fixed time (whatever tangent
        # diffrax gives the event time, it is removed here)
        x_end = x_end - rate(t_end, _sg(x_end), mode) * (sol.ts[0][-1] - t_end)
        if ts is not None:
            # samples of this segment: from its start (inclusive) to the event (exclusive)
            in_seg = (ts_b >= t) & ((ts_b < t_end) | (~hit & (ts_b <= t_end)))
            ys = jnp.where(in_seg[:, None], sol.ys[1], ys)
        return t_end, x_end, hit, st, sol.stats["num_steps"], ys

    if closed_form and in_closed_form(system, forcing):
        segment = closed_form_segment(system, forcing, scale, t0b, t1, ts,
                                      system.event_step_limit(forcing), max_steps,
                                      jnp.zeros_like(mode0))
    else:
        segment = diffrax_segment

    def body(c):
        t, x, mode, k, st, nsteps, ys, impacts, closed, events = c
        # an upcrossing of the switch from where the segment starts (or zero): a start a
        # rounding above zero (a state put back on a rigid wall, moving off it) must not
        # hide the next crossing when one step spans a whole short flight (a Zeno sequence)
        start = jnp.maximum(_sg(switch(t, x, mode)), 0.0)
        t_end, x_hat, hit, st, steps, ys = segment(t, x, mode, ys, start)
        # the event-time tangent by the implicit function theorem
        g = switch(t_end, x_hat, mode)
        _, gdot = jax.jvp(lambda tt, xx: switch(tt, xx, mode), (t_end, _sg(x_hat)),
                          (jnp.ones_like(t_end), rate(t_end, _sg(x_hat), mode)))
        gdot = jnp.where(gdot == 0, 1.0, gdot)
        raw = -g / _sg(gdot)  # its tangent is dt*, the implicit-function derivative
        step = jnp.clip(_sg(raw), -POLISH_MAX, POLISH_MAX)  # a last, bounded Newton step
        dt = jnp.where(hit, step + (raw - _sg(raw)), 0.0)
        st = jnp.where((st == Status.SUCCESS) & hit & (jnp.abs(_sg(g)) > EVENT_CHECK),
                       Status.SOLVER_FAILED, st)
        x_star = x_hat + rate(t_end, _sg(x_hat), mode) * dt
        new_mode, x_proj = system.next_mode(t_end, x_star * scale, forcing, mode)
        x_proj = x_proj / scale
        new_mode = jnp.where(hit, new_mode, mode)
        x_new = jnp.where(hit, x_proj - rate(t_end, _sg(x_proj), new_mode) * dt, x_hat)
        impacts = impacts + (hit & system.event_is_impact(t_end, _sg(x_star) * scale, forcing,
                                                          mode)).astype(int)
        closed = closed + jnp.where(system.in_contact(mode), t_end - t, 0.0)
        if log:
            times, modes = events
            events = (times.at[k].set(jnp.where(hit, t_end, jnp.inf)), modes.at[k].set(mode))
        return (t_end, x_new, new_mode, k + 1, st, nsteps + steps, ys,
                impacts, closed, events)

    def cond(c):
        t, _, _, k, st, _, _, _, _, _ = c
        return (t < t1b) & (k < max_segments) & (st == Status.SUCCESS)

    ys0 = None if ts is None else jnp.zeros(ts.shape + x0.shape, x0.dtype)
    events0 = ((jnp.full((max_segments,), jnp.inf, t0b.dtype),
                jnp.zeros((max_segments,) + jnp.shape(mode0), jnp.asarray(mode0).dtype))
               if log else None)
    c0 = (t0b, x0, mode0, jnp.zeros((), int), jnp.asarray(Status.SUCCESS),
          jnp.zeros((), int), ys0, jnp.zeros((), int), jnp.zeros((), t0b.dtype), events0)
    t, x, mode, k, st, nsteps, ys, impacts, closed, events = jax.lax.while_loop(cond, body,
                                                                                 c0)
    st = jnp.where((st == Status.SUCCESS) & (t < t1b), Status.MAX_STEPS, st)
    # a final time that depends on parameters (nT): move along the last mode's field
    x = x + rate(t1b, _sg(x), mode) * (t1 - t1b)
    if ts is not None:
        modes = jax.vmap(lambda tt, yy: system.mode_of(tt, yy * scale, forcing))(ts_b, _sg(ys))
        ys = ys + jax.vmap(rate)(ts_b, _sg(ys), modes) * jnp.reshape(ts - ts_b, (-1, 1))
    if log:
        return ys, x, st, nsteps, k, (impacts, closed), events
    return ys, x, st, nsteps, k, (impacts, closed)
