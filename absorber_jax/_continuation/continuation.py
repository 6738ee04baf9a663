"""Pseudo-arclength continuation of periodic orbits, with bifurcation detection and location
and branch switching at period doublings.

Unknowns ``z = (x, p)``: the orbit's internal state on its Poincaré section (``t = 0 mod nT``
at first, see Section below) divided by a state scale (``system.state_scale``, rescaled to the
orbit as it grows) and the continuation parameter divided by ``|its start value|`` (by
the bounds' larger magnitude in ``band_continuation``).  The residual is the shooting
residual of the steady-state layer, ``Φ_{nT}(x; p) - x``
(``_integration.flow.period_map``, the same flow, tolerances and derivatives as
``Shooting``); its Jacobian ``[M - I, ∂Φ/∂p]`` comes from one forward-mode pass over
``n + 1`` directions.

- **Predictor**: ``z + h t`` along the unit tangent ``t`` (null vector of the Jacobian,
  oriented to continue the previous one).
- **Corrector**: Newton on ``[Φ - x; t·(z - z_pred)] = 0`` (minimum-norm least-squares
  steps: a floating absorber's orbit family leaves the bordered matrix singular), until the
  scaled residual is below ``tol``, then one more step with the same Jacobian; stopped
  early where the residual has not halved over the last two steps.  The Jacobian of the last
  corrector iterate gives the next tangent and the Floquet multipliers (eigenvalues of
  ``M``) for free; the point's statistics and stability label are the point solve's
  (``_periodic.orbit.finish_orbit``).
- **Section**: the orbit's state is taken on a Poincaré section where the absorbers fly
  free, moved along the branch when a contact comes near it (``_Driver.resection``);
  the states reported are at ``t = 0``.
- **Step control**: the step grows after quick corrections, shrinks after slow ones, and is
  halved when the corrector fails or the tangent turns by more than ``max_angle``.
- **Bifurcations** between two accepted points, by sign changes of test functions: fold
  (the tangent's parameter component), period doubling (``Π(μ_i + 1)``: a real multiplier
  through -1), Neimark–Sacker (a complex pair crossing the unit circle).  Each is located by
  the Illinois variant of regula falsi (M. Dowell, P. Jarratt, *BIT* 11 (1971) 168) on the
  arclength, every evaluation a corrector solve on the hyperplane through the predicted point.
- **Branch switching** at a period doubling: the period-``2n`` branch starts from the
  bifurcating orbit pushed along the eigenvector of the multiplier -1, on the hyperplane
  normal to it, and is followed until it leaves the bounds or rejoins the period-``n``
  branch (at the other end of a flip window).

``band_continuation`` follows half-branches from several start values together, the
corrector solves of each round batched in one vmapped call (a generator per half-branch
yields its corrector requests, ``_follow``).

References: E. L. Allgower & K. Georg, *Introduction to Numerical Continuation Methods*
(SIAM, 2003), ch. 2 and 6; Yu. A. Kuznetsov, *Elements of Applied Bifurcation Theory*
(Springer, 2004), ch. 10 (test functions); R. Seydel, *Practical Bifurcation and Stability
Analysis* (Springer, 2010), ch. 7 (periodic orbits by shooting).
"""

from __future__ import annotations

import dataclasses
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from .._core.checks import check_scalar, check_state, require_x64
from .._core.legacy import moved, no_more
from .._core.status import Status
from .._core.units import signals_of
from .._integration.flow import (
    state_scale,
)
from .._integration.settings import integrator_from
from .._periodic.harmonic import HarmonicBalance
from .._periodic.shooting import Shooting
from .._periodic.steady import check_system_and_forcing, steady_state
from .._systems.base import AbstractSystem, is_hybrid
from .._systems.forcing import AbstractPeriodicForcing
from .._systems.params import replace_params, resolve
from .balance import _BalanceDriver, _BalanceProblem
from .branch import Bifurcation, Branch
from .constants import FORCING_PARAMETERS, GAP, START_SCALES
from .driver import (
    _axis,
    _bar,
    _bifurcation,
    _branch,
    _close_returns,
    _config,
    _Driver,
    _first_orbit,
    _follow,
    _inside,
    _run,
    _run_batched,
    _shared,
    _switch,
)
from .method import PseudoArclength
from .problem import _get_value, _Problem, _set_value


def continuation(system: AbstractSystem, forcing: AbstractPeriodicForcing,
                 parameter: str = "omega", *, bounds, method: PseudoArclength | None = None,
                 n: int = 1, direction: str = "up", start=None, guess=None, integrator=None,
                 orbit=None, progress=False, **legacy) -> Branch:
    """Follow a branch of period-``n`` orbits of ``system`` under ``forcing`` in
    ``parameter`` by pseudo-arclength continuation (see the module docstring), through
    folds, with the bifurcations on it detected and located.

    **Arguments**

    - ``forcing``: any periodic forcing (``Harmonic``, ``MultiHarmonic``,
      ``PeriodicForcing`` ...).
    - ``parameter``: ``"omega"`` (the forcing's fundamental [rad/s], through
      ``forcing.with_omega``), ``"amplitude"`` (F0 [N], through ``forcing.with_amplitude``)
      or any name of ``system.parameter_names()`` (``k1``, ``gap``, ``N``, ``tmd1.k`` ...).
    - ``bounds``: ``(lo, hi)``: the branch ends where the parameter leaves them (the last
      point lands on the bound); the start value must lie inside.
    - ``method``: a ``PseudoArclength`` with the step, corrector and location options
      (``locate=False``: bifurcations reported at the nearer branch point, not located).
    - ``n``: period multiple of the orbits followed.
    - ``direction``: ``"up"`` or ``"down"``: the parameter's direction at the start.
    - ``start``: None (the first orbit is solved at the forcing's and system's current
      parameter value by Newton shooting from ``guess``, default the linear response; where
      that fails, from the closest returns of a trajectory marched from it, then by
      ``steady_state`` with its retries), or a period-doubling
      ``Bifurcation`` of a branch of this system in this parameter: the period-``2n``
      branch born there is followed (branch switching); ``direction`` is then ignored.
    - ``integrator``: an ``Integrator`` (default: the periodic tolerances, rtol = atol =
      1e-9 on the scaled state; the solver is chosen at the lowest frequency of the bounds
      when continuing in ``omega``).
    - ``progress``: a tqdm bar over the branch points.

    **Returns** a ``Branch``.

    ```python
    import absorber_jax as aj
    system, forcing = aj.presets.impact("kelvin_voigt", omega=40.0)
    br = aj.continuation(system, forcing, "omega", bounds=(30.0, 70.0))
    br.values, br.amplitude, br.stable, [(b.kind, b.value) for b in br.bifurcations]
    ```
    """
    method, lo, hi = _check_common(system, forcing, parameter, bounds, method, n, "continuation",
                                   legacy)
    locate = method.locate
    if direction not in ("up", "down"):
        raise ValueError(f"direction must be 'up' or 'down', got {direction!r}")
    if start is not None:
        if not isinstance(start, Bifurcation) or start.kind != "period_doubling":
            raise ValueError("start must be a period-doubling Bifurcation of a Branch, got "
                             f"{start!r}")
        system, forcing = _set_value(system, forcing, parameter, float(start.value))
        n = 2 * start.period_multiple
    value0 = _get_value(system, forcing, parameter)
    if not lo <= value0 <= hi:
        raise ValueError(f"the start value of {parameter!r} ({value0:g}) must lie inside "
                         f"bounds ({lo:g}, {hi:g})")
    check_state("guess", guess, system.num_states)

    integ = integrator_from(integrator, "periodic", "continuation", legacy)
    no_more("continuation", legacy)
    solver, rtol, atol, max_steps = integ.solver, integ.rtol, integ.atol, integ.max_steps
    cfg = _config(system, forcing, parameter, lo, solver, rtol, atol, max_steps)
    s0 = state_scale(system, forcing)
    pscale = abs(value0) if value0 != 0 else max(abs(lo), abs(hi))
    if orbit is not None:
        _check_balance(system, orbit, n, start)
        g = None if guess is None else system.to_internal(jnp.asarray(guess, dtype=float))
        prob, first = _balance_start(system, forcing, parameter, orbit, cfg, method, value0,
                                     pscale, direction, g)
        drv = _BalanceDriver(prob, method, (lo, hi))
        with _bar(method.max_points, parameter, progress) as bar:
            points, bifs, termination = _run(_follow(drv, first, None, locate, bar))
        return _finish(_branch(points, bifs, termination, drv, value0, system))
    prob = _Problem(system=system, forcing=forcing, s0=s0, pscale=jnp.asarray(pscale),
                    cfg=cfg, parameter=parameter, n=n)
    drv = _Driver(prob, method, (lo, hi))
    p0 = value0 / pscale

    if start is None:
        shooting = Shooting(n=n, tol=method.tol)
        g = (shooting.initial_state(system, forcing) if guess is None
             else system.to_internal(jnp.asarray(guess, dtype=float)))
        # the first orbit: the branch's own corrector at the start value (Newton shooting
        # from the guess, compiled once for the whole branch), then from the closest
        # returns of a marched trajectory, and steady_state with its retries (marching,
        # then shooting again) only where both fail: its program costs a compilation of its
        # own (~20 s on the hard-contact scenes of scripts/benchmark_hard_contacts.py; the
        # rigid one's first call from 20 rad/s, a new process, warm persistent cache:
        # 31 s with it, 13 s with the close returns)
        e = _axis(prob, direction)
        z_guess = np.append(np.asarray(g) / np.asarray(s0), p0)
        first = drv.solve(z_guess, e, True)
        seeds = _close_returns([drv], [z_guess])[0] if not first["ok"] else []
        if seeds:
            # as band_continuation's starts: Newton from the closest returns of a marched
            # trajectory (a chaotic motion passes near the unstable orbits; a settling one
            # ends on its orbit), the march a smaller program than steady_state's
            point = _run(_first_orbit(drv, seeds, e))
            first = point if point["ok"] else first
        if not first["ok"]:
            ss = steady_state(system, forcing, method=shooting, guess=guess, integrator=integ)
            x0 = np.asarray(system.to_internal(ss.state)) / np.asarray(s0)
            if int(ss.status) != Status.SUCCESS:
                first = dict(ss=jax.tree_util.tree_map(np.asarray, ss), ok=False)
            else:
                first = drv.solve(np.append(x0, p0), e, True)
        rejoin = None
    else:
        first, rejoin = _switch(drv, system, forcing, start, s0, p0, cfg, parameter, pscale)

    with _bar(method.max_points, parameter, progress) as bar:
        points, bifs, termination = _run(_follow(drv, first, rejoin, locate, bar))
    return _finish(_branch(points, bifs, termination, drv, value0, system))


def _finish(branch):
    """``branch``, with a warning where it did not go where it was asked to."""
    if not branch.reached:
        warnings.warn(f"continuation: {branch.ending()}", RuntimeWarning, stacklevel=3)
    return branch


def _check_balance(system, orbit, n, start):
    """Checks of ``continuation(orbit=...)``."""
    if not isinstance(orbit, HarmonicBalance):
        raise ValueError(f"continuation.orbit must be None (shooting) or an "
                         f"aj.HarmonicBalance(...), got {type(orbit).__name__}")
    if n != 1 or start is not None:
        raise ValueError("continuation with orbit=HarmonicBalance follows period-1 orbits "
                         "from the forcing's values: give n=1 and no start (branch switching "
                         "at a period doubling needs shooting)")
    if is_hybrid(system):
        raise ValueError("continuation with orbit=HarmonicBalance needs a vector field to "
                         "balance: the exact event-driven laws have none; use shooting "
                         "(orbit=None) or a compliant or smoothed law")


def band_continuation(system: AbstractSystem, forcing: AbstractPeriodicForcing,
                      parameter: str = "omega", *,
                      bounds, starts=8, method: PseudoArclength | None = None, n: int = 1,
                      fill: int = 2, integrator=None, orbit=None, progress=False,
                      **legacy) -> tuple:
    """Cover a parameter band with branches of period-``n`` orbits followed from several
    start values at once: every start up and down, each half-branch bounded by the
    neighbouring start values (so every cell between two starts is followed from both
    ends), all half-branches advanced together, their corrector solves batched in one
    vmapped call per step.

    Where the branch through the band snakes through many folds (the hard impact absorber
    of ``scripts/benchmark_hard_contacts.py``: 1200 points from 20 rad/s reach only 29.3
    rad/s) one branch cannot cover the band in reasonable time, and it misses the branches
    and isolas it is not connected to; the starts find those, and the batch runs many small
    orbits for little more than the price of one (that scene: 8 Jacobians in 0.059 s against
    0.031 s for one).

    **Arguments** as ``continuation`` (``bounds``, ``method``, ``n``, ``integrator``,
    ``orbit``, ``progress``), and

    - ``starts``: the number of start values (the centres of that many equal cells of the
      bounds) or the start values themselves (inside the bounds).  The first orbit at each
      is Newton shooting from the linear response (scaled by ``START_SCALES`` in turn where
      that fails), then from the closest returns of a trajectory marched from it
      (``CLOSE_RETURNS`` of ``CLOSE_RETURN_PERIODS`` periods: a chaotic motion passes near
      the unstable periodic orbits embedded in it); a start where all fail gives two
      branches that ended ``"start_failed"`` (a fill pass's start, none, where its march
      failed), and its neighbours follow its cells.
    - ``fill``: passes, after the starts' branches end, that start new ones in the parts of
      the band none reached (wider than ``GAP`` of it): as many starts as the batch holds
      (one per start of the band), spread over those parts by width, each followed within
      its part, the first orbit from the closest returns of a marched trajectory at once:
      branches that fold back on both sides of a part leave it uncovered (the Kelvin–Voigt
      scene: the branches from 27.8 and 30.9 rad/s turn at folds at 28.35 and 29.25 rad/s;
      2 passes cover both hard-contact scenes' 20–45 rad/s whole).

    The bifurcations the half-branches pass are located together, in batches: those of
    each pass in the next fill pass's batch (in the lanes its half-branches leave free),
    those of the last pass after it.

    With ``orbit=HarmonicBalance(...)`` the half-branches are balanced orbits (period 1,
    as ``continuation``), followed one after the other (one compiled corrector serves them
    all), each start's first orbit balanced from the linear response there, the fill
    passes' likewise.

    **Returns** a tuple of ``Branch`` es, two per start (down, then up), the fill
    passes' after the starts' (two per fill start that had a first guess).
    """
    method, lo, hi = _check_common(system, forcing, parameter, bounds, method, n,
                                   "band_continuation", legacy)
    locate = method.locate
    if isinstance(starts, int) and not isinstance(starts, bool):
        if starts < 1:
            raise ValueError(f"starts must be a positive integer or values, got {starts!r}")
        values = lo + (np.arange(starts) + 0.5) * (hi - lo) / starts
    else:
        try:
            values = np.sort(np.asarray(starts, dtype=float).ravel())
        except (TypeError, ValueError):
            raise ValueError(f"starts must be a positive integer or values, got {starts!r}") \
                from None
        if values.size < 1 or not np.all((values >= lo) & (values <= hi)):
            raise ValueError(f"starts must lie inside bounds ({lo:g}, {hi:g}), got {starts!r}")
    if not isinstance(fill, int) or isinstance(fill, bool) or fill < 0:
        raise ValueError(f"fill must be a non-negative integer, got {fill!r}")
    integ = integrator_from(integrator, "periodic", "band_continuation", legacy)
    no_more("band_continuation", legacy)
    solver, rtol, atol, max_steps = integ.solver, integ.rtol, integ.atol, integ.max_steps
    cfg = _config(system, forcing, parameter, lo, solver, rtol, atol, max_steps)
    if orbit is not None:
        _check_balance(system, orbit, n, None)
        count = len(values)                 # starts per fill pass, as the starts'
        with _bar(method.max_points * 2 * count, parameter, progress) as bar:
            out = _balance_pass(system, forcing, parameter, orbit, cfg, method, values,
                                _cells(values, lo, hi), bar)
            for _ in range(fill):
                values, limits = _fill_starts(_gaps(out, lo, hi), count)
                if not values.size:
                    break
                bar.total += method.max_points * 2 * values.size
                out += _balance_pass(system, forcing, parameter, orbit, cfg, method, values,
                                     limits, bar)
        return _band_result(out, parameter, lo, hi, system)
    base = _Problem(system=system, forcing=forcing, s0=state_scale(system, forcing),
                    pscale=jnp.asarray(max(abs(lo), abs(hi))), cfg=cfg, parameter=parameter,
                    n=n)
    lanes = 2 * len(values)                 # the batch of the half-branches, for every phase
    with _bar(method.max_points * lanes, parameter, progress) as bar:
        out, _ = _band_pass(base, method, values, [(lo, hi)] * len(values), lanes, locate,
                            bar)
        done = 0                            # out[:done]: their bifurcations handed out
        for _ in range(fill):
            values, limits = _fill_starts(_gaps(out, lo, hi), lanes // 2)
            if not values.size:
                break
            bar.total += method.max_points * 2 * values.size
            # the bifurcations not handed out yet (the last pass's) are located in the batch
            # of this one, in the lanes its half-branches leave free (most of its rounds
            # hold the few that snake through folds)
            gens, finish = _located_later(out, done, base, method, lanes)
            done = len(out)
            more, found = _band_pass(base, method, values, limits, lanes, locate, bar,
                                     linear=False, extra=gens)
            finish(found)
            out += more
        gens, finish = _located_later(out, done, base, method, lanes)
        finish(_run_batched(gens, base, method, lanes))
    return _band_result(out, parameter, lo, hi, system)


def _located_later(out, start, base, method, lanes):
    """The bifurcations the half-branches ``out[start:]`` deferred, located together:
    ``(generators, finish)``, the corrector requests' generators of those to locate (one
    location for a bifurcation two half-branches saw: ``_shared``; each a few corrector
    solves in turn, so a batch of them, the Hertz band's main pass took 91 rounds of its
    batch, 37 bifurcations of 1-19 solves each) and ``finish(results)``, which puts their
    results (in the generators' order) in their branches' places, locating on its own
    each whose shared location lies off its own bracket (another bifurcation of the same
    kind, or a bracket too curved to tell) or failed."""
    todo = [(i, j) for i, ((_, bifs, _), _, _) in enumerate(out) if i >= start
            for j, b in enumerate(bifs) if isinstance(b, tuple)]
    args = [out[i][0][1][j] for i, j in todo]
    first, brackets = _shared(args, [i for i, _ in todo])
    own = [k for k, f in enumerate(first) if f == k]

    def finish(results):
        found = dict(zip(own, results))
        again = [k for k, f in enumerate(first) if f != k
                 and not _inside(brackets[k], found[f])]
        found.update(zip(again, _run_batched([_bifurcation(*args[k]) for k in again], base,
                                             method, lanes)))
        for k, (i, j) in enumerate(todo):
            # a location taken from the other sighting cost this one no solve
            b, spent = (found[k], found[k].evaluations) if k in found else (found[first[k]], 0)
            out[i][0][1][j] = dataclasses.replace(b, index=args[k][4], evaluations=spent)

    return [_bifurcation(*args[k]) for k in own], finish


def _band_result(out, parameter, lo, hi, system):
    """The ``Branch`` es of the half-branches ``out``, with a warning naming the parts of
    ``(lo, hi)`` none reached."""
    missed = _gaps(out, lo, hi)
    if missed:
        parts = ", ".join(f"{a:.6g}-{b:.6g}" for a, b in sorted(missed))
        warnings.warn(f"band_continuation: no branch reached {parameter} in {parts}; try: "
                      f"more starts or fill passes, or aj.attractors there (the response "
                      f"may not be periodic)", RuntimeWarning, stacklevel=3)
    signals = signals_of(system)
    return tuple(_branch(*r, drv, v, system, signals) for r, drv, v in out)


def _start_cells(values, limits, live):
    """Per start value, its two half-branches' ``(sign, cell)``: down (``-1``) and up, each
    bounded by the nearest start with a first orbit (``live`` indices; every cell between
    two of them is then followed from both ends, and a start without one leaves its cells
    to its neighbours) and by the start's ``limits``."""
    cells = []
    for i, (v, (a, b)) in enumerate(zip(values, limits)):
        below, above = values[live[live < i]], values[live[live > i]]
        cells.append(((-1.0, (max(a, below[-1]) if below.size else a, v)),
                      (1.0, (v, min(b, above[0]) if above.size else b))))
    return cells


def _cells(values, lo, hi):
    """Each start's limits: the neighbouring start values (the bounds at the ends)."""
    edges = np.concatenate([[lo], values, [hi]])
    return [(float(edges[i]), float(edges[i + 2])) for i in range(len(values))]


def _balance_start(system, forcing, parameter, orbit, cfg, method, value, pscale, direction,
                   guess=None):
    """The balance problem of a branch started at ``value`` and its first orbit there
    (balanced from ``guess``, an internal state, or the linear response), its tangent
    along ``direction``."""
    sysv, forcv = _set_value(system, forcing, parameter, float(value))
    s0 = state_scale(sysv, forcv)
    prob = _BalanceProblem(system=system, forcing=forcing, s0=s0, pscale=jnp.asarray(pscale),
                           balance=orbit, cfg=cfg, parameter=parameter)
    g = sysv.linear_guess(forcv) if guess is None else guess
    first = _BalanceDriver(prob, method, (value, value)).first(
        np.asarray(g) / np.asarray(s0), float(value) / pscale, direction, cfg)
    return prob, first


def _balance_pass(system, forcing, parameter, orbit, cfg, method, values, limits, bar):
    """Half-branches of balanced orbits from the start ``values`` (each start's first orbit
    balanced once, then followed down and up within ``limits[i]``: a branch that turns at a
    fold inside them follows the orbits beyond it), one after the other, listed as
    ``_band_pass`` lists its half-branches."""
    out = []
    for v, lim in zip(values, limits):
        pscale = abs(float(v)) if v != 0 else max(abs(lim[0]), abs(lim[1]))
        prob, first = _balance_start(system, forcing, parameter, orbit, cfg, method, v,
                                     pscale, "up")
        for sign in (-1.0, 1.0):
            drv = _BalanceDriver(prob, method, lim)
            gen = _follow(drv, dict(first, t=sign * first["t"]), None, method.locate, bar)
            out.append((_run(gen), drv, float(v)))
    return out


def _band_pass(base, method, values, limits, lanes, locate, bar, linear=True, extra=()):
    """Half-branches from the start ``values`` (start ``i`` followed within ``limits[i]``),
    all together; returns ``[(result, driver, start value)]``, two per start (down, up),
    and the results of the generators ``extra`` (other corrector requests, served in the
    lanes the half-branches leave free: after them in the batch).  ``linear``: first
    guesses from the scaled linear response before the close returns
    (the fill passes go to the close returns at once: their starts lie where the branches
    snake, near a resonance, where Newton from the linear response fails, and the failures
    cost the most: the Hertz band's fill passes spent 30 of 93 s on them); a start with no
    first guess at all (its march failed) is left out."""
    pscale = float(base.pscale)
    starters, guesses = [], []
    for v in values:
        sysv, forcv = _set_value(base.system, base.forcing, base.parameter, float(v))
        prob = dataclasses.replace(base, s0=state_scale(sysv, forcv))
        x0 = np.asarray(sysv.linear_guess(forcv)) / np.asarray(prob.s0)
        starters.append(_Driver(prob, method, (float(v), float(v))))
        guesses.append([np.append(f * x0, v / pscale) for f in START_SCALES])
    up = _axis(base, "up")
    # the first orbit at every start, all starts together: Newton from the scaled linear
    # responses, then, where none converged, from the closest returns of a marched
    # trajectory (orbits near an unstable period-n orbit pass close to it again n periods
    # later: the Kelvin–Voigt scene of scripts/benchmark_hard_contacts.py has no period-1
    # orbit near its linear response at 30.9 rad/s, where the motion is chaotic)
    firsts = [None] * len(values)
    if linear:
        firsts = _run_batched([_first_orbit(d, g, up) for d, g in zip(starters, guesses)],
                              base, method, lanes)
    missing = [i for i, f in enumerate(firsts) if f is None or not f["ok"]]
    if missing:
        seeds = _close_returns([starters[i] for i in missing], [guesses[i][0] for i in missing],
                               lanes=max(lanes // 2, len(missing)))
        seeded = [(i, g) for i, g in zip(missing, seeds) if g]
        again = _run_batched([_first_orbit(starters[i], g, up) for i, g in seeded], base,
                             method, lanes)
        for (i, _), f in zip(seeded, again):
            firsts[i] = f
    keep = [i for i, f in enumerate(firsts) if f is not None]
    values, starters, firsts = values[keep], [starters[i] for i in keep], [firsts[i] for i in keep]
    limits = [limits[i] for i in keep]
    live = np.flatnonzero([f["ok"] for f in firsts])
    drivers, gens = [], []
    for d, first, cells in zip(starters, firsts, _start_cells(values, limits, live)):
        for sign, cell in cells:
            drv = _Driver(d.prob, method, cell)
            drivers.append(drv)
            gens.append(_follow(drv, dict(first, t=sign * first["t"]), None, locate, bar,
                                defer=True))
    results = _run_batched(gens + list(extra), base, method, lanes)
    return ([(r, drv, float(v)) for r, drv, v in zip(results, drivers, np.repeat(values, 2))],
            results[len(gens):])


def _fill_starts(gaps, count):
    """Start values for a fill pass: ``count`` of them (as many as the compiled batch holds,
    two half-branches each) spread over the ``gaps`` in proportion to their widths, at
    least one in each of the ``count`` widest, each at the centre of an equal part of its
    gap; returns ``(values, limits)``, the limits of each start its gap.

    Several starts in a gap rather than one at its centre: where the branches snake, a
    branch from one start turns at folds inside the gap and leaves parts of it on both
    sides, and Newton from the marched trajectory's close returns fails at some values and
    not at others nearby (the Hertz scene of scripts/benchmark_hard_contacts.py, 8 values
    over 28.30-29.35 rad/s: 4 of 8 first orbits found)."""
    gaps = gaps[:count]
    if not gaps:
        return np.zeros(0), []
    widths = np.array([g1 - g0 for g0, g1 in gaps])
    k = np.ones(len(gaps), int)
    for _ in range(count - len(gaps)):          # the next start to the gap whose parts
        k[np.argmax(widths / k)] += 1           # are widest
    values = [g0 + (m + 0.5) * (g1 - g0) / ki for (g0, g1), ki in zip(gaps, k)
              for m in range(ki)]
    limits = [g for g, ki in zip(gaps, k) for _ in range(ki)]
    order = np.argsort(values)
    return np.asarray(values)[order], [limits[i] for i in order]


def _gaps(out, lo, hi):
    """The parts of ``(lo, hi)`` that no converged point of the half-branches ``out`` (as
    ``_band_pass`` lists them) reached, wider than ``GAP`` of the band, widest first."""
    spans = sorted((min(v), max(v)) for v in
                   ([q["z"][-1] * float(drv.prob.pscale) for q in pts if q["ok"]]
                    for (pts, _, _), drv, _ in out) if v)
    gaps, reach = [], lo
    for a, b in spans:
        if a > reach:
            gaps.append((reach, a))
        reach = max(reach, b)
    gaps.append((reach, hi))
    return sorted((g for g in gaps if g[1] - g[0] > GAP * (hi - lo)),
                  key=lambda g: g[0] - g[1])


def _check_common(system, forcing, parameter, bounds, method, n, where, legacy):
    """Checks shared by the continuation entry points; returns ``(method, lo, hi)``, the
    deprecated ``locate`` keyword moved from ``legacy`` into the method."""
    require_x64(where)
    check_system_and_forcing(system, forcing, where)
    method = PseudoArclength() if method is None else method
    if not isinstance(method, PseudoArclength):
        raise ValueError(f"method must be a PseudoArclength(...), got {method!r}")
    if "locate" in legacy:
        given = {"locate": bool(legacy.pop("locate"))}
        moved(where, given, "method=aj.PseudoArclength({})")
        method = dataclasses.replace(method, **given)
    if not isinstance(parameter, str):
        raise ValueError(f"parameter must be a name, got {parameter!r}")
    if parameter not in FORCING_PARAMETERS:
        resolve(system, parameter)
    if not isinstance(n, int) or not 1 <= n <= 64:
        raise ValueError(f"n must be an integer in [1, 64], got {n!r}")
    try:
        lo, hi = (float(b) for b in bounds)
    except (TypeError, ValueError):
        raise ValueError(f"bounds must be (lo, hi), got {bounds!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ValueError(f"bounds must be finite with lo < hi, got {bounds!r}")
    for b in (lo, hi):                      # both ends must be valid parameter values
        if parameter == "omega":
            check_scalar(where, "bounds (omega)", b, lo=0.0, lo_open=True)
        elif parameter == "amplitude":
            check_scalar(where, "bounds (amplitude)", b, lo=0.0)
        else:
            replace_params(system, {parameter: b}, check=True)
    return method, lo, hi
