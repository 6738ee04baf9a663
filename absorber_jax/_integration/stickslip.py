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

Where the flights are in closed form (``_integration.flights``) the derivative of a period
map in the parameters is taken apart from that in the state (``closed_form_jacobian``):
the integration, differentiated in the start state, records its segments (start and end
times, modes, states), and the parameters' directions are those of a replay of the
record (``_replay``; the forcing frequency alone, where it moves only the forcing's
rotation, is a direction of the integration itself: ``flights._frequency_jvp``).  Each
segment's flight is there its linearization about the recorded flight, the propagator
``Φ`` and the parameters' tangent of the exact flow, computed ``REPLAY_BATCH`` segments
at a time in one batched exponential (one Fréchet derivative a parameter, where the loop
would differentiate one exponential a segment in every direction), and each event the
saltation above, by the same code as the integration's (``_switch``).  The replay's
values are the recorded ones.
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from .._core.status import Status, from_diffrax
from .flights import closed_form_segment, flight_linearizations, in_closed_form
from .rootfind import AbstractWrappedRootFinder

# segments allowed per forcing period (stick–slip has 2 to 4; more means chattering)
SEGMENTS_PER_PERIOD = 32
# event location: bisection to |g| < EVENT_TOL (dimensionless) and a time bracket of
# EVENT_TOL s, then one Newton step no longer than POLISH_MAX s (a grazing switch, ġ ~ 0,
# must not send it far); an event whose switch residual stays above EVENT_CHECK fails
EVENT_TOL = 1e-10
POLISH_MAX = 1e-8
EVENT_CHECK = 1e-6
# segments whose exact flights the replay of a closed-form integration linearizes together
REPLAY_BATCH = 8


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
    system = system.prepared()
    if closed_form and in_closed_form(system, forcing):
        segment = _closed_form_segments(system, forcing, scale, t0, t1, ts, max_steps)
    else:
        def segment(free_mode):
            return _diffrax_segment(system, forcing, scale, t1, ts, solver, rtol, atol,
                                    max_steps, norm)
    out, record, _ = _run(system, forcing, scale, x0, t0, t1, ts, segment, max_segments,
                          record=log)
    if log:
        times, modes, _, _, hit = record
        return out + ((jnp.where(hit, times, jnp.inf), modes),)
    return out


def _rate(system, forcing, scale):
    return lambda t, x, mode: system.mode_rate(t, x * scale, forcing, mode) / scale


def _switch_of(system, forcing, scale):
    return lambda t, x, mode: system.switch_function(t, x * scale, forcing, mode)


def _diffrax_segment(system, forcing, scale, t1, ts, solver, rtol, atol, max_steps, norm):
    """The segment function of ``_run`` by diffrax: from scaled state ``x`` at ``t`` in
    ``mode`` to the first upward crossing of the switching function past ``start`` (or to
    ``t1``), the save times ``ts`` it passes written into ``ys``."""
    rate, switch = _rate(system, forcing, scale), _switch_of(system, forcing, scale)
    t1b = _sg(t1)
    # The event is bracketed by diffrax's last step, and bisection on its dense interpolant
    # cannot leave the bracket (Newton failed on grazing switches, where ġ ~ 0 at a near
    # double root).  The switching functions are dimensionless (system.switch_function), so
    # one tolerance on their value serves every scale of motion; it cannot be much tighter:
    # late in a long run one rounding step of t moves g by |ġ| ulp(t) ~ 1e-12.  The located
    # time is then polished by one Newton step dt = -g/ġ (_switch).
    root = _EventBisection(optx.Bisection(rtol=1e-14, atol=EVENT_TOL, flip=False))
    # rigid walls: no step longer than the system's limit, so that an excursion beyond a
    # wall shorter than one step (crossed and crossed back between the step's ends, near
    # grazing) stays shallow (see AbstractHybridSystem.event_step_limit)
    ctrl = diffrax.PIDController(rtol=rtol, atol=atol, norm=norm,
                                 dtmax=system.event_step_limit(forcing))
    ts_b = None if ts is None else _sg(ts)

    def segment(t, x, mode, ys, start):
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
        # of t kept |g| above its tolerance): the residual check in _switch decides
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

    return segment


def _closed_form_segments(system, forcing, scale, t0, t1, ts, max_nodes):
    """The segment functions of ``_run`` in closed form (``flights.closed_form_segment``),
    given the all-open mode."""
    def segment(free_mode):
        return closed_form_segment(system, forcing, scale, _sg(t0), t1, ts,
                                   system.event_step_limit(forcing), max_nodes, free_mode)

    return segment


def _start(system, forcing, scale, x0, t0):
    """The start ``(t0 without tangent, state, mode)``: ``x0`` mapped into the modes'
    domain, and moved along its mode's field by the start time's tangent."""
    t0b = _sg(t0)
    x0 = system.admissible_state(t0b, x0 * scale, forcing) / scale
    mode0 = system.mode_of(t0b, _sg(x0) * scale, forcing)
    return t0b, x0 - _rate(system, forcing, scale)(t0b, x0, mode0) * (t0 - t0b), mode0


def _switch(system, forcing, scale, t_end, x_hat, hit, mode, st):
    """The event that ends a segment at the located time ``t_end`` (no tangent), the state
    there ``x_hat`` (its tangent at fixed time), ``hit`` whether a switch ended it.

    Returns ``(x_new, new_mode, status, impact)``: the state the next segment starts from
    at ``t_end`` (its tangent the saltation's, module docstring), its mode, the status
    (failed where the located switch's residual exceeds ``EVENT_CHECK``) and whether the
    event is an impact."""
    rate, switch = _rate(system, forcing, scale), _switch_of(system, forcing, scale)
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
    impact = hit & system.event_is_impact(t_end, _sg(x_star) * scale, forcing, mode)
    return x_new, new_mode, st, impact


def _run(system, forcing, scale, x0, t0, t1, ts, make_segment, max_segments, record=False):
    """The event-driven loop of ``hybrid_solve``, segment after segment
    (``make_segment(free_mode)``, ``free_mode`` the all-open mode, gives the segment
    function: from ``(t, x, mode, ys, start)`` to ``(t_end, x_hat, hit, status, steps,
    ys)``).

    Returns ``hybrid_solve``'s outputs, the record of its segments (``record``; else
    None): ``(ends, modes, states, ends' states, hits)``, ``max_segments`` of each,
    segment ``k`` from state ``states[k]`` in ``modes[k]`` (at ``ends[k - 1]``, the
    start time for the first) to ``ends[k]`` where its state is ``ends' states[k]`` (at
    fixed time), an event there where ``hits[k]``; and the last mode."""
    rate, switch = _rate(system, forcing, scale), _switch_of(system, forcing, scale)
    t0b, x0, mode0 = _start(system, forcing, scale, x0, t0)
    t1b = _sg(t1)
    segment = make_segment(jnp.zeros_like(mode0))

    def body(c):
        t, x, mode, k, st, nsteps, ys, impacts, closed, rec = c
        # an upcrossing of the switch from where the segment starts (or zero): a start a
        # rounding above zero (a state put back on a rigid wall, moving off it) must not
        # hide the next crossing when one step spans a whole short flight (a Zeno sequence)
        start = jnp.maximum(_sg(switch(t, x, mode)), 0.0)
        t_end, x_hat, hit, st, steps, ys = segment(t, x, mode, ys, start)
        x_new, new_mode, st, impact = _switch(system, forcing, scale, t_end, x_hat, hit, mode,
                                              st)
        impacts = impacts + impact.astype(int)
        closed = closed + jnp.where(system.in_contact(mode), t_end - t, 0.0)
        if record:
            rec = tuple(r.at[k].set(v) for r, v in
                        zip(rec, (t_end, mode, _sg(x), _sg(x_hat), hit)))
        return (t_end, x_new, new_mode, k + 1, st, nsteps + steps, ys, impacts, closed, rec)

    def cond(c):
        t, _, _, k, st, _, _, _, _, _ = c
        return (t < t1b) & (k < max_segments) & (st == Status.SUCCESS)

    def slots(v):
        v = jnp.asarray(v)
        return jnp.zeros((max_segments,) + v.shape, v.dtype)

    ys0 = None if ts is None else jnp.zeros(ts.shape + x0.shape, x0.dtype)
    rec0 = (tuple(slots(v) for v in (t0b, mode0, x0, x0, False)) if record else None)
    c0 = (t0b, x0, mode0, jnp.zeros((), int), jnp.asarray(Status.SUCCESS),
          jnp.zeros((), int), ys0, jnp.zeros((), int), jnp.zeros((), t0b.dtype), rec0)
    t, x, mode, k, st, nsteps, ys, impacts, closed, rec = jax.lax.while_loop(cond, body, c0)
    st = jnp.where((st == Status.SUCCESS) & (t < t1b), Status.MAX_STEPS, st)
    # a final time that depends on parameters (nT): move along the last mode's field
    x = x + rate(t1b, _sg(x), mode) * (t1 - t1b)
    if ts is not None:
        ts_b = _sg(ts)
        modes = jax.vmap(lambda tt, yy: system.mode_of(tt, yy * scale, forcing))(ts_b, _sg(ys))
        ys = ys + jax.vmap(rate)(ts_b, _sg(ys), modes) * jnp.reshape(ts - ts_b, (-1, 1))
    return (ys, x, st, nsteps, k, (impacts, closed)), rec, mode


def _replay(system, forcing, x0, t0, t1, scale, rec, count, last_mode):
    """The final state of a recorded closed-form integration (``_run``'s record of
    ``count`` segments, ``last_mode`` the mode it ends in) as a function of the inputs, to
    first order about the recorded one: its value is the recorded state, its tangent the
    integration's (module docstring).  The flights are linearized ``REPLAY_BATCH`` at a
    time (``flight_linearizations``: their end states' tangents in the parameters, their
    propagators in the start state), then composed with their events one after the
    other."""
    t0b, x, _ = _start(system, forcing, scale, x0, t0)
    M = rec[0].shape[0]
    starts = jnp.concatenate([t0b[None], rec[0][:-1]])

    def batch(c):
        b, x = c
        idx = jnp.minimum(b * REPLAY_BATCH + jnp.arange(REPLAY_BATCH), M - 1)
        tb, m, xs, xh, hit = (r[idx] for r in rec)
        ta = starts[idx]
        flown, Phi = flight_linearizations(system, forcing, m, scale, xs, ta, tb - ta)
        d = flown - _sg(flown)
        live = jnp.minimum(count - b * REPLAY_BATCH, REPLAY_BATCH)

        def step(c):
            j, x = c
            # the recorded value; the tangents of the start state and of the parameters
            x_hat = xh[j] + Phi[j] @ (x - _sg(x)) + d[j]
            x, _, _, _ = _switch(system, forcing, scale, tb[j], x_hat, hit[j], m[j],
                                 jnp.asarray(Status.SUCCESS))
            return j + 1, x

        return b + 1, jax.lax.while_loop(lambda c: c[0] < live, step, (0, x))[1]

    batches = (count + REPLAY_BATCH - 1) // REPLAY_BATCH
    _, x = jax.lax.while_loop(lambda c: c[0] < batches, batch, (0, x))
    t1b = _sg(t1)
    return x + _rate(system, forcing, scale)(t1b, _sg(x), last_mode) * (t1 - t1b)


def closed_form_jacobian(make, p, s, *, max_nodes, max_segments):
    """The final state of a closed-form hybrid integration without save times and its
    Jacobian in two groups of inputs: ``make(p, s)`` gives ``(system, forcing, x0, t0,
    t1, scale)`` from the parameters ``p`` (a vector: what enters the flights' modes) and
    ``s`` (a vector: the start state, the start and final times, and the forcing frequency
    where it moves the modes' rotation block alone).

    ``J_s`` by forward mode through the integration, which records its segments (each
    flight's tangent then needs the exponential alone, or with the oscillators' block
    repeated for the frequency: ``flights._flight``); ``J_p`` by
    the replay of that record (``_replay``), each batch of flights linearized in ``p``
    (``F = ∂x_end/∂p``, the batched exponential's Fréchet derivative, one direction a
    parameter) and composed with the events' saltations.  Returns ``(J_p, J_s,
    outputs)``, ``outputs`` those of ``hybrid_solve``."""
    P = p.shape[0]
    p_b = _sg(p)

    def run(s_):
        system, forcing, x0, t0, t1, scale = make(p_b, s_)
        system = system.prepared()
        segment = _closed_form_segments(system, forcing, scale, t0, t1, None, max_nodes)
        out, rec, mode = _run(system, forcing, scale, x0, t0, t1, None, segment,
                              max_segments, record=P > 0)
        return out[1], (jax.lax.stop_gradient(out), rec, mode)

    if s.shape[0]:
        J_s, (out, rec, mode) = jax.jacfwd(run, has_aux=True)(s)
    else:
        _, (out, rec, mode) = run(s)
        J_s = jnp.zeros(out[1].shape + (0,), out[1].dtype)
    if P == 0:
        return jnp.zeros(out[1].shape + (0,), out[1].dtype), J_s, out

    def replay(q):
        system, *rest = make(q, _sg(s))
        return _replay(system.prepared(), *rest, rec, out[4], mode)

    return jax.jacfwd(replay)(p_b), J_s, out
