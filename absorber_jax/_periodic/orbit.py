"""Periodic orbits as results: amplitudes and harmonics over one response period, the
Floquet multipliers and the stability label.

Amplitudes (over one full response period ``nT``, from uniform samples refined by parabolic
interpolation at the extremes; ``SAMPLES_PER_PERIOD`` per forcing period for the largest
period multiple allowed) of the system's observable (``x1`` for the two-mass systems, the
chosen degree of freedom or weighted set of a ``StructuralSystem``): ``amplitude`` =
half peak-to-peak; ``rms`` = RMS about zero; ``harmonic`` = magnitude of its component at the
forcing frequency; ``dof_amplitude``, ``dof_rms``, ``dof_harmonic`` the same at each of the
system's ``output_names``; ``absorber_amplitude`` and ``absorber_rms`` the same for the
absorber's motion relative to its host (``x2 - x1``; the largest over several absorbers);
``impacts``: contact closures per forcing period (``system.penetrations`` turning positive
between consecutive samples, around the closed orbit, divided by ``n``; 0 without contacts):
resolved for contacts lasting more than a few samples, ``T / 64`` at period 1; with rigid
impacts (``Restitution``), the impacts counted at the events themselves.
``contact_fraction``: the fraction of the response period with a contact closed (a sample
with positive penetration; with rigid impacts the time held against a wall, from the
events).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np

from .._core.status import Status
from .._core.tables import steady_dataset
from .._integration.flights import hermite_apex
from .._integration.flow import (
    accurate_tangents,
    event_counts,
    flat_inputs,
    integrate_flow,
    lane_by_lane,
    large_state,
    period_map,
    state_scale,
)
from .._systems.base import is_hybrid

SAMPLES_PER_PERIOD = 256


class SteadyState(eqx.Module):
    """A periodic response: an orbit of period ``nT`` (``T = 2π/ω`` the forcing period,
    ``n`` = ``period_multiple``), its statistics and its stability.

    The statistics are those of the system's observable (``x1`` for the two-mass systems,
    the chosen degree of freedom or weighted set of a ``StructuralSystem``) over one full
    response period ``nT``, from 256 uniform samples per forcing period refined by parabolic
    interpolation at the extremes, in the observable's unit (m): ``amplitude`` = half
    peak-to-peak; ``rms`` = RMS about zero; ``harmonic`` = magnitude of the component at the
    forcing frequency; ``dof_amplitude``, ``dof_rms``, ``dof_harmonic``: the same at each of
    the system's ``output_names``; ``absorber_amplitude``, ``absorber_rms``: the same for the
    absorber's motion relative to its host (``x2 - x1``; the largest over several
    absorbers); ``impacts``: contact closures per forcing period (0 without contacts),
    resolved for contacts lasting more than a few samples (``T/64`` at period 1), counted
    at the events with rigid impacts; ``contact_fraction``: the fraction of the response
    period with a contact closed (held against a wall, with rigid impacts).

    ``state``: public state (``system.state_names``) on the orbit at ``t = 0 mod nT``;
    ``multipliers``: Floquet multipliers of the period-``nT`` map, the eigenvalues of its
    monodromy matrix (Floquet theory: A. H. Nayfeh, B. Balachandran, *Applied Nonlinear
    Dynamics*, Wiley, 1995; with the exact stick–slip friction laws the monodromy matrix
    carries the saltation matrices of the switches: R. I. Leine, H. Nijmeijer, *Dynamics and
    Bifurcations of Non-Smooth Mechanical Systems*, Springer, 2004); ``stable``: all
    ``|μ| <= 1 + 1e-6``, except, on an orbit where the absorber floats without touching the
    walls, the structural double multiplier 1 of its free position;
    ``status``: [`Status`][absorber_jax.Status]; ``iterations``: Newton steps (shooting) or periods
    marched.
    """

    amplitude: jax.Array
    rms: jax.Array
    harmonic: jax.Array
    absorber_amplitude: jax.Array
    absorber_rms: jax.Array
    impacts: jax.Array
    contact_fraction: jax.Array
    dof_amplitude: jax.Array
    dof_rms: jax.Array
    dof_harmonic: jax.Array
    period_multiple: jax.Array
    state: jax.Array
    multipliers: jax.Array
    stable: jax.Array
    status: jax.Array
    residual: jax.Array
    iterations: jax.Array

    @property
    def ok(self):
        """Whether the solve succeeded (``status == Status.SUCCESS``), per orbit."""
        return self.status == Status.SUCCESS

    def to_xarray(self, system=None):
        """An ``xarray.Dataset`` of this orbit (or batch of orbits, over ``point``): every
        field with ``units`` and ``long_name``, the state and degrees of freedom named and
        the observable and stroke labelled after ``system`` when given (needs xarray)."""

        return steady_dataset(self, system)


class SteadyResults:
    """What results holding a batched ``SteadyState`` as ``steady`` share (sweeps,
    continuation branches): the orbit states, multipliers, success flags and the
    per-degree-of-freedom fields by name (``dof_names``)."""

    @property
    def states(self):
        return self.steady.state

    @property
    def multipliers(self):
        return self.steady.multipliers

    @property
    def ok(self):
        """Whether each point succeeded (``status == Status.SUCCESS``)."""
        return self.status == Status.SUCCESS

    def dof(self, name, field="amplitude"):
        """``dof_<field>`` (amplitude, rms or harmonic) at the degree of freedom ``name``."""
        return dof_field(self.steady, self.dof_names, name, field)


def dof_field(source, names, name, field):
    """``source.dof_<field>`` (points × degrees of freedom ``names``) at the degree of
    freedom ``name`` (ValueError naming the known ones otherwise)."""
    if name not in names:
        raise ValueError(f"dof must be one of {list(names)}, got {name!r}")
    return np.asarray(getattr(source, "dof_" + field))[..., names.index(name)]


def read_through(cls, names, where):
    """Give ``cls`` a read-only property per ``SteadyState`` field in ``names``."""
    for name in names:
        setattr(cls, name, property(lambda self, n=name: getattr(self.steady, n),
                                    doc=f"``SteadyState.{name}`` per {where}."))


def parabolic_peak(y, i):
    """Extreme value of the periodic samples ``y`` near index ``i`` (parabola through 3)."""
    n = y.shape[0]
    a, b, c = y[(i - 1) % n], y[i], y[(i + 1) % n]
    den = a - 2 * b + c
    return b - 0.125 * (a - c) ** 2 / jnp.where(den == 0, 1.0, den) * (den != 0)


def _half_p2p(y):
    return 0.5 * (parabolic_peak(y, jnp.argmax(y)) - parabolic_peak(y, jnp.argmin(y)))


def closures(pen, cyclic=False):
    """Times a contact wall closes in the samples ``pen`` (``(N, walls)`` penetrations): a
    sample with positive penetration whose predecessor has none (``cyclic``: the samples go
    round a closed orbit, the last preceding the first)."""
    closed = pen > 0
    if cyclic:
        return jnp.sum(closed & ~jnp.roll(closed, 1, axis=0))
    return jnp.sum(closed[1:] & ~closed[:-1])


def has_rigid_walls(system):
    """Whether ``system`` has rigid impacts (an event-driven system with contact walls)."""
    return is_hybrid(system) and system.penetrations(system.rest_state()).shape[0] > 0


def contact_statistics(system, forcing, x0, s, n, cfg, n_cap=1, *, cyclic=True, counted=None):
    """Impacts per forcing period and the fraction of time a contact is closed over the
    ``n`` forcing periods from scaled state ``x0`` sampled as internal states ``s``: from
    the samples' penetrations (``cyclic``: around a closed orbit), or (rigid impacts)
    counted at the events (``counted``: ``(impacts, time closed [s])`` from the samples'
    own integration, else integrated again)."""
    pen = jax.vmap(system.penetrations)(s)                            # (N, walls)
    if pen.shape[1] == 0:
        zero = jnp.zeros((), s.dtype)
        return zero, zero
    if has_rigid_walls(system):
        T = 2 * jnp.pi / forcing.omega
        impacts, closed = (event_counts((system, forcing), x0, n * T, cfg.over_periods(n_cap))
                           if counted is None else counted)
        return (impacts / n).astype(s.dtype), closed / (n * T)
    closed = jnp.any(pen > 0, axis=1)
    return (closures(pen, cyclic=cyclic) / n).astype(s.dtype), jnp.mean(closed.astype(s.dtype))


def sample_orbit(system, forcing, x0, n, cfg, n_cap=1, *, with_end=False):
    """Internal states ``s`` at ``SAMPLES_PER_PERIOD · n_cap`` uniform times ``ts`` over one
    response period ``nT`` from scaled state ``x0``, and the integrator's status; with
    ``with_end``, also the scaled state at ``nT`` from the same integration (the period
    map, for the residual: the steps are the same, the samples are interpolated) and, for
    rigid walls, the impacts and time in contact counted at its events (else None)."""
    scale = state_scale(system, forcing)
    T = 2 * jnp.pi / forcing.omega
    N = SAMPLES_PER_PERIOD * n_cap
    ts = jnp.arange(N) * (n * T / N)
    if with_end:
        rigid = has_rigid_walls(system)
        out = integrate_flow((system, forcing), x0, n * T, jnp.append(ts, n * T),
                             cfg=cfg.over_periods(n_cap), counts=rigid)
        ys, st = out[:2]
        return ys[:-1] * scale, ts, st, ys[-1], (out[2] if rigid else None)
    ys, st = integrate_flow((system, forcing), x0, n * T, ts, cfg=cfg.over_periods(n_cap))
    return ys * scale, ts, st


def orbit_statistics(system, forcing, x0, n, cfg, n_cap=1):
    """Amplitudes over one response period ``nT`` starting from scaled state ``x0``
    (``n`` may be traced; ``n_cap`` is its static upper bound), the integrator's status, the
    largest stroke per absorber, the scaled state at ``nT`` and the internal states sampled
    (``sample_orbit``)."""
    s, ts, st, end, counted = sample_orbit(system, forcing, x0, n, cfg, n_cap, with_end=True)
    stats, stroke_max = sample_statistics(system, forcing, s, ts, x0, n, cfg, n_cap, counted)
    return stats, st, stroke_max, end, s


def sample_statistics(system, forcing, s, ts, x0=None, n=1, cfg=None, n_cap=1, counted=None):
    """The statistics of an orbit from its internal states ``s`` at uniform times ``ts``
    over one response period ``nT`` (amplitudes of the observable, outputs and strokes,
    contacts: see ``SteadyState``), and the largest stroke per absorber.  ``x0`` and
    ``cfg``: the scaled state at ``t = 0`` and the integrator, needed only to count rigid
    impacts at their events (unless ``counted`` gives them, see ``contact_statistics``)."""
    phase = jnp.exp(-1j * forcing.omega * ts)

    def stats_of(y):
        return (_half_p2p(y), jnp.sqrt(jnp.mean(y**2)), 2.0 * jnp.abs(jnp.mean(y * phase)))

    amp, rms, harm = stats_of(jax.vmap(system.observable)(s))
    d_amp, d_rms, d_harm = jax.vmap(stats_of, in_axes=1)(jax.vmap(system.outputs)(s))
    u = jax.vmap(system.strokes)(s)                                   # (N, absorbers)
    u_amp, u_rms, _ = jax.vmap(stats_of, in_axes=1)(u)
    most = (lambda a: jnp.max(a)) if u.shape[1] else (lambda a: jnp.zeros((), s.dtype))
    impacts, contact = contact_statistics(system, forcing, x0, s, n, cfg, n_cap,
                                          counted=counted)
    stats = dict(amplitude=amp, rms=rms, harmonic=harm, absorber_amplitude=most(u_amp),
                 absorber_rms=most(u_rms), impacts=impacts, contact_fraction=contact,
                 dof_amplitude=d_amp, dof_rms=d_rms, dof_harmonic=d_harm)
    return stats, jnp.max(jnp.abs(u), axis=0)


# The integration tolerance of a large state's monodromy (>= SENSITIVITY_STATES states)
# need not be tighter than this where its multipliers lie well inside the unit circle.
# Measured on the 44-state building of scripts/benchmark_structure.py (tangent-controlled
# steps, against rtol 1e-10): at 0.8-1.3 w1 the multipliers above 0.5 within 4e-6 at 1e-5
# (2.5e-7 at 1e-6, 1.1e-4 at 1e-4), in 300 steps (14 ms with unrolled stages) instead of
# 480 (21 ms); over the 256-point sweep the largest |multiplier| moved by at most 5.7e-5
# from its value at 1e-6.  (Steps controlled on the state alone at 1e-5 gave a spurious
# |mu| = 1.6e4: the tangent control is what keeps them right.)
FLOQUET_RTOL_COARSE = 1e-5
# ... and where that coarse monodromy has a multiplier within FLOQUET_MARGIN of the unit
# circle (where the stability label depends on it), it is recomputed at FLOQUET_RTOL: the
# six largest |multipliers| of 16 orbits of that building within 7.5e-7 of rtol 1e-9 (3.2e-8
# at 1e-7).  The margin is ~120x the coarse error measured on the linear 12-state building
# (every multiplier within 8e-5 of exp(lambda T), tests/systems/test_structural.py), ~170x that on
# the 44-state building's largest |multiplier|, and ~12x the relative error of the largest
# on a 12-state building carrying a hard impact damper (Kelvin-Voigt 1e6 N/m on 5 kg, 8
# impacts per period: |mu| = 1.3146, 1.1e-3 off at 1e-5, 3.7e-5 at 1e-6; on its orbits of
# 14-16 impacts, |mu| = 14-83, 8-17 % off at 1e-5: far from the circle, the label holds).
FLOQUET_RTOL = 1e-6
FLOQUET_MARGIN = 1e-2
# ... and that of a small state's (below SENSITIVITY_STATES) need not be tighter than this.
# Measured on the 256 orbits of the Table 1 sweep (scripts/benchmark_sweep.py) against
# tangent-controlled rtol 1e-12: every |multiplier| within 5.8e-8 at 1e-8 (1.9e-8 at 1e-9),
# for 0.19 s instead of 0.35 s (the label was ~27 % of that sweep); ForwardMode through
# state-controlled steps is 6.9e-5 off at 1e-9 (6.8e-7 at 1e-10).
FLOQUET_RTOL_SMALL = 1e-8


def floquet(system, forcing, x0, n, cfg, n_cap=None):
    """Floquet multipliers (eigenvalues of the monodromy matrix, by forward-mode AD); ``n``
    may be traced when ``n_cap`` (its static upper bound) is given."""
    return floquet_matrix(system, forcing, x0, n, cfg, n_cap=n_cap)[1]


def _at_least(cfg, tol):
    return dataclasses.replace(cfg, rtol=max(cfg.rtol, tol), atol=max(cfg.atol, tol))


def floquet_matrix(system, forcing, x0, n, cfg, n_cap=None, *, unroll=False):
    """``(M, multipliers)``: the monodromy matrix (scaled state) and its eigenvalues, which
    ``floquet`` reports.  Steps controlled on the tangents, tolerance no tighter than
    ``FLOQUET_RTOL_SMALL`` for a small state; for a large one ``FLOQUET_RTOL_COARSE``, and
    ``FLOQUET_RTOL`` where a multiplier lies within ``FLOQUET_MARGIN`` of the unit circle
    (decided on the eigenvalues, which are returned rather than computed again).
    ``unroll``: a large state's tangents integrated with unrolled stages (~30 % faster,
    twice the compilation: for the sweeps, which compute one monodromy per point)."""
    # the multipliers are not differentiated: no second derivatives of the flow when a
    # design or jax.grad differentiates the orbit
    system, forcing, x0 = _no_gradient((system, forcing, x0))
    # steps controlled on the tangents too: multipliers accurate to ~1e-6, not ~1e-3, across
    # stiff contacts (see accurate_tangents), so that stability labels near bifurcations hold
    cfg = accurate_tangents(cfg)
    if not large_state(system):
        M = monodromy(system, forcing, x0, n, _at_least(cfg, FLOQUET_RTOL_SMALL), n_cap=n_cap)
        return M, jnp.linalg.eigvals(M)
    fine = dataclasses.replace(_at_least(cfg, FLOQUET_RTOL), unroll_tangents=unroll)
    coarse = _at_least(fine, FLOQUET_RTOL_COARSE)
    factors = (coarse.rtol / fine.rtol, coarse.atol / fine.atol)
    if factors == (1.0, 1.0):
        M = monodromy(system, forcing, x0, n, fine, n_cap=n_cap)
        return M, jnp.linalg.eigvals(M)

    # a large state's monodromy costs ~num_states integrations: coarse first, refined only
    # where the label needs it; one compiled integration for both (its tolerances scaled by
    # traced factors), run one lane at a time under vmap, so that the refinement runs only
    # in the lanes that need it (vmapped, both passes would run in every lane)
    def two_tier(system, forcing, x0, n):
        def body(c):
            k = c[0]
            first = k == 0
            M = monodromy(system, forcing, x0, n, dataclasses.replace(
                fine, tol_factors=tuple(jnp.where(first, f, 1.0) for f in factors)),
                n_cap=n_cap)
            mu = jnp.linalg.eigvals(M)
            near = jnp.any(jnp.abs(jnp.abs(mu) - 1.0) < FLOQUET_MARGIN)
            return k + 1, (M, mu), ~(first & near)

        m = x0.shape[0]
        start = (jnp.zeros((m, m), x0.dtype), jnp.zeros((m,), jnp.result_type(x0.dtype, 1j)))
        return jax.lax.while_loop(lambda c: ~c[2], body,
                                  (jnp.asarray(0), start, jnp.asarray(False)))[1]

    return lane_by_lane(two_tier)(system, forcing, x0, n)


def monodromy(system, forcing, x0, n, cfg, n_cap=None):
    """``∂Φ_{nT}/∂x`` at the scaled state ``x0`` (forward mode)."""
    return jax.jacfwd(lambda x: period_map(system, forcing, x, n, cfg, n_cap=n_cap)[0])(x0)


def _no_gradient(tree):
    return jax.tree_util.tree_map(lambda a: jax.lax.stop_gradient(a) if eqx.is_array(a) else a,
                                  tree)


@eqx.filter_custom_jvp
def implicit_orbit(x, system, forcing, n, *, cfg, n_cap):
    """The fixed point ``x`` of the period-``n`` map (found by iteration, e.g. marching),
    returned as is, with the derivative of the implicit function theorem:
    ``dx = (I - ∂Φ/∂x)⁺ ∂Φ/∂θ dθ`` (minimum-norm, for a floating absorber's orbit family).
    Forward and reverse mode; the loop that found ``x`` is never differentiated."""
    return x


@implicit_orbit.def_jvp
def _implicit_orbit_jvp(primals, tangents, *, cfg, n_cap):
    x, system, forcing, n = primals
    _, t_sys, t_forc, _ = tangents
    if all(t is None for t in jax.tree_util.tree_leaves((t_sys, t_forc),
                                                         is_leaf=lambda a: a is None)):
        return x, None
    x = jax.lax.stop_gradient(x)
    vec, rebuild, t_vec = flat_inputs((system, forcing), (t_sys, t_forc))
    _, rhs = jax.jvp(lambda v: period_map(*rebuild(v), x, n, cfg, n_cap=n_cap)[0],
                     (vec,), (t_vec,))
    M = monodromy(*_no_gradient((system, forcing, x)), n, cfg, n_cap=n_cap)
    # (the flow's Jacobians are finite, see integrate_flow; the tangent stays linear in dθ, so that
    # reverse mode can transpose it: no test on its values)
    op = lx.MatrixLinearOperator(jnp.eye(x.shape[0]) - jnp.where(jnp.isfinite(M), M, 0.0))
    return x, lx.linear_solve(op, rhs, lx.SVD(), throw=False).value


def finish_orbit(system, forcing, x, n, cfg, status, residual, iterations, with_floquet=True,
            n_cap=1, multipliers=None, tol=None, section=None, closure=None):
    """The ``SteadyState`` of the scaled orbit state ``x`` (statistics, multipliers,
    stability); ``multipliers`` when the caller already has them (continuation: from the
    Jacobian of its last corrector step).  With ``tol`` (shooting), ``residual`` and
    ``status`` are not given but measured here: ``max |Φ_nT(x) - x|`` from the statistics'
    own integration, SUCCESS when within ``tol``.

    With ``section`` (continuation; ``n`` static, ``n_cap = n``): ``x`` lies on the Poincaré
    section ``section`` samples after ``t = 0`` (``forcing`` is the
    ``PhasedHarmonic`` of that section); the state reported is
    the orbit's at ``t = 0`` (a sample of the statistics' integration), and the result is
    ``(steady, Section)`` (``section_of``).

    ``closure=(weight, bound)`` (continuation): a solved ``status`` is kept only where the
    statistics' own integration returns to ``x`` within ``bound`` (``max |end - x|·weight``,
    ``weight`` the unknowns' scale over the flow's), else it is ``NO_CONVERGENCE``: the
    corrector's last Newton step, taken with the Jacobian at hand, can cross a grazing (a
    flight that now passes a wall), where the period map jumps and the point is no
    orbit."""
    scale = state_scale(system, forcing)
    stats, st2, stroke_max, end, samples = orbit_statistics(system, forcing, x, n, cfg, n_cap)
    if section is not None and samples.shape[0] != SAMPLES_PER_PERIOD * n:
        raise ValueError("finish_orbit(section=...) needs a static n equal to n_cap")
    if tol is not None:
        residual = jnp.max(jnp.abs(end - x))
        status = jnp.where(st2 != Status.SUCCESS, st2,
                           jnp.where(residual <= tol, Status.SUCCESS, Status.NO_CONVERGENCE))
    if closure is not None:
        weight, bound = closure
        opens = jnp.max(jnp.abs(end - x) * weight) > bound
        status = jnp.where((status == Status.SUCCESS) & opens, Status.NO_CONVERGENCE, status)
    if multipliers is not None:
        mult = multipliers.astype(complex)
    elif with_floquet:
        mult = floquet(system, forcing, x, n, cfg, n_cap=n_cap)
    else:
        mult = jnp.full((system.num_states,), jnp.nan + 0j)
    status = jnp.where(status == Status.SUCCESS, st2, status)
    at_zero = x * scale if section is None else samples[(-section) % samples.shape[0]]
    steady = steady_of(system, stats, stroke_max, at_zero, n, mult, status, residual,
                       iterations)
    if section is None:
        return steady
    approach = sampled_approach(system, forcing, samples, n) if has_rigid_walls(system) else None
    return steady, section_of(system, samples, section, at_zero, approach)


def orbit_map(system, forcing, x, n, cfg):
    """The period-``n`` map of a steady-state method: ``(Φ_nT(x), status)``, the scaled
    internal state after ``n`` forcing periods from the scaled internal state ``x`` at
    ``t = 0`` (``x`` as ``AbstractSteadyMethod.solve`` receives it: the internal state over
    ``state_scale``), integrated with the settings ``cfg`` the method was given (exact
    events and saltation included for hybrid systems), and the integrator's
    [`Status`][absorber_jax.Status].  Differentiable in ``x`` (its Jacobian is the
    monodromy matrix) and vmappable."""
    return period_map(system, forcing, x, n, cfg)


def orbit_result(system, forcing, x, n, cfg, *, tol, iterations, with_floquet=True):
    """The [`SteadyState`][absorber_jax.SteadyState] a steady-state method returns for the
    period-``n`` orbit through the scaled internal state ``x`` at ``t = 0``: its amplitudes,
    harmonics, impacts and strokes from one more integration over the orbit, its residual
    ``max |Φ_nT(x) - x|`` (scaled) from the same integration, ``SUCCESS`` where that is
    within ``tol`` (else ``NO_CONVERGENCE``, or the integrator's failure), its Floquet
    multipliers (``with_floquet``) and stability; ``iterations`` is reported as given."""
    return finish_orbit(system, forcing, x, n, cfg, None, None, iterations, with_floquet,
                        n_cap=n, tol=tol)


def steady_of(system, stats, stroke_max, at_zero, n, mult, status, residual, iterations):
    """The ``SteadyState`` of an orbit from its statistics (``sample_statistics``), its
    internal state at ``t = 0``, its Floquet multipliers and the solver's status: a point
    whose statistics are not finite is flagged ``NONFINITE``, and a failed point (or one
    whose multipliers are not known) is never called stable."""
    # an absorber floating without touching the walls: its free position and velocity give a
    # structural double multiplier 1 (a Jordan block, split by ~sqrt(rounding) numerically);
    # stability is judged on the other multipliers (2 per floating absorber set aside)
    pairs = system.floating_pairs(stroke_max)
    dist = jnp.abs(mult - 1.0)
    kth = jnp.sort(dist)[jnp.clip(2 * pairs - 1, 0, dist.shape[0] - 1)]
    structural = (pairs > 0) & (dist <= kth) & (dist < 1e-2)
    vals = jnp.concatenate([jnp.ravel(stats[k]) for k in stats])
    finite = jnp.all(jnp.isfinite(vals)) & jnp.all(jnp.isfinite(at_zero))
    status = jnp.where((status == Status.SUCCESS) & ~finite, Status.NONFINITE, status)
    stable = (jnp.all((jnp.abs(mult) <= 1.0 + 1e-6) | structural) & (status == Status.SUCCESS)
              & jnp.all(jnp.isfinite(mult)))
    return SteadyState(**stats, period_multiple=jnp.asarray(n),
                       state=system.to_public(at_zero), multipliers=mult, stable=stable,
                       status=status, residual=residual, iterations=jnp.asarray(iterations))


class Section(eqx.Module):
    """Where an orbit sampled from a Poincaré section lies against its contact walls
    (``section_of``): ``clearance`` at the section, ``best_clearance`` at the best
    sample and ``least_clearance`` at the worst (the least distance [m] to any wall,
    negative in contact, ``inf`` without walls), the ``best`` sample's index from ``t = 0``
    and its internal state, the orbit's internal state at ``t = 0``, and (rigid walls) the
    highest apex [m] of its free flights on the samples (``sampled_approach``; ``-inf``
    where none is sampled or the walls are compliant)."""

    clearance: jax.Array
    best_clearance: jax.Array
    least_clearance: jax.Array
    best: jax.Array
    best_state: jax.Array
    at_zero: jax.Array
    approach: jax.Array


def section_of(system, samples, section, at_zero, approach=None):
    """The ``Section`` of an orbit's internal ``samples`` taken from the section
    ``section`` samples after ``t = 0``.

    Shooting from a section where a stiff contact is closed is badly conditioned: the state
    there moves with the impact's timing, within the short contact, so Newton's basin
    shrinks to nothing (the Kelvin–Voigt 2e4 scene of scripts/benchmark_hard_contacts.py at
    28.50 rad/s, |μ| = 50: from a perturbation of 1e-3 of the orbit's scaled state, Newton
    diverges with the section in contact and converges quadratically (1e-1, 1e-4, 4e-7)
    where the absorber flies free).  The best sample is the one farthest from every wall."""
    pen = jax.vmap(system.penetrations)(samples)                      # (N, walls)
    if pen.shape[1] == 0:
        clear = jnp.full(samples.shape[:1], jnp.inf, samples.dtype)
    else:
        clear = -jnp.max(pen, axis=1)
    k = jnp.argmax(clear)
    approach = jnp.asarray(-jnp.inf, samples.dtype) if approach is None else approach
    return Section(clearance=clear[0], best_clearance=clear[k], least_clearance=jnp.min(clear),
                   best=(section + k) % samples.shape[0], best_state=samples[k],
                   at_zero=at_zero, approach=approach)


def wall_kinematics(system, forcing, ts, states):
    """Each wall's penetration [m], its rate [m/s] and its acceleration [m/s²] at the
    internal ``states`` at times ``ts`` [s] of ``forcing``, ``(N, walls)`` each: the rates
    those of free flight (every contact open)."""
    system = system.prepared()
    free = jnp.zeros_like(system.mode_of(0.0, system.rest_state(), forcing))

    def kinematics(t, s):
        def rate(t, s):
            v = system.mode_rate(t, s, forcing, free)
            return jax.jvp(system.penetrations, (s,), (v,))[1]

        v = system.mode_rate(t, s, forcing, free)
        r, a = jax.jvp(rate, (t, s), (jnp.ones_like(t), v))
        return system.penetrations(s), r, a

    return jax.vmap(kinematics)(ts, states)


def free_flight_apexes(pen, rate, acc, dt, length, speed, xp=np):
    """The apexes of free flight towards a wall among sampled penetrations ``pen``, rates
    ``rate`` and accelerations ``acc`` ``(N + 1, walls)`` a time ``dt`` apart (numpy, or
    ``xp=jax.numpy`` inside a compiled function): where the rate turns from approaching to
    leaving *smoothly* (the change over the interval the trapezoidal rule of the
    accelerations, within a tenth: an impact reverses the rate at once), refined by the
    cubic Hermite interpolant of the interval (its error is of order ``dt⁴`` times the
    penetration's fourth derivative / 384: about 1e-9 of a harmonic motion's amplitude at 256
    samples a period).  Intervals that touch a hold (at the wall, at rest relative to it;
    ``length`` [m] and ``speed`` [m/s] scale that test) are not apexes.  Returns
    ``(is_apex, heights, times)`` per interval and wall ``(N, walls)``: the penetration [m]
    at the apex (at least the interval's ends) and its time [s] from the first sample."""
    rest = (xp.abs(rate) <= 1e-12 * speed) & (xp.abs(pen) <= 1e-10 * length)
    # a hold lasts: a sample at rest on the wall is held where a neighbour is too (a grazing
    # flight touches the wall at one instant, and its apex may fall on a sample)
    none = xp.zeros_like(rest[:1])
    held = rest & (xp.concatenate([none, rest[:-1]]) | xp.concatenate([rest[1:], none]))
    p0, p1, r0, r1 = pen[:-1], pen[1:], rate[:-1] * dt, rate[1:] * dt
    smooth = xp.abs(r1 - r0 - 0.5 * (acc[:-1] + acc[1:]) * dt**2) <= 0.1 * (r0 - r1)
    turn = (r0 > 0) & (r1 <= 0) & smooth & ~held[:-1] & ~held[1:]
    with np.errstate(divide="ignore", invalid="ignore"):
        tau, h = hermite_apex(p0, p1, r0, r1, xp=xp)
    start = xp.arange(pen.shape[0] - 1)[:, None]
    return turn, xp.maximum(h, xp.maximum(p0, p1)), (start + tau) * dt


def sampled_approach(system, forcing, samples, n):
    """The highest apex [m] of the free flights of the closed orbit sampled as internal
    ``samples`` over ``n`` periods of ``forcing`` from its ``t = 0`` (``free_flight_apexes``
    on the samples, the first again closing the loop), ``-inf`` where none is sampled:
    negative while every flight stays clear of the walls."""
    N = samples.shape[0]
    dt = n * forcing.period / N
    closed = jnp.concatenate([samples, samples[:1]])
    pen, rate, acc = wall_kinematics(system, forcing, jnp.arange(N + 1) * dt, closed)
    length = jnp.max(jnp.abs(state_scale(system, forcing)))
    turn, heights, _ = free_flight_apexes(pen, rate, acc, dt, length, length * forcing.omega,
                                          xp=jnp)
    return jnp.max(jnp.where(turn, heights, -jnp.inf))
