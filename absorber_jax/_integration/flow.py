"""The flow of a system over forcing periods and its derivatives: the one place that
integrates for the steady-state layer (shooting, marching, orbit statistics).

States are the *internal* state scaled to order one (``system.state_scale``: positions by
a length ``L``, velocities by ``Lω``) so that one tolerance means the same thing for every
component.  Derivatives (shooting's Jacobian, Floquet multipliers, design gradients) are
computed in forward mode: through diffrax ``ForwardMode`` for explicit solvers on non-stiff
scenes; by forward sensitivity equations for implicit solvers and for explicit ones on
stiff-ish scenes (steps then controlled on the tangents too); through the event times for
hybrid systems (``_integration.stickslip``).  The flow carries a custom JVP whose tangent
is a linear map of the input tangents (the forward Jacobian applied to them), so JAX can
transpose it: ``jax.grad`` works too and gives the forward-mode numbers.
"""

from __future__ import annotations

import dataclasses

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from .._core.checks import is_traced
from .._core.status import Status, from_diffrax
from .._systems.base import is_hybrid
from .flights import frequency_in_rotation_only, frequency_leaf, in_closed_form
from .simulate import _resolve_solver, left_to_scene
from .stickslip import SEGMENTS_PER_PERIOD, closed_form_jacobian, hybrid_solve
from .unrolled import unrolled

# event-driven segments allowed in one integration of one forcing period (the loop ends at
# t1 long before, unless the motion chatters without end), and per step of its budget over
# several periods
MAX_SEGMENTS = SEGMENTS_PER_PERIOD * 64
STEPS_PER_SEGMENT = 64


def max_segments(cfg):
    """Segments allowed to a hybrid integration under ``cfg`` (more over more periods)."""
    return max(MAX_SEGMENTS, int(cfg.max_steps) // STEPS_PER_SEGMENT)


class Config(eqx.Module):
    solver: diffrax.AbstractSolver
    rtol: float = eqx.field(static=True)
    atol: float = eqx.field(static=True)
    # integrator steps allowed per forcing period (an integration over n periods may take
    # n times as many, see over_periods)
    max_steps: int = eqx.field(static=True)
    # derivatives of the flow by sensitivity equations whose steps are controlled on the
    # tangents too (explicit solvers on stiff-ish scenes, see make_config)
    tangent_control: bool = eqx.field(static=True, default=False)
    # a large state's sensitivities integrated with unrolled stages (_integration.unrolled):
    # ~30 % faster run, ~2x the compilation; for the integrations a sweep repeats at every
    # point (Floquet monodromies, see _periodic.orbit.floquet_matrix)
    unroll_tangents: bool = eqx.field(static=True, default=False)
    # rtol and atol multiplied by these (floats, or traced scalars: one compiled
    # integration run at two tolerances, see _periodic.orbit.floquet_matrix)
    tol_factors: tuple = (1.0, 1.0)
    # hybrid systems with affine modes under a forcing with exact harmonics: flights in
    # closed form (_integration.flights), unless a solver was named
    closed_form: bool = eqx.field(static=True, default=True)

    def over_periods(self, n: int) -> Config:
        """The configuration of one integration over ``n`` forcing periods."""
        return dataclasses.replace(self, max_steps=int(self.max_steps) * int(n))


# An explicit solver's monodromy is taken from sensitivity equations with steps controlled on
# the tangents as well as the state once (largest linearised rate × period) exceeds this.
# Below it, diffrax ForwardMode (state-controlled steps, ~4x cheaper) is right; above it
# the stiff direction has decayed in the state, so the state's error estimate lets the steps
# reach the edge of the explicit stability region, where the O(1) tangent seeded in that
# direction grows: with state-controlled steps, the stick–slip scene of
# tests/integration/test_stickslip.py
# (smoothed Coulomb eps = 1e-4, 70 rad/s, λT = 2e4) gives |μ| = 1e66 from shooting and 2.8e9
# from marching on a stable orbit (|μ| = 0.86).
TANGENT_CONTROL_STEPS_PER_PERIOD = 2.0e3


def state_scale(system, forcing):
    """Per-component scale of the internal state (the system's own, see
    ``AbstractAbsorberSystem.state_scale``)."""
    return system.state_scale(forcing)


def _scaled_rate(dyn, t, x):
    system, forcing = dyn
    scale = state_scale(system, forcing)
    return system.vector_field(t, x * scale, forcing) / scale


def _mode_rate(dyn, t, x):
    """The rate of hybrid ``dyn`` at scaled state ``x`` and time ``t`` in the mode there."""
    system, forcing = dyn
    system = system.prepared()
    scale = state_scale(system, forcing)
    mode = system.mode_of(t, x * scale, forcing)
    return system.mode_rate(t, x * scale, forcing, mode) / scale


def _diffeqsolve(rate, x0, t0, t1, ts, cfg, norm=optx.rms_norm):
    saveat = diffrax.SaveAt(t1=True) if ts is None else diffrax.SaveAt(ts=ts)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(rate), cfg.solver, t0, t1, None, x0, saveat=saveat,
        stepsize_controller=diffrax.PIDController(rtol=cfg.rtol * cfg.tol_factors[0],
                                                  atol=cfg.atol * cfg.tol_factors[1], norm=norm),
        max_steps=cfg.max_steps, throw=False, adjoint=diffrax.ForwardMode(),
    )
    return sol.ys, from_diffrax(sol.result)


def integrate(dyn, x0, t0, t1, ts, cfg, counts=False):
    """Scaled states of ``dyn`` from ``x0`` at ``t0`` saved at ``ts`` (or at ``t1`` only when
    ``ts`` is None), and the status: smooth systems by one diffrax solve, hybrid ones
    (exact stick–slip) segment by segment (``_integration.stickslip``).  ``counts``: also
    the impacts and the time [s] a contact is held closed, counted at the events of the
    same integration (zeros for a smooth system)."""
    system, forcing = dyn
    if is_hybrid(system):
        # vmapped, lane by lane (see lane_by_lane): the lanes' event sequences differ
        out = lane_by_lane(_hybrid_states)(dyn, x0, t0, t1, ts, cfg)
        return out if counts else out[:2]
    if counts:
        ys, status = integrate(dyn, x0, t0, t1, ts, cfg)
        return ys, status, _no_counts(ys)
    return _smooth_states(dyn, x0, t0, t1, ts, cfg)


@eqx.filter_jit
def _smooth_states(dyn, x0, t0, t1, ts, cfg):
    """``integrate``'s states and status of a smooth system: one diffrax solve.  A function
    of its arguments alone, jitted, so that the integrations repeated inside one program
    (shooting's steps, the Floquet matrix, the orbit's samples) are traced once."""
    if large_state(dyn[0]):
        # run lane by lane, a large state's plain integrations pay diffrax's per-stage loop
        # bookkeeping in full (vmapped lanes share it): unrolled stages, the same steps and
        # numbers (_integration.unrolled).  The integrations that carry tangents
        # (_sensitivity_jacobian, flow_along) keep diffrax's loop (it compiles in half the
        # time), except the Floquet monodromies a sweep repeats at every point
        # (cfg.unroll_tangents)
        cfg = dataclasses.replace(cfg, solver=unrolled(cfg.solver))
    return _diffeqsolve(lambda t, x, a: _scaled_rate(dyn, t, x), x0, t0, t1, ts, cfg)


def _no_counts(ys):
    return jnp.zeros((), int), jnp.zeros((), ys.dtype)


@eqx.filter_custom_jvp
def integrate_flow(dyn, x0, t1, ts, *, cfg, counts=False):
    """Scaled states of ``dyn = (system, forcing)`` from ``x0`` at ``t = 0`` saved at ``ts``
    (or at ``t1`` only when ``ts`` is None), and the integrator's status; differentiable in
    forward *and* reverse mode (``jax.jacfwd``, ``jax.linearize``, ``jax.grad``).
    ``counts``: also ``(impacts, time in contact [s])`` counted at the events of the same
    integration (``event_counts``; no derivative).

    Derivatives are forward sensitivities (through diffrax ``ForwardMode``, or by
    ``_sensitivity_jacobian``) with respect to the inputs
    that carry a tangent, assembled into a Jacobian, whose product with the tangent is
    linear in it: JAX transposes that product for reverse mode.  A design has a handful of
    parameters and the state a handful of components, so this costs what forward mode costs
    (one integration carrying ``len(x0) + #parameters`` tangents), with no backward
    integration or checkpointing, and reverse mode gives the same numbers as forward mode.
    """
    return integrate(dyn, x0, 0.0, t1, ts, cfg, counts)


def integrate_periods(dyn, x0, t0, period, count, cfg):
    """Scaled states of ``dyn`` after each of ``count`` times ``period`` [s] from ``x0`` at
    ``t0``, and the status (the first failure's).  A hybrid system is integrated one
    period at a time, saving nothing in between: diffrax's save times inside its
    event-driven segments cost more than the periods' restarts (a rigid-impact march of
    40 periods, ~15 impacts each, 0.64-0.83 ms a period saving at each, 0.37 ms period by
    period)."""
    if not is_hybrid(dyn[0]):
        ts = t0 + period * jnp.arange(1, count + 1)
        return integrate(dyn, x0, t0, ts[-1], ts, cfg.over_periods(count))

    def one(x, k):
        y, st = integrate(dyn, x, t0 + k * period, t0 + (k + 1) * period, None, cfg)
        return y[0], (y[0], st)

    _, (ys, sts) = jax.lax.scan(one, x0, jnp.arange(count))
    failed = sts != Status.SUCCESS
    return ys, jnp.where(jnp.any(failed), sts[jnp.argmax(failed)], Status.SUCCESS)


def _hybrid_states(dyn, x0, t0, t1, ts, cfg):
    """``integrate``'s hybrid states, status and event counts (no lane-by-lane wrapper: for
    the derivatives, which ``_flow_jvp`` runs lane by lane as a whole)."""
    ys, x, status, _, _, counted = _hybrid(dyn, x0, t0, t1, ts, cfg)
    return (x[None] if ts is None else ys), status, counted


def event_counts(dyn, x0, t1, cfg):
    """Impacts and the time [s] a contact is held closed, from scaled state ``x0`` at
    ``t = 0`` to ``t1``, counted at the events of a hybrid system (rigid impacts happen at
    instants that no sampling of the orbit resolves); no derivatives."""
    def counted(dyn, x0, t1, cfg):
        return _hybrid_states(dyn, x0, 0.0, t1, None, cfg)[2]

    return lane_by_lane(counted)(*jax.lax.stop_gradient((dyn, x0, t1)), cfg)


@eqx.filter_jit
def _hybrid(dyn, x0, t0, t1, ts, cfg):
    """``hybrid_solve`` of ``dyn`` under ``cfg`` (its tolerances, step and segment
    budgets) on the scaled state."""
    system, forcing = dyn
    return hybrid_solve(system, forcing, x0, t0, t1, ts, solver=cfg.solver,
                        rtol=cfg.rtol * cfg.tol_factors[0], atol=cfg.atol * cfg.tol_factors[1],
                        max_steps=cfg.max_steps, scale=state_scale(system, forcing),
                        max_segments=max_segments(cfg),
                        closed_form=cfg.closed_form)


def flat_inputs(primals, tangents):
    """The inexact leaves of ``primals`` that carry a tangent, as one vector; a function that
    puts such a vector back; and the tangents as one vector."""
    active, t_vec = _active_tangents(tangents)
    vec, rebuild = _flat_active(primals, active)
    return vec, rebuild, t_vec


def _active_tangents(tangents):
    """The indices of the leaves that carry a tangent, and those tangents as one vector."""
    t_leaves = jax.tree_util.tree_leaves(tangents, is_leaf=lambda a: a is None)
    active = [i for i, t in enumerate(t_leaves) if t is not None]
    return active, jnp.concatenate([jnp.ravel(t_leaves[i]) for i in active])


def _flat_active(primals, active):
    """The leaves ``active`` (indices) of ``primals`` as one vector, and a function that puts
    such a vector back."""
    is_none = lambda a: a is None  # noqa: E731
    p_leaves, p_def = jax.tree_util.tree_flatten(primals, is_leaf=is_none)
    shapes = [jnp.shape(p_leaves[i]) for i in active]
    sizes = [int(jnp.size(p_leaves[i])) for i in active]
    vec = jnp.concatenate([jnp.zeros((0,))]
                          + [jnp.ravel(jnp.asarray(p_leaves[i], dtype=float)) for i in active])

    def rebuild(v):
        leaves, k = list(p_leaves), 0
        for i, shape, size in zip(active, shapes, sizes):
            leaves[i] = jnp.reshape(v[k:k + size], shape)
            k += size
        return jax.tree_util.tree_unflatten(p_def, leaves)

    return vec, rebuild


@integrate_flow.def_jvp
def _flow_jvp(primals, tangents, *, cfg, counts=False):
    is_none = lambda a: a is None  # noqa: E731
    dyn, x0, t1, ts = primals
    no_tangent = (None, None) + (((None, None),) if counts else ())
    if all(t is None for t in jax.tree_util.tree_leaves(tangents, is_leaf=is_none)):
        return integrate(dyn, x0, 0.0, t1, ts, cfg, counts), no_tangent
    # Smooth systems: a Jacobian in the system, forcing and initial state; the save times
    # (they move with the forcing period) add the flow's rate there.  They are not input
    # directions of the Jacobian: sampling an orbit at 256 times whose tangent is the
    # period's would carry 256 more tangents through the solve (measured: the 22-point grid
    # pass of exact_peak on a TMD takes 0.15 s this way, 1.23 s with them).  Hybrid (exact
    # stick–slip, rigid impacts) systems: the system, forcing, initial state and final time
    # through the event times and the segments' steps; the save times (256 of them a
    # period, each a direction of the Jacobian otherwise) add the rate of the mode there.
    hybrid = is_hybrid(dyn[0])
    k = 3 if hybrid else 2
    if any(t is not None for t in jax.tree_util.tree_leaves(tangents[:k], is_leaf=is_none)):
        active, t_vec = _active_tangents(tangents[:k])
        if _by_sensitivities(dyn, cfg):
            dyn_active = any(t is not None for t in
                             jax.tree_util.tree_leaves(tangents[0], is_leaf=is_none))

            def sensitivities(inputs, t1, ts):
                return _sensitivity_jacobian(inputs, tuple(active), t1, ts, cfg, dyn_active)

            if large_state(dyn[0]):
                sensitivities = lane_by_lane(sensitivities)
            jac, (ys, status) = sensitivities(primals[:k], t1, ts)
            counted = _no_counts(ys)
        else:
            # through the explicit solver's steps (diffrax ForwardMode, one solve for all
            # directions)
            def jacobian(primals, cfg):
                return _forward_jacobian(primals, tuple(active), cfg)

            if hybrid and ts is None and closed_form_flights(*dyn, cfg):
                def jacobian(primals, cfg):
                    return _closed_form_jacobian(primals, tuple(active), cfg)

            # hybrid systems' lanes each follow their own events (see lane_by_lane)
            jac, (ys, status, counted) = (lane_by_lane(jacobian) if hybrid
                                          else jacobian)(primals, cfg)
        # an integration gone wrong (at a trial Newton iterate, say) gives no derivative
        # rather than a non-finite one: the status flags the point, and the linear solves
        # downstream (lineax raises on NaN even with throw=False) see finite input
        jac = jnp.where(jnp.isfinite(jac), jac, 0.0)
        dys = jnp.tensordot(jac, t_vec, axes=1)
    else:
        ys, status, counted = integrate(dyn, x0, 0.0, t1, ts, cfg, True)
        dys = jnp.zeros_like(ys)
    if hybrid:
        dt = None if ts is None else tangents[3]
    else:
        dt = tangents[2] if ts is None else tangents[3]
    if dt is not None:
        t_save = jnp.asarray(t1)[None] if ts is None else ts
        rate = _mode_rate if hybrid else _scaled_rate
        f = jax.vmap(lambda t, x: rate(dyn, t, x))(t_save, ys)
        dys = dys + jnp.where(jnp.isfinite(f), f, 0.0) * jnp.reshape(dt, (-1, 1))
    if counts:
        return (ys, status, counted), (dys, None, (None, None))
    return (ys, status), (dys, None)


@eqx.filter_jit
def _forward_jacobian(primals, active, cfg):
    """``_flow_jvp``'s Jacobian in the leaves ``active`` (indices) of ``primals[:k]``
    (``k = 3`` for a hybrid system, whose final time is an input direction, else 2)
    through the explicit solver's steps: diffrax ``ForwardMode``, one solve for all
    directions.  Returns ``(jac, (ys, status, counts))``."""
    hybrid = is_hybrid(primals[0][0])
    k = 3 if hybrid else 2
    vec, rebuild = _flat_active(primals[:k], active)

    def states(v):
        dyn_, x0_, t1_, ts_ = tuple(rebuild(v)) + primals[k:]
        if hybrid:
            ys, status, counted = _hybrid_states(dyn_, x0_, 0.0, t1_, ts_, cfg)
        else:
            ys, status, counted = integrate(dyn_, x0_, 0.0, t1_, ts_, cfg, True)
        return ys, (ys, status, jax.lax.stop_gradient(counted))

    return jax.jacfwd(states, has_aux=True)(vec)


def closed_form_flights(system, forcing, cfg):
    """Whether the hybrid integrations of ``system`` under ``forcing`` and ``cfg`` fly in
    closed form (``_integration.flights``)."""
    return cfg.closed_form and in_closed_form(system, forcing)


@eqx.filter_jit
def _closed_form_jacobian(primals, active, cfg):
    """``_flow_jvp``'s Jacobian of a hybrid period map whose flights are in closed form
    (``stickslip.closed_form_jacobian``): the system's and forcing's active leaves are the
    parameters (replayed), the start state's and final time's the rest (through the
    integration), and so is the forcing frequency where it is the only active parameter
    and enters the modes through their rotation block alone
    (``flights.frequency_in_rotation_only``; measured on the hard rigid scene of
    scripts/benchmark_rigid_impacts.py, the state and frequency columns in about two
    thirds of the time the replay took).  Returns ``(jac, (ys, status, counts))`` as
    ``jacobian`` there."""
    is_none = lambda a: a is None  # noqa: E731
    dyn, x0, t1 = primals[:3]
    n_sys = len(jax.tree_util.tree_leaves(dyn[0], is_leaf=is_none))
    n_dyn = len(jax.tree_util.tree_leaves(dyn, is_leaf=is_none))
    params = [i for i in active if i < n_dyn]
    leaf = frequency_leaf(dyn[1])
    if (leaf is not None and params == [n_sys + leaf]
            and frequency_in_rotation_only(dyn[0].prepared(), dyn[1])):
        # the forcing frequency alone: a direction of the integration itself, as the
        # start state (``flights._frequency_jvp``), not of the replay
        params = []
    p, rebuild_p = _flat_active(dyn, params)
    s, rebuild_s = _flat_active(primals[:3], [i for i in active if i not in params])

    def make(p, s):
        dyn_s, x0_, t1_ = rebuild_s(s)
        system, forcing = rebuild_p(p) if params else dyn_s
        return system, forcing, x0_, 0.0, t1_, state_scale(system, forcing)

    J_p, J_s, out = closed_form_jacobian(make, p, s, max_nodes=cfg.max_steps,
                                         max_segments=max_segments(cfg))
    _, x, status, _, _, counted = out
    jac = jnp.concatenate([J_p, J_s], axis=1)[None]
    return jac, (x[None], status, jax.lax.stop_gradient(counted))


# Explicit solvers on systems with at least this many states take their derivatives from
# the matrix sensitivity equations (one solve, all directions integrated together) rather than
# from diffrax ForwardMode (the solve vmapped over the tangent directions): measured on a
# 64-lane vmapped monodromy of the 44-state 20-DOF building of
# scripts/benchmark_structure.py, 4.4 s against 7.5 s (same steps, same numbers); on the
# 12-state 3-storey building with three TMDs of tests/systems/test_structure.py 0.112 s against
# 0.151 s; on the
# 5-state Table 1 impact absorber ForwardMode is a little faster (256 lanes: 56 vs 69 ms).
SENSITIVITY_STATES = 12


def large_state(system):
    """Whether ``system`` has a large state (>= ``SENSITIVITY_STATES``): derivatives by
    sensitivity equations, integrated lane by lane under vmap (``lane_by_lane``),
    Floquet monodromies coarse first (``_periodic.orbit.floquet_matrix``), chained sweep lanes one
    at a time, a smooth system's plain integrations with unrolled stages
    (``integrate``)."""
    return system.num_states >= SENSITIVITY_STATES


def _by_sensitivities(dyn, cfg):
    """Derivatives by sensitivity equations (implicit solvers, explicit ones whose steps
    are controlled on the tangents, and large states), not through the solver's steps."""
    implicit = isinstance(cfg.solver, diffrax.AbstractImplicitSolver)
    large = large_state(dyn[0])
    return (implicit or cfg.tangent_control or large) and not is_hybrid(dyn[0])


def lane_by_lane(fn):
    """``fn`` (of arrays, returning arrays), evaluated one lane at a time (``jax.lax.map``)
    when vmapped, instead of all lanes in lockstep.

    For integrations of a large augmented state (a 44-state system's 44 × 44 sensitivities):
    vmapped, every step of every lane waits for the lane with the most steps and each step
    streams the whole batch (64 lanes × 1980 components) through memory; lane by lane, each
    integration takes its own steps on a state that stays in cache.  Measured on 64 Floquet
    monodromies of the 44-state building of ``scripts/benchmark_structure.py`` (this 2-core
    machine): 4.31 s vmapped, 1.85 s lane by lane (the same matrices to 1e-13).  Small
    states (a plain period of the same system: 2.3 ms per lane vmapped against 4 ms alone
    through diffrax's stage loop, 2.4 ms with unrolled stages) are better vmapped, except
    in event-driven (hybrid) integrations, whose lanes meet their events at different
    times and take different numbers of segments: 8 lanes of a chattering rigid-impact
    absorber, 4.4 ms a period vmapped, 3.3 ms lane by lane (8 x 0.37 ms alone).
    Closed-over values must not be batched: pass them as arguments."""
    from jax.custom_batching import custom_vmap

    def call(*args):
        leaves, tree = jax.tree_util.tree_flatten(args)
        arrays = [i for i, a in enumerate(leaves) if eqx.is_array(a)]

        @custom_vmap
        def g(*dyn):
            full = list(leaves)
            for i, a in zip(arrays, dyn):
                full[i] = a
            return fn(*jax.tree_util.tree_unflatten(tree, full))

        @g.def_vmap
        def rule(axis_size, in_batched, *dyn):
            dyn = [a if b else jnp.broadcast_to(a, (axis_size,) + jnp.shape(a))
                   for a, b in zip(dyn, in_batched)]
            out = jax.lax.map(lambda d: g(*d), dyn)
            return out, jax.tree_util.tree_map(lambda _: True, out)

        return g(*[leaves[i] for i in arrays])

    return call


@eqx.filter_jit
def _sensitivity_jacobian(inputs, active, t1, ts, cfg, dyn_active):
    """The Jacobian of ``integrate_flow`` in the leaves ``active`` (indices) of ``inputs =
    (dyn, x0)``, flattened into one vector ``vec`` (the save times fixed), by the matrix
    sensitivity equations
    ``Ẋ_v = ∂f/∂x X_v + ∂f/∂v``, all ``m`` input directions integrated together with the
    state in one solve.

    Derivatives of the equations, not of the solver's internals: none passes through an
    implicit solver's stage Newton solve (whose forward-mode derivative raises inside
    lineax when a trial stage diverges, as on LuGre with sigma0 >= 1e6).  One solve, not
    one per direction (``jax.jacfwd`` of a per-direction augmented solve integrates the
    state again with every tangent): the Floquet multipliers of the 256-point Table 1 sweep
    take 0.43 s this way against 1.24 s direction by direction.  The steps are controlled as
    direction by direction would control them: on the state only (implicit solvers), or
    (``tangent_control``) on the state together with the worst single direction.  The
    state returned is this solve's (with tangent control its steps are finer than a
    state-only solve's: the two differ at the integration tolerance, far below shooting's).
    Jitted on its arguments alone: the monodromies one program repeats are traced once.
    Returns ``(jac, (ys, status))``, ``jac`` of shape ``ys.shape + (m,)``."""
    vec, rebuild = _flat_active(inputs, active)
    dyn, x0 = rebuild(vec)
    # one direction per row: (m, n), the layout vmap batches without transposes
    D0 = jax.jacfwd(lambda v: rebuild(v)[1])(vec).T

    def augmented(t, y, a):
        x, D = y
        # the sensitivity rate is linear in D; its dependence on x is hidden from the
        # implicit solver's Jacobian (stop_gradient), which is then block-diagonal (the
        # second derivatives of the contact law, singular for Hertz at first contact, would
        # otherwise stall the stage Newton iterations)
        xs = jax.lax.stop_gradient(x)
        _, lin = jax.linearize(lambda x_: _scaled_rate(dyn, t, x_), xs)
        dD = jax.vmap(lin)(D)
        if dyn_active:
            dD = dD + jax.jacfwd(lambda v: _scaled_rate(rebuild(v)[0], t, xs))(vec).T
        return _scaled_rate(dyn, t, x), dD

    if cfg.tangent_control:
        def norm(e):
            # the state with the worst single direction, as when each was integrated alone
            ex, eD = e
            return jnp.sqrt(0.5 * (jnp.mean(ex**2) + jnp.max(jnp.mean(eD**2, axis=-1))))
    else:
        norm = lambda e: optx.rms_norm(e[0])  # noqa: E731
    if cfg.unroll_tangents:
        # integrated alone (lane by lane), a large state's 44 x 44 sensitivities spend a
        # third of each step in diffrax's stage loop: unrolled stages (_integration.unrolled;
        # _periodic.orbit.floquet_matrix asks for them only for large states)
        cfg = dataclasses.replace(cfg, solver=unrolled(cfg.solver))
    (ys, dys), status = _diffeqsolve(augmented, (x0, D0), 0.0, t1, ts, cfg, norm=norm)
    dys = jnp.swapaxes(dys, -1, -2)                                   # (..., n, m)
    # a sensitivity integration that failed gives no derivative (the status flags the point)
    dys = jnp.where((status == Status.SUCCESS) & jnp.isfinite(dys), dys, 0.0)
    return dys, (ys, status)


def flow_along(dyn, x0, v0, t1, ts, cfg):
    """Scaled states of ``dyn`` from ``x0`` at ``t = 0`` saved at ``ts``, the flow's
    derivative along the single direction ``v0`` saved with them, and the status.

    One integration of the state and that tangent together, with steps controlled on both
    (as ``accurate_tangents``): what a Lyapunov exponent needs, at the cost of one
    tangent rather than the ``n`` of a Jacobian (``jax.jvp`` of ``integrate_flow`` assembles the
    full Jacobian first).  Hybrid (exact stick–slip) systems, whose tangent crosses events,
    take ``jax.jvp`` of ``integrate_flow``.  Returns ``(ys, vs, status)``."""
    if is_hybrid(dyn[0]):
        (ys, status), (vs, _) = jax.jvp(lambda z: integrate_flow(dyn, z, t1, ts, cfg=cfg),
                                        (x0,), (v0,))
        return ys, vs, status

    def augmented(t, y, a):
        x, v = y
        # the tangent's rate is linear in v; its dependence on x is hidden from an implicit
        # solver's Jacobian (as in _sensitivity_jacobian)
        _, jv = jax.jvp(lambda x_: _scaled_rate(dyn, t, x_), (jax.lax.stop_gradient(x),), (v,))
        return _scaled_rate(dyn, t, x), jv

    def norm(e):
        return jnp.sqrt(0.5 * (jnp.mean(e[0] ** 2) + jnp.mean(e[1] ** 2)))

    (ys, vs), status = _diffeqsolve(augmented, (x0, v0), 0.0, t1, ts, cfg, norm=norm)
    return ys, vs, status


def period_map(system, forcing, x0, n, cfg: Config, t0=0.0, *, n_cap=None):
    """Scaled state after ``n`` forcing periods from ``t = 0``, and the integrator's status
    (``t0`` must be a multiple of the forcing period; ``n`` may be traced when ``n_cap``,
    its static upper bound, is given)."""
    del t0
    T = 2 * jnp.pi / forcing.omega
    cfg_n = cfg.over_periods(n if n_cap is None else n_cap)
    ys, status = integrate_flow((system, forcing), x0, n * T, None, cfg=cfg_n)
    return ys[-1], status


def accurate_tangents(cfg: Config) -> Config:
    """``cfg`` for a Jacobian whose integration steps are controlled on the tangents as well
    as the state (explicit solvers; implicit ones integrate sensitivity equations anyway).
    Floquet multipliers and continuation tangents use it: forward mode through steps chosen
    for the state alone differentiates the discrete flow, whose Jacobian across a stiff
    contact (a smoothed kink) is off by up to ~1e-3 (measured on the hardening oscillator of
    tests/continuation/test_continuation.py against exact piecewise-linear multipliers: 8e-4
    against 6e-3 for steady_state, 3e-6 against 1.8e-3 for continuation)."""
    if isinstance(cfg.solver, diffrax.AbstractImplicitSolver):
        return cfg
    return dataclasses.replace(cfg, tangent_control=True)


def make_config(system, forcing, solver=None, rtol=1e-9, atol=1e-9, max_steps=200_000, *,
                closed_form=None):
    """The integration settings of ``system`` under ``forcing``: ``solver`` resolved (None or
    ``"auto"``: by the scene), tangent control where the scene is stiff for an explicit
    solver, and flights in closed form where ``closed_form`` (None: where the solver is
    ``left_to_scene``; a caller that resolved it first passes that of its own input)."""
    _, solver_obj = _resolve_solver(solver, system, forcing, rtol)
    explicit = not isinstance(solver_obj, diffrax.AbstractImplicitSolver)
    lam, period = system.stiffness_rate(), forcing.period
    stiffish = (not is_traced(lam) and not is_traced(period)
                and float(lam) * float(period) > TANGENT_CONTROL_STEPS_PER_PERIOD)
    return Config(solver=solver_obj, rtol=float(rtol), atol=float(atol), max_steps=int(max_steps),
                   tangent_control=bool(explicit and stiffish and not is_hybrid(system)),
                   closed_form=left_to_scene(solver) if closed_form is None
                   else bool(closed_form))
