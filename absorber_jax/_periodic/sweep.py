"""Frequency-response curves: steady states over a frequency grid (and a design grid) in
one compiled, vmapped call per chunk."""

from __future__ import annotations

import dataclasses
import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core import tables
from .._core.checks import check_time_grid, require_x64
from .._core.devices import by_parts, over_lanes, put
from .._core.legacy import moved, no_more
from .._core.progress import PointProgress
from .._core.status import Status, nan_where_failed
from .._core.units import Signals, signals_of
from .._integration.flow import lane_by_lane, large_state, state_scale
from .._integration.settings import integrator_from
from .._integration.simulate import choose_solver, left_to_scene
from .._systems.base import AbstractSystem, is_hybrid
from .._systems.forcing import at_frequency, sweep_shape
from .._systems.params import replace_params, resolve
from .._systems.scales import warn_scales
from .base import AbstractChainingMethod
from .orbit import SteadyResults, read_through
from .steady import (
    SteadyState,
    make_config,
    march_from_rest,
    march_then_shoot,
    method_from,
    polished,
    solve_point,
)

# the per-point scalar results of the point solve (SteadyState), read through
FIELDS = tuple(f.name for f in dataclasses.fields(SteadyState)
               if f.name not in ("state", "multipliers") and not f.name.startswith("dof_"))
DOF_FIELDS = tuple(f.name for f in dataclasses.fields(SteadyState) if f.name.startswith("dof_"))


class FrequencyResponse(SteadyResults, eqx.Module):
    """Steady-state results over ``omegas`` (and designs): the point solve's
    [`SteadyState`][absorber_jax.SteadyState], batched (``steady``), with the grid.

    Every field of [`SteadyState`][absorber_jax.SteadyState] reads through (``amplitude``,
    ``stable``, ``status``, ``dof_amplitude`` ...; ``states`` and ``multipliers`` for ``state`` and
    ``multipliers``).  Arrays have shape ``(F,)`` for a plain sweep, or ``(P, F)`` when
    ``params`` gave ``P`` designs (per-degree-of-freedom fields add a last axis over
    ``dof_names``).  ``status`` is per point (0 = success, see [`Status`][absorber_jax.Status]); a
    failed point never spoils the others.  ``direction`` is ``"parallel"`` (every point from its own
    linear guess), ``"up"`` or ``"down"`` (each point seeded from its neighbour: follows a branch,
    shows hysteresis).  The measured fields (``amplitude`` ... ``dof_harmonic``) are NaN at
    failed points.  ``signals``: the names and SI units of what the fields measure (the
    observable, the absorber stroke, the degrees of freedom), as the CSV headers, plot labels
    and ``to_xarray`` attributes give them."""

    omegas: np.ndarray
    steady: SteadyState
    params: dict
    direction: str = eqx.field(static=True, default="parallel")
    dof_names: tuple = eqx.field(static=True, default=())
    signals: Signals = eqx.field(static=True, default=Signals())

    def failures(self):
        """``[(index, what failed and what to try)]`` of the points that failed."""
        return tables.failure_list(self.status)

    def to_csv(self, path):
        """One row per (design, frequency), SI values, each header with its unit: the sweep
        direction, the design parameters, ``omega [rad/s]``, the observable's statistics
        (``amplitude x1 [m]``, ``rms``, ``harmonic``), the absorber stroke's (``amplitude
        x2 - x1 [m]``: relative motion), impacts, period multiple, stability, status,
        residual, iterations, the largest |multiplier|, each degree of freedom's absolute
        statistics (``dof amplitude x2 [m]``), the status text; ``nan`` at failed points."""
        tables.write_csv(path, tables.frequency_response_columns(self))

    def to_dataframe(self):
        """The rows of ``to_csv`` as a ``pandas.DataFrame`` (needs pandas)."""
        return tables.dataframe(tables.frequency_response_columns(self),
                                "FrequencyResponse.to_dataframe")

    def to_xarray(self):
        """An ``xarray.Dataset`` over ``omega`` [rad/s] (and ``design``, with the design
        parameters as coordinates): every field with ``units`` and ``long_name``, the
        per-degree-of-freedom fields over ``dof``, ``state`` and ``multipliers`` over their
        components, ``status`` with its code names (needs xarray)."""
        return tables.frequency_response_dataset(self)


read_through(FrequencyResponse, FIELDS + DOF_FIELDS, "point")


def _forcing(amplitude, omega):
    """The forcing at ``omega``: ``amplitude`` is a force amplitude (a ``Harmonic``) or a
    periodic forcing (its ``with_omega``)."""
    return at_frequency(amplitude, omega)


def _one_point(system, omega, amplitude, guess, cfg, method, with_floquet):
    return solve_point(system, _forcing(amplitude, omega), method, cfg, guess=guess,
                       with_floquet=with_floquet)


# points per resume call, and per retry call where the lanes are vmapped (one compilation;
# lanes one after the other: the first pass's batch, see _finish_stragglers)
RETRY_BATCH = 8
# Newton steps of the vmapped first pass: a lane still iterating then is resumed from its
# best iterate with the rest of the budget, in a small batch, so that the whole chunk does
# not run in lockstep at the pace of its slowest lane (measured on the friction absorber of
# scripts/benchmark_sweep.py: 230 of 256 points converge in <= 5 steps, one takes 14).
# 5 rather than 8 (measured on the three scenes of scripts/benchmark_sweep.py, 256 points):
# Table 1 1.04 s against 1.23 s, Table 5 LuGre 7.1 against 9.1 s, exact Coulomb 1.65
# against 1.72 s; a 5th step is mostly Newton confirming a residual already within tolerance
FIRST_PASS_NEWTON = 5
# chunks of at most this many points run every lane's whole Newton budget in the vmapped
# pass: resuming a few stragglers of so few lanes would compile a second program (10-20 s)
# to save a few lockstep Newton steps (ms)
SMALL_CHUNK = 2 * RETRY_BATCH


@eqx.filter_jit
def retry_chunk(system, omegas, amplitude, pvals, cfg, method, names, with_floquet, live):
    """March then shoot at each lane's frequency ``omegas`` and parameter values ``pvals``;
    ``live``: False for the lanes that pad a batch (skipped where the lanes run one after
    the other: ``over_lanes``)."""
    def point(w, pv):
        return march_then_shoot(_with(system, names, pv), _forcing(amplitude, w), cfg, method,
                                with_floquet=with_floquet)

    return over_lanes(point, is_hybrid(system), masked=True)(live, omegas, pvals)


@eqx.filter_jit
def march_chunk(system, omegas, amplitude, pvals, cfg, names, with_floquet, live):
    """``march_from_rest`` at each lane's frequency and parameter values: the marches of
    ``march_then_shoot``, whose polishing shots run in programs the caller already has
    (the sweep's, ``_finish_stragglers``; a design's, ``tune``'s reseeding); their
    results and the marched internal states."""
    def point(w, pv):
        sysp, forcp = _with(system, names, pv), _forcing(amplitude, w)
        ma, xm = march_from_rest(sysp, forcp, cfg, with_floquet=with_floquet)
        return ma, xm * state_scale(sysp, forcp)

    return over_lanes(point, is_hybrid(system), masked=True)(live, omegas, pvals)


def _retry_batch(system):
    """Points per resume or retry call: ``RETRY_BATCH``, or 1 for large states, whose
    Jacobians run lane by lane, so that a padding lane costs as much as a real one (the
    20-DOF building's one straggler of 256 points was resumed in a batch of 8: 0.82 s of
    a 7.2 s sweep)."""
    return 1 if large_state(system) else RETRY_BATCH


def _in_batches(res, bad, solve, desc, progress, size):
    """Apply ``solve(padded indices, live)`` to the points ``bad`` of a flat (point-axis)
    result in fixed batches of ``size`` (one compilation; ``live`` False on the padding)
    and write the results back; the iteration counts add up."""
    if bad.size == 0:
        return res
    with PointProgress(bad.size, desc, bool(progress)) as bar:
        for start in range(0, bad.size, size):
            idx = bad[start:start + size]
            pad = np.concatenate([idx, np.repeat(idx[-1:], size - idx.size)])
            k = idx.size
            live = jnp.asarray(np.arange(size) < k)
            out = jax.tree_util.tree_map(lambda a, k=k: np.asarray(a)[:k], solve(pad, live))
            res = _written(res, idx, out)
            bar.update(k)
    return res


def _finish_stragglers(system, res, W, PV, amp, cfg, method, rest, names, with_floquet,
                       progress, first=None, size=None, ndev=1):
    """After the vmapped first pass: resume the lanes still iterating from their last
    iterate with ``rest`` (``method.resume``; None when the first pass had the whole
    budget), then (``method.retry``) re-solve what still failed by marching then
    shooting.

    Given the first pass's method ``first``, batch ``size`` and devices ``ndev`` (points
    solved independently, lanes one after the other, so that a padding lane costs
    nothing), the retry's marches run in a program of their own and its polishing shots
    in those already built, as the sweep's own points: the first pass's, then the
    resume's for the rest of the Newton budget, rather than a march-then-shoot program
    holding a third copy of the shooting solve (the rigid-ball building of
    scripts/benchmark_rigid_impacts.py, compilation cache off, one machine: the marches
    traced and compiled in 37-46 s against 81 s for march-then-shoot, the first call
    123-148 s against 176 s; the same statuses, impacts and stability labels, amplitudes
    equal to 2e-15, a retried point's Newton count up to 5 more: the resume restarts from
    the first pass's best iterate)."""
    res = jax.tree_util.tree_map(np.array, res)  # writable copies

    def guesses(p, states):
        return jnp.asarray(np.stack([np.asarray(_with(system, names, PV[i]).to_internal(x))
                                     for i, x in zip(p, states)]))

    def resumed(out, points, desc):
        # ``rest`` on the rows of ``out`` still iterating (``points``: each row's point),
        # from their best iterates
        slow = np.flatnonzero(out.status == Status.NO_CONVERGENCE)
        states = np.array(out.state)
        return _in_batches(out, slow, lambda j, live: _parallel_chunk(
            system, jnp.asarray(W[points[j]]), amp, jnp.asarray(PV[points[j]]),
            guesses(points[j], states[j]), cfg, rest, names, with_floquet, live), desc,
            progress, _retry_batch(system))

    if rest is not None:
        res = resumed(res, np.arange(W.shape[0]), "resume")
    if not method.retry:
        return res
    bad = np.flatnonzero(res.status != Status.SUCCESS)
    if first is None or not bad.size:
        return _in_batches(res, bad, lambda p, live: retry_chunk(
            system, jnp.asarray(W[p]), amp, jnp.asarray(PV[p]), cfg, method, names,
            with_floquet, live), "retry", progress, _retry_batch(system))
    ma, xm = by_parts(bad, size, lambda p, live, d: march_chunk(
        system, put(W[p], d), amp, put(PV[p], d), cfg, names, with_floquet, put(live, d)),
                      ndev, progress)
    # the whole Newton budget, as the sweep's own points had it: the first pass's, then
    # (the marched points still iterating) the rest of it in the resume's program
    shot = by_parts(np.arange(bad.size), size, lambda j, live, d: _parallel_chunk(
        system, put(W[bad[j]], d), amp, put(PV[bad[j]], d), put(xm[j], d), cfg, first,
        names, with_floquet, put(live, d)), ndev)
    if rest is not None:
        shot = resumed(jax.tree_util.tree_map(np.array, shot), bad, "retry")
    return _written(res, bad, polished(ma, shot, method.n, np))


def _written(res, idx, out):
    """The flat results ``res`` with the points ``idx`` replaced by ``out`` (one per point
    of ``idx``), their iterations added to those already spent."""
    out = eqx.tree_at(lambda r: r.iterations, out, out.iterations + res.iterations[idx])

    def write(dst, src):
        dst[idx] = src
        return dst

    return jax.tree_util.tree_map(write, res, out)


def _with(system, names, values):
    return replace_params(system, dict(zip(names, values)), check=False) if names else system


@eqx.filter_jit
def _parallel_chunk(system, omegas, amplitude, pvals, guesses, cfg, method, names,
                    with_floquet, live):
    """``method`` at each lane's frequency and parameter values from the lane's guess (an
    internal state; NaN: the method's own start)."""
    def point(w, pv, g):
        return _one_point(_with(system, names, pv), w, amplitude, g, cfg, method,
                          with_floquet)

    return over_lanes(point, is_hybrid(system), masked=True)(live, omegas, pvals, guesses)


# points one lane of a chained sweep solves in a row (see _chained_sweep)
MAX_CHAIN = 16
# ... and when its lanes run one at a time (see _one_lane_at_a_time): one lane per device and
# compiled call
ALONE_CHAIN = 64


# a chained point extrapolates its start (orbit and Jacobian) linearly from the last two
# converged points of its lane when its frequency lies within this many of their spacings
# beyond the last (a failed point between them widens the gap); farther, the last alone
MAX_EXTRAPOLATION = 1.5


@eqx.filter_jit
def _chained_chunk(system, omegas, amplitude, pvals, cfg, method, names, with_floquet):
    """Lanes (vmapped) of consecutive frequencies ``omegas[lane]``: each point solved by
    ``method.solve_chained`` from the lane's last converged orbits and the Jacobians they
    left (the first point from the method's own start and ``method.chain_jacobian`` there).
    Once two points have converged, the start is their linear extrapolation in ω (the
    Jacobians too, when each point leaves its own: ``with_floquet``): measured on the
    44-state building of ``scripts/benchmark_structure.py``, quasi-Newton steps per point
    median 7 -> 5 (the neighbour's orbit alone is a few percent off there, the secant
    ~3x closer, and its Jacobian error about halves).  Large states' lanes run one at a
    time (``_one_lane_at_a_time``)."""

    def lane(ws, pv, system, amplitude):
        sysp = _with(system, names, pv)
        f0 = _forcing(amplitude, ws[0])
        s0 = state_scale(sysp, f0)
        x0 = method.initial_state(sysp, f0)

        def step(carry, w):
            # the last two converged points: internal orbit states, Jacobians in unscaled
            # internal coordinates (diag(s) J diag(1/s): velocities scale with ω), frequencies
            # (NaN until a point has converged there)
            (x1, j1, w1), (x2, j2, w2) = carry
            f = _forcing(amplitude, w)
            s = state_scale(sysp, f)
            # (a padded lane repeats its last frequency: w1 == w2 there, no extrapolation)
            two = jnp.isfinite(w2) & (w1 != w2)
            r = (w - w1) / jnp.where(two, w1 - w2, 1.0)
            r = jnp.where(two & (r <= MAX_EXTRAPOLATION), r, 0.0)
            x = x1 + r * (x1 - x2)
            jac = (j1 + r * (j1 - j2)) if with_floquet else j1
            res, jac = method.solve_chained(sysp, f, x / s, jac / s[:, None] * s[None, :], cfg,
                                            with_floquet=with_floquet)
            ok = res.status == Status.SUCCESS
            new = ((sysp.to_internal(res.state), s[:, None] * jac / s[None, :], w), (x1, j1, w1))
            return jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), new, carry), res

        j0 = s0[:, None] * method.chain_jacobian(sysp, f0, x0 / s0, cfg) / s0[None, :]
        first = (x0, j0, jnp.full_like(ws[0], jnp.nan))
        return jax.lax.scan(step, (first, first), ws)[1]

    if _one_lane_at_a_time(system):
        lane = lane_by_lane(lane)
    return jax.vmap(lane, in_axes=(0, 0, None, None))(omegas, pvals, system, amplitude)


def _one_lane_at_a_time(system):
    """Whether a chained sweep runs its lanes one at a time (``lane_by_lane``) rather than
    vmapped in lockstep: for large states (``_integration.flow.large_state``), whose Floquet
    monodromies run lane by lane anyway.  In lockstep every point of a chunk of lanes waits
    for the lane needing the most quasi-Newton steps (the 44-state building of
    ``scripts/benchmark_structure.py``: median 7, but up to the first pass's 20 in almost
    every chunk); one at a time, a period integration costs 2.4 ms per lane with its
    stages unrolled (``_integration.unrolled``; 4 ms through diffrax's loop) against 2.3 ms
    vmapped, but each lane takes only its own steps, and lanes can be longer (``ALONE_CHAIN``
    points, one lane per device and compiled call: fewer first points, each started from
    the linear guess with up to ~20 steps).  Measured there, 256 frequencies: 20.4 s
    vmapped (lanes of 4), 17.2 s one at a time in lanes of 16, 15.5 s in lanes of 64."""
    return large_state(system)


def _parallel_sweep(system, W, PV, amp, cfg, first, names, floquet, size, ndev, progress):
    """The points ``(W, PV)`` solved independently, ``size`` per compiled call; the flat
    results."""
    nan = np.full((W.shape[0], system.num_states), np.nan)
    return by_parts(np.arange(W.shape[0]), size, lambda p, live, d: _parallel_chunk(
        system, put(W[p], d), amp, put(PV[p], d), put(nan[p], d), cfg, first, names, floquet,
        put(live, d)), ndev, progress)


def _chained_sweep(system, W, PV, amp, cfg, first, names, floquet, chunk_size, ndev, progress,
                   per_design):
    """The points ``(W, PV)`` (design-major: ``per_design`` frequencies of each design, in
    order) solved in lanes of up to ``MAX_CHAIN`` consecutive frequencies of one design, so
    that every point but a lane's first starts from its neighbours' orbits and monodromies
    (the chord's Jacobian; see ``_chained_chunk``); ``chunk_size`` lanes per compiled call
    (large states: lanes of ``ALONE_CHAIN``, one per device and call).
    Returns the flat results (one per point)."""
    total = W.shape[0]
    alone = _one_lane_at_a_time(system)
    k = int(min(ALONE_CHAIN, per_design) if alone
            else min(MAX_CHAIN, max(1, math.ceil(total / chunk_size))))
    # lanes never cross from one design to the next
    lanes = np.concatenate([np.minimum(np.arange(a, a + per_design, k)[:, None]
                                       + np.arange(k)[None, :], a + per_design - 1)
                            for a in range(0, total, per_design)])      # (L, k) points
    size = ndev if alone else int(math.ceil(min(chunk_size, lanes.shape[0]) / ndev) * ndev)
    res = by_parts(lanes, size, lambda p, live, d: _chained_chunk(
        system, put(W[p], d), amp, put(PV[p[:, 0]], d), cfg, first, names, floquet), ndev,
                   progress)
    # back to one result per point (a lane padded by repeating its last point wrote it twice)
    flat = lanes.reshape(-1)
    where = np.empty(total, dtype=int)
    where[flat[::-1]] = np.arange(flat.size)[::-1]
    return jax.tree_util.tree_map(lambda a: a.reshape((-1,) + a.shape[2:])[where], res)


@eqx.filter_jit
def _sequential_chunk(system, omegas, amplitude, pvals, carry, cfg, method, names, with_floquet):
    """lax.scan along the frequency axis (vmapped over designs), each point seeded from the
    previous point's orbit when that one converged."""

    def per_design(pv, s_prev):
        sysp = _with(system, names, pv)

        def step(s_prev, w):
            res = _one_point(sysp, w, amplitude, s_prev, cfg, method, with_floquet)
            s_int = sysp.to_internal(res.state)
            nxt = jnp.where(res.status == Status.SUCCESS, s_int, jnp.nan)
            return nxt, res

        return jax.lax.scan(step, s_prev, omegas)

    carry, res = jax.vmap(per_design)(pvals, carry)
    return carry, res


def frequency_response(system: AbstractSystem, omegas, *, amplitude, method=None,
                       integrator=None, params=None, direction="parallel", floquet=True,
                       progress=False, **legacy):
    """Steady-state frequency response of ``system`` under ``amplitude·sin(ωt)`` for every
    ``ω`` in ``omegas`` [rad/s], in one jit-compiled vmapped call per chunk of points.

    **Arguments**

    - ``omegas``: sorted 1-D grid [rad/s]; ``amplitude``: force amplitude F0 [N] of
      ``F0 sin(ωt)``, or a periodic forcing (``MultiHarmonic``, ``PeriodicForcing`` ...)
      whose fundamental is swept: ``amplitude.with_omega(ω)`` at each ``ω`` (its own
      ``omega`` is not used).
    - ``method``: ``Shooting(...)`` (the default) or ``Marching(...)`` carrying its options
      (as in ``steady_state``).  With ``Shooting(root="chord")`` the parallel pass follows
      lanes of neighbouring frequencies, each point started from the orbits of the previous
      ones (extrapolated from the last two) with their Floquet monodromy as its Jacobian:
      one monodromy per point, the fastest choice for large structures.
    - ``integrator``: an ``Integrator`` (default: the periodic tolerances).
    - ``params``: optional ``{name: 1-D array}`` of designs (same length ``P``), names as
      ``parameter_names(system)`` lists them (``k1``, ``c1``, ``m``, ``gap``, ``N``, ...).
      Results then have shape ``(P, F)``: a (design × frequency) grid in one call.
    - ``direction``: ``"parallel"`` (every point from its own linear guess), ``"up"`` or
      ``"down"`` (each point seeded from its neighbour: follows one branch through its
      jumps, as a slow sweep on a shaker would).
    - ``floquet``: compute the Floquet multipliers and the stability labels.
    - ``progress``: a tqdm bar over the points, which says when it is compiling.

    Parallel shooting does not wait for stragglers: the vmapped pass runs a few Newton
    steps, the points still iterating resume from their best iterate a few at a time, and
    (``Shooting(retry=True)``, the default) the points that still failed are re-solved by
    marching then shooting before they are flagged.  On a CPU, ``use_cpu_cores()`` (before
    any JAX computation) gives one device per core and the points are split between them.

    **Returns** a ``FrequencyResponse``: arrays over frequency (× designs), with a
    ``status`` per point (0 = success; ``failures()`` says what failed and what to try).

    ```python
    import numpy as np, absorber_jax as aj
    system, _ = aj.presets.impact("kelvin_voigt")
    frf = aj.frequency_response(system, np.linspace(30, 70, 64), amplitude=2.0)
    frf.amplitude, frf.stable, frf.status
    frf = aj.frequency_response(system, np.linspace(30, 70, 64), amplitude=2.0,
                                method=aj.Marching(max_periods=2000),
                                integrator=aj.Integrator(rtol=1e-10, atol=1e-10))
    ```
    """
    require_x64("frequency_response")
    if not isinstance(system, AbstractSystem):
        raise ValueError(f"system must be an ImpactAbsorber, FrictionAbsorber or "
                         f"StructuralSystem, got {type(system).__name__}")
    check_time_grid("omegas", omegas, strictly=True)
    om = np.asarray(omegas, dtype=float)
    if om[0] <= 0:
        raise ValueError(f"omegas must be > 0 [rad/s], got {om[0]:g}")
    amplitude = sweep_shape(amplitude, "frequency_response")
    method = method_from(method, "frequency_response", legacy)
    integ = integrator_from(integrator, "periodic", "frequency_response", legacy)
    solver, rtol, atol, max_steps = integ.solver, integ.rtol, integ.atol, integ.max_steps
    chunk_size, shard = legacy.pop("chunk_size", 64), legacy.pop("shard", True)
    if (chunk_size, shard) != (64, True):
        moved("frequency_response", {"chunk_size": chunk_size, "shard": shard},
              "neither ({}): the library sizes its compiled calls and splits them over the "
              "devices that use_cpu_cores() gives")
    no_more("frequency_response", legacy)
    if direction == "both":
        warnings.warn("frequency_response(direction='both') is deprecated (it returns a pair): "
                      "call it with direction='up' and with direction='down'",
                      DeprecationWarning, stacklevel=2)
    if direction not in ("parallel", "up", "down", "both"):
        raise ValueError(f"direction must be 'parallel', 'up', 'down' or 'both', got {direction!r}")
    if not isinstance(chunk_size, int) or chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    if direction == "both":
        kw = dict(amplitude=amplitude, method=method, params=params, progress=progress,
                  floquet=floquet, integrator=integ)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            kw.update(chunk_size=chunk_size, shard=shard)
            return (frequency_response(system, om, direction="up", **kw),
                    frequency_response(system, om, direction="down", **kw))

    names, pvals = _check_params(system, params)
    warn_scales(system, [_forcing(amplitude, float(w))
                         for w in om[np.linspace(0, om.size - 1, min(om.size, 16)).astype(int)]],
                "frequency_response")
    # a solver left to the scene: rigid impacts on a linear structure fly in closed form
    # (the grid's solver then serves nothing else)
    closed_form = left_to_scene(solver)
    solver = _grid_solver(system, names, pvals, amplitude, om, solver, rtol)
    cfg = make_config(system, _forcing(amplitude, float(om[0])), solver, rtol, atol, max_steps,
                      closed_form=closed_form)
    run = _run_parallel if direction == "parallel" else _run_sequential
    res = run(system, om, pvals, names, amplitude, cfg, method, bool(floquet), direction,
              chunk_size, shard, progress)
    squeeze = params is None
    get = (lambda a: a[0]) if squeeze else (lambda a: a)
    out = FrequencyResponse(
        omegas=om,
        steady=nan_where_failed(jax.tree_util.tree_map(lambda a: get(np.asarray(a)), res)),
        params={k: np.asarray(pvals[:, i]) for i, k in enumerate(names)},
        direction=direction, dof_names=tuple(system.output_names),
        signals=signals_of(system),
    )
    failed = out.failures()
    if failed:
        warnings.warn(f"frequency_response: {len(failed)} of {np.asarray(out.status).size} "
                      f"points failed (their values are NaN); the first, point {failed[0][0]}: "
                      f"{failed[0][1]}; all of them: result.failures()", RuntimeWarning,
                      stacklevel=2)
    return out


def _grid_solver(system, names, pvals, amplitude, om, solver, rtol):
    """The one solver of a sweep's grid: as given, or (``None``/``"auto"``) implicit if any
    design is stiff at the lowest frequency (the longest period: the most explicit steps per
    period)."""
    if not left_to_scene(solver):
        return solver
    designs = pvals if pvals.shape[0] <= 256 else np.stack([pvals.min(0), pvals.max(0)])
    f0 = _forcing(amplitude, float(om[0]))
    stiff = (any(choose_solver(replace_params(system, dict(zip(names, d))), f0,
                               rtol=rtol) != "tsit5" for d in designs)
             if names else choose_solver(system, f0, rtol=rtol) != "tsit5")
    return "kvaerno5" if stiff else "tsit5"


def _run_parallel(system, om, pvals, names, amp, cfg, method, floquet, direction, chunk_size,
                  shard, progress):
    """Every (design, frequency) point from its own start: vmapped chunks over the devices
    (lanes of neighbours with ``Shooting(root="chord")``), then the stragglers resumed and
    the failures retried.  Returns the results shaped ``(P, F)``."""
    P = pvals.shape[0]
    # flatten (design, frequency) into one axis of points
    W = np.broadcast_to(om[None, :], (P, len(om))).reshape(-1)
    PV = np.repeat(pvals, len(om), axis=0)
    total = W.shape[0]
    size = min(chunk_size, total)
    ndev = jax.local_device_count() if shard else 1
    size = int(math.ceil(size / ndev) * ndev)
    first, rest = ((method.first_pass(FIRST_PASS_NEWTON), method.resume(FIRST_PASS_NEWTON))
                   if size > SMALL_CHUNK else (method, None))
    reuse = {}
    if isinstance(method, AbstractChainingMethod) and method.chains:
        res = _chained_sweep(system, W, PV, amp, cfg, first, names, floquet, chunk_size,
                             ndev, progress, len(om))
    else:
        res = _parallel_sweep(system, W, PV, amp, cfg, first, names, floquet, size, ndev,
                              progress)
        if is_hybrid(system):
            # lanes one after the other: the stragglers and retries in the same program
            reuse = dict(first=first, size=size, ndev=ndev)
    res = _finish_stragglers(system, res, W, PV, amp, cfg, method, rest, names, floquet,
                             progress, **reuse)
    res = jax.tree_util.tree_map(lambda a: a.reshape((P, len(om)) + a.shape[1:]), res)
    return res


def _run_sequential(system, om, pvals, names, amp, cfg, method, floquet, direction,
                    chunk_size, shard, progress):
    """Each point seeded from its neighbour's orbit (``direction`` ``"up"`` or ``"down"``),
    in compiled chunks; the points the branch could not be followed to are re-solved by
    marching then shooting.  Returns the results shaped ``(P, F)`` in ``om``'s order."""
    P = pvals.shape[0]
    order = om if direction != "down" else om[::-1]
    carry = jnp.full((P, system.num_states), jnp.nan)
    size = min(chunk_size, len(order))
    out = []
    pv = jnp.asarray(pvals)
    with PointProgress(P * len(order), f"sweep {direction}", bool(progress)) as bar:
        for start in range(0, len(order), size):
            w = order[start:start + size]
            pad = size - w.shape[0]
            if pad:
                w = np.concatenate([w, np.repeat(w[-1:], pad)])
            carry, res = _sequential_chunk(system, jnp.asarray(w), amp, pv, carry, cfg, method,
                                           names, floquet)
            keep = size - pad
            out.append(jax.tree_util.tree_map(lambda a, k=keep: np.asarray(a)[:, :k], res))
            bar.update(P * keep)
    res = jax.tree_util.tree_map(lambda *a: np.concatenate(a, axis=1), *out)
    if direction == "down":
        res = jax.tree_util.tree_map(lambda a: a[:, ::-1], res)
    if method.retry:
        # a point the branch could not be followed to (past a fold, a grazing) is
        # re-solved by marching from rest then shooting: the sweep jumps to the
        # attractor there, as a slow physical sweep would
        flat = jax.tree_util.tree_map(lambda a: np.array(a).reshape((-1,) + a.shape[2:]),
                                      res)
        W = np.broadcast_to(om[None, :], (P, len(om))).reshape(-1)
        PV = np.repeat(pvals, len(om), axis=0)
        bad = np.flatnonzero(flat.status != Status.SUCCESS)
        flat = _in_batches(flat, bad, lambda p, live: retry_chunk(
            system, jnp.asarray(W[p]), amp, jnp.asarray(PV[p]), cfg, method, names,
            floquet, live), "retry", progress, _retry_batch(system))
        res = jax.tree_util.tree_map(lambda a: a.reshape((P, len(om)) + a.shape[1:]), flat)
    return res


def _check_params(system, params):
    if not params:
        return (), np.zeros((1, 0))
    names = tuple(params)
    cols = []
    for k in names:
        resolve(system, k)
        v = np.atleast_1d(np.asarray(params[k], dtype=float))
        if v.ndim != 1:
            raise ValueError(f"params[{k!r}] must be a 1-D array, got shape {v.shape}")
        cols.append(v)
    P = cols[0].shape[0]
    for k, v in zip(names, cols):
        if v.shape[0] != P:
            raise ValueError(f"params arrays must share one length: {names[0]!r} has {P}, "
                             f"{k!r} has {v.shape[0]}")
        # range checks are monotone: validating the extremes validates every design
        for extreme in (v.min(), v.max()):
            replace_params(system, {k: float(extreme)}, check=True)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"params[{k!r}] must be finite")
    return names, np.stack(cols, axis=1)
