"""Gradient-based absorber design: differentiable band objectives and ``tune``.

Gradients of steady-state amplitudes go through the periodic-orbit solve implicitly: Newton
shooting solves ``R(x, θ) = Φ_T(x; θ) - x = 0``, and optimistix's implicit adjoint gives
``dx/dθ = -(∂R/∂x)⁺ ∂R/∂θ`` (a minimum-norm solve, so a floating absorber's free position
does not spoil it); the amplitude then differentiates through one period of the orbit.
Nothing backpropagates through the transient.  The derivatives are forward-mode
(``jax.jacfwd``): a design has a handful of parameters, and diffrax's ``ForwardMode`` makes
the tangent integrations ride along with the orbit's own.

Objectives over a frequency band ``ω_1..ω_F`` of primary amplitudes ``a_i``:

- ``"peak"``: the smooth maximum ``τ log Σ exp(a_i/τ) - τ log F`` with ``τ = softness·max a``
  (``softness`` 2e-3 by default).  It lies within ``[max - τ log F, max]``: its bias against
  the true maximum is at most 0.83 % for 64 frequencies and is returned as ``peak_bias`` in
  the history;
- ``"mean_square"``: ``mean(a_i²)``;
- ``"amplitude"``: the amplitude at a single frequency (a band of one point).

Where the branch the guess follows changes (an orbit appears or disappears, the period
multiple changes), the steady state is not a smooth function of the parameters: points
whose status or period multiple changed, or that are unstable, are reported in
``history["nonsmooth"]``, and the gradient there is only one-sided.
"""

from __future__ import annotations

import math
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.checks import check_scalar, require_x64
from .._core.devices import by_parts, put
from .._core.legacy import moved, no_more
from .._core.status import Status
from .._integration.settings import Integrator, integrator_from
from .._periodic.attractors import attractors
from .._periodic.harmonic import HarmonicBalance
from .._periodic.marching import Marching
from .._periodic.shooting import Shooting
from .._periodic.steady import make_config, steady_state
from .._periodic.sweep import RETRY_BATCH, frequency_response, march_chunk
from .._systems.forcing import Harmonic
from .._systems.params import get_param, replace_params
from .base import (
    Reparam,
    band_amplitudes,
    band_objective,
    check_design,
    design_method,
    legacy_objective,
    shooting_for_design,
)
from .objectives import SmoothPeak, as_objective
from .peak import design_system, evaluate_points, exact_peak_of, peak_core
from .robust import robust_peak_of, stable_responses

_TRACES = {"tune_step": 0}


def _amplitudes_fn(system, names, reparam, omegas, amplitude, guesses, cfg, method):
    def f(u):
        p = reparam.forward(u)
        sysp = replace_params(system, dict(zip(names, p)), check=False)
        amps, states, status, _ = band_amplitudes(sysp, omegas, amplitude, guesses, cfg, method)
        return amps, (amps, states, status)

    return f


@eqx.filter_jit
def _amplitudes_and_jac(system, names, reparam, u, omegas, amplitude, guesses, cfg, method):
    _TRACES["tune_step"] += 1  # runs only when traced: counts compilations
    f = _amplitudes_fn(system, names, reparam, omegas, amplitude, guesses, cfg, method)
    # forward mode: one tangent per parameter, the Jacobian of every band amplitude
    jac, aux = jax.jacfwd(f, has_aux=True)(u)
    return jac, aux


@eqx.filter_jit
def _objective_and_grad(amps, jac, objective, softness):
    val, g = jax.value_and_grad(lambda a: band_objective(a, objective, softness))(amps)
    return val, g @ jac


def _value_and_jac(system, names, reparam, u, omegas, amplitude, guesses, cfg, method,
                   objective, softness):
    """The band objective and its gradient in ``u``: the amplitudes and their Jacobian in one
    compiled program (whatever the objective: every objective and softness shares it), the
    objective applied after it by the chain rule."""
    jac, aux = _amplitudes_and_jac(system, names, reparam, u, omegas, amplitude, guesses, cfg,
                                   method)
    val, g = _objective_and_grad(aux[0], jac, objective, softness)
    return val, g, aux


def value_and_grad(system, params, omegas, *, amplitude, objective=None, method=None,
                   integrator=None, **legacy):
    """A band objective over the grid ``omegas`` [rad/s] and its gradient with respect to
    the named parameters (in their own units), e.g.
    ``value_and_grad(system, ["k1", "c1"], omegas, amplitude=2.0)``.

    ``objective``: ``objectives.SmoothPeak()`` (default) or ``MeanSquare()`` of the grid
    amplitudes (implicit differentiation through each orbit solve), or ``ExactPeak()`` /
    ``RobustPeak()`` over the grid's band (their ``n_freq`` is the grid's size); ``method``:
    the ``Shooting`` of each orbit (default ``Shooting(tol=1e-7, newton_steps=40)``), or a
    ``HarmonicBalance`` for the grid objectives (its orbits differentiated implicitly too);
    ``integrator``: default the design tolerances (1e-10).

    Returns ``(value, {name: dvalue/dname}, status per frequency)``."""
    obj = SmoothPeak() if objective is None else (
        SmoothPeak() if objective == "amplitude" else as_objective(objective, "value_and_grad"))
    obj = legacy_objective(obj, "value_and_grad", legacy, options=("softness",))
    method = design_method(method, "value_and_grad", legacy, balance=True)
    integ = integrator_from(integrator, "design", "value_and_grad", legacy,
                            fields=("solver", "rtol", "atol", "max_steps"))
    no_more("value_and_grad", legacy)
    objective, softness = obj.kind, getattr(obj, "softness", 2e-3)
    tol, newton_steps = method.tol, method.newton_steps
    rtol, atol, solver = integ.rtol, integ.atol, integ.solver
    names, omegas = check_design(system, params, omegas, objective)
    solver_of_orbits = (method if isinstance(method, HarmonicBalance)
                        else shooting_for_design(tol, newton_steps))
    if objective in ("exact_peak", "robust_peak") and isinstance(method, HarmonicBalance):
        raise ValueError(f"value_and_grad: objective {objective!r} follows its peaks by "
                         "shooting; give method=aj.Shooting(...), or a grid objective "
                         "(SmoothPeak, MeanSquare) with HarmonicBalance")
    if objective in ("exact_peak", "robust_peak"):
        if omegas.size < 3:
            raise ValueError(f"objective {objective!r} needs a grid of >= 3 frequencies")
        kw = dict(amplitude=amplitude, params=names, n_freq=omegas.size, peaks=obj.peaks,
                  tol=tol, rtol=rtol, atol=atol, newton_steps=newton_steps, solver=solver,
                  xtol=obj.xtol, max_iter=obj.max_iter, modes=obj.modes,
                  max_steps=integ.max_steps)
        band = (omegas[0], omegas[-1])
        pk = (exact_peak_of(system, band, **kw) if objective == "exact_peak" else
              robust_peak_of(system, band, probes=obj.probes, samples=obj.probe_samples,
                             spread=obj.spread, seed=obj.seed, max_periods=obj.max_periods,
                             **kw))
        plain = pk if objective == "exact_peak" else pk.plain
        return pk.value, pk.gradient, plain.grid_status
    p0 = jnp.array([float(get_param(system, k)) for k in names])
    ident = Reparam(lo=jnp.zeros(len(names)), hi=jnp.ones(len(names)),
                    bounded=jnp.zeros(len(names), bool), identity=jnp.zeros(len(names), bool))
    cfg = make_config(system, Harmonic(amplitude=amplitude, omega=float(omegas[0])), solver,
                      rtol, atol, integ.max_steps)
    guesses = jnp.full((len(omegas), system.num_states), jnp.nan, dtype=jnp.float64)
    val, g, (amps, _, status) = _value_and_jac(system, names, ident, jnp.log(p0),
                                               jnp.asarray(omegas), jnp.asarray(amplitude, float),
                                               guesses, cfg, solver_of_orbits, objective,
                                               softness)
    grads = {k: float(g[i] / p0[i]) for i, k in enumerate(names)}  # d/dlog p -> d/dp
    return float(val), grads, np.asarray(status)


def _reseed(system, names, reparam, u, omegas, amplitude, status, states, cfg):
    """Internal-state guesses for a band: the converged states where ``status`` is 0, and
    for the others the state marched from rest (``march_from_rest``, in padded batches of
    ``RETRY_BATCH`` by ``by_parts``: one compilation).  The design's own shooting then
    starts from them, so the marches need no shooting of their own (no march-then-shoot
    program)."""

    p = np.asarray(reparam.forward(u))
    bad = np.flatnonzero(status != Status.SUCCESS)
    seeds = np.where((status == Status.SUCCESS)[:, None], states, np.nan)
    if bad.size:
        om, pv = np.asarray(omegas), np.tile(p, (RETRY_BATCH, 1))
        amp = jnp.asarray(amplitude, dtype=float)
        _, seeds[bad] = by_parts(bad, RETRY_BATCH, lambda i, live, d: march_chunk(
            system, put(om[i], d), amp, put(pv, d), cfg, names, False, put(live, d)), 1)
    return seeds


def tune(system, params, band, *, amplitude, objective=None, optimizer=None, steps=100,
         starts=None, method=None, integrator=None, progress=False, confirm=True, **legacy):
    """Tune absorber parameters to minimise the steady-state amplitude of the system's
    observable over a frequency band.

    **Arguments**

    - ``system``: the starting design; ``params``: names to tune (``"k1"``, ``"c1"``, ``"m"``,
      ``"gap"``, ``"N"``, ``"k2"``, ``"c2"``, ``"mu"``, ...: ``parameter_names(system)``), or
      ``{name: (lo, hi)}`` with bounds in the parameters' units (``None``: unbounded, the
      parameter must then stay positive).
    - ``band``: ``(lo, hi)`` [rad/s]; ``amplitude``: the force amplitude F0 [N].
    - ``objective``: an objective object from ``absorber_jax.objectives`` carrying its
      options; default ``absorber_jax.objectives.ExactPeak`` ``()``: the band's peaks
      located exactly and minimised as a minimax problem by SLSQP on the epigraph, which
      lands on the equal-peak (H∞) optimum.  ``absorber_jax.objectives.RobustPeak``
      adds the stable coexisting responses attractor maps find;
      ``absorber_jax.objectives.SmoothPeak`` and
      ``absorber_jax.objectives.MeanSquare`` are grid objectives descended by
      ``optimizer``.  The names ``"exact_peak"``, ``"robust_peak"``, ``"peak"``,
      ``"mean_square"`` stand for those objects with their default options.
    - ``optimizer``: an optax transformation acting on the reparametrised values (``log p``
      for positive parameters, ``logit`` of the position within ``bounds[name]``).  Default
      for the grid objectives: Adam, learning rate 0.05 with cosine decay over ``steps``; for
      the exact objectives ``None`` means the minimax solve, an optax optimiser there descends
      the largest peak instead.
    - ``steps``: optimiser steps (SLSQP iterations for the minimax solve).
    - ``starts``: global starts, ``{name: values}`` for some or all tuned parameters: the grid
      of their combinations is evaluated on the band in vmapped calls, the 3 best designs are
      each tuned and the best result returned (``history["starts"]``); a pair
      ``(grid, n_best)`` keeps ``n_best`` instead of 3.
    - ``method``: the ``Shooting`` that solves each orbit (its ``tol``, the scaled
      max-norm of the period-map residual, and ``newton_steps``); default
      ``Shooting(tol=1e-7, newton_steps=40)``; or, for the grid objectives, a
      ``HarmonicBalance`` (its orbits differentiated implicitly; failed frequencies are
      reseeded by shooting's marching retry all the same).  Design evaluations never fall back to
      marching (a branch switch would make the objective discontinuous): failed points are
      reseeded by marching between evaluations instead.
    - ``integrator``: an ``Integrator`` (default: the design tolerances, rtol = atol =
      1e-10).
    - ``progress``: ``True`` for a tqdm bar, or a function ``progress(step, value, params)``
      called after each evaluation.
    - ``confirm``: re-check the curves before and after by marching (an independent method)
      on 12 frequencies and march from 8 initial states at the tuned design's peak: the
      responses it settles on (``history["settles_on"]``); a pair ``(points, samples)`` sets
      those counts.

    **Returns** ``(tuned_system, history)``; ``history`` holds per evaluation ``objective``,
    ``params`` (dict of lists), ``grad_norm``, ``failed`` (frequencies that did not
    converge), ``nonsmooth``, and for the exact objectives ``peaks`` and ``peak_omegas`` per
    slot; plus ``omegas``, ``amplitude_before``/``after``, ``best`` and, with ``confirm``, the
    marching check.

    ```python
    import absorber_jax as aj
    system, _ = aj.presets.impact("kelvin_voigt")
    tuned, hist = aj.tune(system, ["k1", "c1"], (25.0, 45.0), amplitude=2.0, steps=30)
    hist["best"]            # {"k1": ..., "c1": ...}
    ```
    """
    bounds = legacy.pop("bounds", None)
    if bounds is not None:
        moved("tune", {"bounds": bounds}, "params={{name: (lo, hi)}} ({})")
    if isinstance(params, dict):
        bounds = {**{k: tuple(v) for k, v in params.items() if v is not None}, **(bounds or {})}
        params = list(params)
    callback = legacy.pop("callback", None)
    if callback is not None:
        moved("tune", {"callback": callback}, "progress=<your function> ({})")
    if callable(progress):
        callback, progress = progress, False
    obj = SmoothPeak() if objective == "amplitude" else as_objective(objective, "tune")
    obj = legacy_objective(obj, "tune", legacy)
    method = design_method(method, "tune", legacy, balance=True)
    if isinstance(method, HarmonicBalance) and obj.kind in ("exact_peak", "robust_peak"):
        raise ValueError(f"tune: objective {obj.kind!r} follows its peaks by shooting; give "
                         "method=aj.Shooting(...), or a grid objective (SmoothPeak, "
                         "MeanSquare) with HarmonicBalance")
    integ = integrator_from(integrator, "design", "tune", legacy,
                            fields=("solver", "rtol", "atol", "max_steps"))
    n_starts = 3
    if "n_starts" in legacy:
        n_starts = legacy.pop("n_starts")
        moved("tune", {"n_starts": n_starts}, "starts=(grid, {})")
    if isinstance(starts, tuple):
        if len(starts) != 2:
            raise ValueError("tune.starts must be a dict {name: values} or a pair "
                             "(dict, n_best)")
        starts, n_starts = starts
    points, samples = (12, 8) if confirm is True or confirm is False else confirm
    if {"confirm_points", "confirm_samples"} & set(legacy):
        points = legacy.pop("confirm_points", points)
        samples = legacy.pop("confirm_samples", samples)
        moved("tune", {"confirm_points": points, "confirm_samples": samples},
              "confirm=(points, samples)")
    no_more("tune", legacy)
    opts = dict(n_freq=64, softness=2e-3, peaks=2, modes=True, stability_margin=None,
                probes=8, probe_samples=16, rounds=3)
    opts.update(obj.options())
    return _tune(system, params, band, amplitude=amplitude, objective=obj.kind,
                 optimizer=optimizer, steps=steps, bounds=bounds, tol=method.tol,
                 rtol=integ.rtol, atol=integ.atol, newton_steps=method.newton_steps,
                 solver=integ.solver, progress=progress, confirm=bool(confirm),
                 confirm_points=points, confirm_samples=samples, starts=starts,
                 n_starts=n_starts, callback=callback, max_steps=integ.max_steps,
                 balance=method if isinstance(method, HarmonicBalance) else None, **opts)


def _tune(system, params, band, *, amplitude, objective, optimizer, steps, n_freq, bounds,
          softness, peaks, tol, rtol, atol, newton_steps, solver, progress, confirm,
          confirm_points, confirm_samples, stability_margin, starts, n_starts, modes, probes,
          probe_samples, rounds, callback, max_steps=200_000, balance=None):
    """``tune`` with the objective's options unpacked (``objective`` its ``kind``);
    ``balance``: the ``HarmonicBalance`` that solves the grid objectives' orbits (None:
    shooting)."""
    require_x64("tune")
    import optax

    if starts is not None:
        return _tune_from_starts(system, params, band, starts, n_starts, progress, dict(
            amplitude=amplitude, objective=objective, optimizer=optimizer, steps=steps,
            n_freq=n_freq, bounds=bounds, softness=softness, peaks=peaks, tol=tol, rtol=rtol,
            atol=atol, newton_steps=newton_steps, solver=solver, confirm=confirm,
            confirm_points=confirm_points, confirm_samples=confirm_samples,
            stability_margin=stability_margin, modes=modes, probes=probes,
            probe_samples=probe_samples, rounds=rounds, callback=callback,
            max_steps=max_steps, balance=balance))
    if stability_margin is not None:
        check_scalar("tune", "stability_margin", stability_margin, lo=0.0, hi=1.0, hi_open=True)
        if objective not in ("exact_peak", "robust_peak"):
            raise ValueError("tune.stability_margin needs objective='exact_peak' or "
                             "'robust_peak' (the margin is checked on the orbits at the "
                             "located peaks)")
    lo, hi = band
    check_scalar("tune", "band[0]", lo, lo=0.0, lo_open=True)
    check_scalar("tune", "band[1]", hi, lo=float(lo))
    if not isinstance(steps, int) or steps < 0:
        raise ValueError(f"tune.steps must be a non-negative integer, got {steps!r}")
    exact = objective in ("exact_peak", "robust_peak")
    robust = objective == "robust_peak"
    if exact and not (isinstance(n_freq, int) and n_freq >= 3 and hi > lo):
        raise ValueError(f"tune with objective={objective!r} needs a band hi > lo and "
                         f"n_freq >= 3, got band {band} and n_freq {n_freq!r}")
    for field, v in (("probes", probes), ("probe_samples", probe_samples), ("rounds", rounds)):
        if robust and not (isinstance(v, int) and v >= 1):
            raise ValueError(f"tune.{field} must be a positive integer, got {v!r}")
    if exact and not (isinstance(peaks, int) and 1 <= peaks <= n_freq):
        raise ValueError(f"tune.peaks must be an integer in [1, n_freq], got {peaks!r}")
    omegas = np.linspace(lo, hi, n_freq) if hi > lo else np.array([float(lo)])
    names, omegas = check_design(system, params, omegas, "peak" if exact else objective)
    bounds = dict(bounds or {})
    for k in bounds:
        if k not in names:
            raise ValueError(f"bounds given for {k!r}, which is not tuned ({names})")
        b_lo, b_hi = bounds[k]
        if not (np.isfinite(b_lo) and np.isfinite(b_hi) and b_lo < b_hi):
            raise ValueError(f"bounds[{k!r}] must be finite with lo < hi, got {bounds[k]}")
    p0 = np.array([float(get_param(system, k)) for k in names])
    reparam = Reparam(lo=jnp.array([bounds.get(k, (0.0, 1.0))[0] for k in names]),
                      hi=jnp.array([bounds.get(k, (0.0, 1.0))[1] for k in names]),
                      bounded=jnp.array([k in bounds for k in names]),
                      identity=jnp.zeros(len(names), bool))
    for k, v in zip(names, p0):
        if k in bounds and not bounds[k][0] < v < bounds[k][1]:
            raise ValueError(f"the starting {k} = {v:g} must lie strictly inside bounds "
                             f"{bounds[k]}")
        if k not in bounds and v <= 0:
            raise ValueError(f"the starting {k} = {v:g} must be > 0 (or give bounds)")
    cfg = make_config(system, Harmonic(amplitude=amplitude, omega=float(omegas[0])), solver,
                      rtol, atol, max_steps)
    u0 = reparam.inverse(jnp.asarray(p0))
    evaluate = _Evaluator(system, names, reparam, omegas, amplitude, cfg, tol, newton_steps,
                          objective, softness, peaks, stability_margin, solver, rtol, atol,
                          modes, balance)
    hist = {"objective": [], "params": {k: [] for k in names}, "grad_norm": [], "failed": [],
            "nonsmooth": [], "seconds": [], "peak_bias": []}
    if exact:
        hist.update(peaks=[], peak_omegas=[], unstable=0)
    if robust:
        u_best = _robust_rounds(evaluate, band, u0, steps, hist, progress, callback,
                                optimizer, dict(probes=probes, samples=probe_samples,
                                                solver=solver, rtol=rtol, atol=atol), rounds)
    elif exact and optimizer is None:
        u_best = _minimax(evaluate, u0, steps, hist, progress, callback)
    else:
        if optimizer is None:
            optimizer = optax.adam(optax.cosine_decay_schedule(0.05, max(steps, 1), alpha=0.05))
        u_best = _descend(evaluate, optimizer, u0, steps, hist, progress, callback)
    p_best = np.asarray(reparam.forward(u_best))
    tuned = replace_params(system, {k: float(v) for k, v in zip(names, p_best)}, check=True)
    hist["omegas"] = omegas
    hist["names"] = names
    hist["amplitude_before"] = evaluate.amps_before

    after = frequency_response(tuned, omegas, amplitude=float(amplitude),
                               method=balance or Shooting(tol=tol, newton_steps=newton_steps),
                               integrator=Integrator(solver=solver, rtol=rtol, atol=atol))
    hist["amplitude_after"] = after.amplitude
    hist["status_after"] = after.status
    hist["stable_after"] = after.stable
    hist["best"] = {k: float(v) for k, v in zip(names, p_best)}
    if confirm:
        _confirm(system, tuned, hist, amplitude, confirm_points, confirm_samples, solver, rtol,
                 atol)
    return tuned, hist


def _confirm(system, tuned, hist, amplitude, points, samples, solver, rtol, atol):
    """The independent checks of a tuning: marching on ``points`` frequencies before and
    after, and the responses the tuned design settles on at its peak frequency."""

    omegas = hist["omegas"]
    om_c = np.linspace(omegas[0], omegas[-1], min(points, len(omegas)))
    kw = dict(amplitude=float(amplitude), method=Marching(max_periods=4000))
    before = frequency_response(system, om_c, **kw)
    after_m = frequency_response(tuned, om_c, **kw)
    hist["confirm"] = {"omegas": om_c, "before": before.amplitude, "after": after_m.amplitude,
                       "status_before": before.status, "status_after": after_m.status,
                       "period_before": before.period_multiple,
                       "period_after": after_m.period_multiple}
    a = np.where(np.asarray(hist["status_after"]) == Status.SUCCESS,
                 np.asarray(hist["amplitude_after"]), -np.inf)
    w_pk, designed = ((float(omegas[int(np.argmax(a))]), float(np.max(a)))
                      if np.isfinite(a).any() else (math.nan, math.nan))
    if "peaks" in hist and hist["feasible"]:
        i = int(np.nanargmin(hist["objective"]))
        j = int(np.argmax(hist["peaks"][i]))
        w_pk, designed = float(hist["peak_omegas"][i][j]), float(hist["peaks"][i][j])
    hist["settles_on"] = _settles_on(tuned, w_pk, designed, amplitude, samples, solver, rtol,
                                     atol)


def _settles_on(tuned, omega, designed, amplitude, samples, solver, rtol, atol):
    """March the tuned design from ``samples`` initial states at its peak frequency: the
    responses it settles on, and whether the largest stable one is the designed orbit."""

    if not np.isfinite(omega):
        return {"omega": math.nan, "attractors": [], "designed": math.nan,
                "worst_stable": math.nan, "is_designed": False}
    amap = attractors(tuned, Harmonic(amplitude=float(amplitude), omega=float(omega)),
                      samples=samples,
                      integrator=Integrator(solver=solver, rtol=rtol, atol=atol))
    stable = [x.amplitude for x in amap.attractors if x.periodic and x.stable]
    worst = float(max(stable)) if stable else math.nan
    return {"omega": float(omega), "attractors": [x.summary() for x in amap.attractors],
            "designed": designed, "worst_stable": worst,
            "is_designed": bool(stable) and bool(abs(worst - designed) <= 1e-3 * abs(designed))}


def _tune_from_starts(system, params, band, starts, n_starts, progress, kw):
    """Global starts: the grid of ``starts`` evaluated in vmapped calls, the best
    ``n_starts`` designs tuned, the best result returned."""
    import itertools


    names = tuple(params)
    if not isinstance(starts, dict) or not starts:
        raise ValueError("tune.starts must be a dict {parameter: values}, e.g. "
                         "{'gap': [1e-3, 2e-3], 'c1': [1.0, 10.0]}")
    for k, v in starts.items():
        if k not in names:
            raise ValueError(f"starts given for {k!r}, which is not tuned ({names})")
        if np.asarray(v, dtype=float).ndim != 1 or len(v) == 0:
            raise ValueError(f"starts[{k!r}] must be a non-empty list of values")
    if not isinstance(n_starts, int) or n_starts < 1:
        raise ValueError(f"tune.n_starts must be a positive integer, got {n_starts!r}")
    keys = list(starts)
    combos = [dict(zip(keys, c)) for c in itertools.product(*(starts[k] for k in keys))]
    lo, hi = band
    omegas = np.linspace(lo, hi, kw["n_freq"])
    grid = {k: np.array([c[k] for c in combos], dtype=float) for k in keys}
    fr = frequency_response(system, omegas, amplitude=float(kw["amplitude"]), params=grid,
                            method=kw["balance"] or Shooting(tol=kw["tol"],
                                                             newton_steps=kw["newton_steps"]),
                            integrator=Integrator(solver=kw["solver"], rtol=kw["rtol"],
                                                  atol=kw["atol"]),
                            floquet=False, progress=progress)
    amp = np.where(np.asarray(fr.ok), np.asarray(fr.amplitude), np.inf)
    peak = np.max(amp, axis=-1).reshape(len(combos))
    order = [int(i) for i in np.argsort(peak) if np.isfinite(peak[i])][:n_starts]
    if not order:
        raise ValueError("tune: no design of the starts grid converged at every frequency")
    best = None
    for i in order:
        # the independent checks run once, on the best result (below)
        start = replace_params(system, combos[i], check=True)
        tuned, hist = _tune(start, params, band, progress=progress,
                           **dict(kw, confirm=False, starts=None, n_starts=1))
        val = np.nanmin(hist["objective"])
        if best is None or val < best[0]:
            best = (val, tuned, hist)
    _, tuned, hist = best
    if kw["confirm"]:
        _confirm(system, tuned, hist, kw["amplitude"], kw["confirm_points"],
                 kw["confirm_samples"], kw["solver"], kw["rtol"], kw["atol"])
    hist["starts"] = {"designs": combos, "grid_peak": peak, "tuned_from": [combos[i]
                                                                           for i in order]}
    return tuned, hist


class _Evaluator:
    """The objective, its gradient in the reparametrised ``u`` and the bookkeeping shared by
    the optimisers: warm starts from the last converged orbits, reseeding of failed
    frequencies by marching, and one history record per evaluation."""

    def __init__(self, system, names, reparam, omegas, amplitude, cfg, tol, newton_steps,
                 objective, softness, peaks, margin=None, solver=None, rtol=1e-10, atol=1e-10,
                 modes=True, balance=None):
        self.args = (system, names, reparam)
        self.margin, self.integrator = margin, dict(solver=solver, rtol=rtol, atol=atol)
        self.omegas, self.amplitude, self.cfg = omegas, amplitude, cfg
        self.tol, self.newton_steps = tol, newton_steps
        self.objective, self.softness, self.peaks = objective, softness, peaks
        self.modes = bool(modes)
        self.balance = balance
        self.exact = objective in ("exact_peak", "robust_peak")
        # coexisting responses followed by shooting (objective "robust_peak"): their
        # frequencies and internal states
        self.tracked = None
        self.guesses = jnp.full((len(omegas), system.num_states), jnp.nan, dtype=jnp.float64)
        self.amps_before = None
        self.prev_status = None
        self.cache, self.grid_cache = {}, {}

    def _run(self, u, guesses):
        system, names, reparam = self.args
        om, amp = jnp.asarray(self.omegas), jnp.asarray(self.amplitude, dtype=float)
        if self.exact:

            out = peak_core(system, names, reparam, u, om, amp, guesses, self.cfg,
                            float(self.tol), int(self.newton_steps), int(self.peaks), 1e-10, 40,
                            self.modes)
            out = {k: np.asarray(v) for k, v in out.items()}
            F = len(self.omegas)    # the uniform grid (then the modal points)
            return (out, out["grid_amplitude"][:F], out["grid_states"][:F],
                    out["grid_status"][:F])
        val, g, (amps, states, status) = _value_and_jac(
            system, names, reparam, u, om, amp, guesses, self.cfg,
            self.balance or shooting_for_design(float(self.tol), int(self.newton_steps)),
            self.objective, self.softness)
        return ((float(val), np.asarray(g)), np.asarray(amps), np.asarray(states),
                np.asarray(status))

    def _unstable(self, u, res, ok):
        """Slots whose orbit has a multiplier beyond ``1 - margin``."""

        sysp = design_system(*self.args, u)
        out = np.zeros(len(ok), bool)
        for j in np.flatnonzero(ok):
            ss = steady_state(sysp, Harmonic(amplitude=self.amplitude,
                                             omega=float(res["omegas"][j])),
                              guess=np.asarray(sysp.to_public(jnp.asarray(res["states"][j]))),
                              tol=self.tol, retry=False, **self.integrator)
            mult = np.asarray(ss.multipliers)
            # a floating absorber's structural multiplier 1 (already set aside by the
            # stability label) carries no margin
            mu = np.abs(mult[np.abs(mult - 1.0) > 1e-3])
            out[j] = not (bool(ss.stable) and np.all(mu <= 1.0 - self.margin))
        return out

    def _follow(self, u):
        """Amplitudes, gradients and success of the tracked coexisting responses at ``u``;
        their states move on with the design."""

        system, names, reparam = self.args
        w, x = self.tracked
        # in batches of the exact peak's slots: the objective's compiled program, reused
        a, g, xn, st = evaluate_points(
            system, names, reparam, jnp.asarray(u), w, jnp.asarray(self.amplitude, dtype=float),
            x, self.cfg, float(self.tol), int(self.newton_steps), int(self.peaks))
        ok = st == Status.SUCCESS
        self.tracked = (w, np.where(ok[:, None], xn, x))
        return np.where(ok, a, 0.0), np.where(ok[:, None], g[:, 1:], 0.0), ok

    def _grid(self, u):
        """The design's grid pass at ``u`` (failed frequencies reseeded by marching), cached
        by ``u``: the followed responses change between robust rounds, the grid does not."""
        key = np.asarray(u).tobytes()
        if key not in self.grid_cache:
            res, amps, states, status = self._run(u, self.guesses)
            if not np.all(status == Status.SUCCESS):
                # Newton from the warm start (or the linear guess) failed somewhere: seed
                # those frequencies from marching and evaluate again
                system, names, reparam = self.args
                seeds = _reseed(system, names, reparam, u, self.omegas, self.amplitude,
                                status, states, self.cfg)
                res, amps, states, status = self._run(u, jnp.asarray(seeds))
            self.guesses = jnp.where(jnp.asarray(status == Status.SUCCESS)[:, None], states,
                                     jnp.nan)
            self.grid_cache = {key: (res, amps, states, status)}
        return self.grid_cache[key]

    def _exact_values(self, res):
        """``(values, jacobian, ok)`` of the exact objective's constraints: the located
        peaks, and every grid point too (a lower bound of the peak: a peak that no slot
        tracks cannot rise unseen above the others).  A modal grid point that fails is no
        information (no constraint); a uniform grid point or a slot that fails makes the
        design unacceptable (``__call__``)."""
        ok = np.concatenate([res["status"], res["grid_status"]]) == Status.SUCCESS
        vals = np.concatenate([res["amplitudes"], res["grid_amplitude"]])
        jac = np.concatenate([res["jac"], res["grid_jac"]])
        seed_failed = np.zeros(len(vals), bool)
        n = len(res["amplitudes"]) + len(self.omegas)
        seed_failed[n:] = ~ok[n:]
        return (np.where(seed_failed, 0.0, vals), np.where(seed_failed[:, None], 0.0, jac),
                ok | seed_failed)

    def plain_peak(self, u):
        """The exact peak at ``u`` (slots and grid), without the followed responses and
        without a history record."""
        vals, _, ok = self._exact_values(self._grid(jnp.asarray(u, dtype=float))[0])
        return float(np.max(vals[ok])) if ok.any() else math.nan

    def __call__(self, u, hist):
        """``(values, jacobian, ok)``: per slot for "exact_peak" (values (K,), jacobian (K, P)),
        else the objective as one slot.  Cached by ``u``."""
        u = jnp.asarray(u, dtype=float)
        key = np.asarray(u).tobytes()
        if key in self.cache:
            return self.cache[key]
        t = time.perf_counter()
        res, amps, states, status = self._grid(u)
        grid_ok = status == Status.SUCCESS
        if self.amps_before is None:
            self.amps_before = amps
        unstable = None
        if self.exact:
            vals, jac, ok = self._exact_values(res)
            K = len(res["amplitudes"])
            if self.tracked is not None:
                a_t, j_t, ok_t = self._follow(u)
                hist["tracked"].append(a_t.copy())
                ok = np.concatenate([ok, ok_t])
                vals, jac = np.concatenate([vals, a_t]), np.concatenate([jac, j_t])
            if self.margin is not None:
                unstable = np.concatenate([self._unstable(u, res, ok[:K]),
                                           np.zeros(len(vals) - K, bool)])
                hist["unstable"] += int(unstable.any())
                # an infeasible design: far above every feasible one, so that the line
                # search backs off, and never the best
                vals = np.where(unstable, 10.0 * np.max(np.abs(vals)), vals)
                jac = np.where(unstable[:, None], 0.0, jac)
            val = float(np.max(vals[ok])) if ok.any() else math.nan
            g = jac[int(np.argmax(np.where(ok, vals, -np.inf)))] if ok.any() else jac[0] * np.nan
            hist["peaks"].append(vals[:self.peaks].copy())
            hist["peak_omegas"].append(res["omegas"].copy())
            bias = 0.0
        else:
            (val, g), ok = res, np.array([grid_ok.all()])
            vals, jac = np.array([val]), g[None]
            bias = (float(np.max(amps[grid_ok]) - val) if grid_ok.any() and
                    self.objective == "peak" else math.nan)
        system, names, reparam = self.args
        p = np.asarray(reparam.forward(u))
        hist["objective"].append(val)
        for k, v in zip(names, p):
            hist["params"][k].append(float(v))
        hist["grad_norm"].append(float(np.linalg.norm(g)))
        hist["failed"].append(int((~grid_ok).sum()))
        hist["nonsmooth"].append(0 if self.prev_status is None
                                 else int((self.prev_status != status).sum()))
        hist["peak_bias"].append(bias)
        hist["seconds"].append(time.perf_counter() - t)
        self.prev_status = status
        feasible = not (self.exact and self.margin is not None
                        and bool(unstable.any()))
        out = (vals, jac, ok & grid_ok.all(), val, g, dict(zip(names, p)), feasible)
        self.cache = {key: out}
        return out


def _descend(evaluate, optimizer, u, steps, hist, progress, callback):
    """Gradient descent with an optax ``optimizer``; the best design whose every frequency
    converged."""
    from tqdm.auto import tqdm

    opt_state = optimizer.init(u)
    best = (np.inf, u)
    bar = tqdm(range(steps + 1), desc="tune", disable=not progress)
    for it in bar:
        _, _, ok, val, g, p, feasible = evaluate(u, hist)
        if ok.all() and feasible and val < best[0]:
            best = (val, u)
        bar.set_postfix(objective=f"{val:.4g}", **{k: f"{v:.4g}" for k, v in p.items()})
        if callback is not None:
            callback(it, val, p)
        if it == steps or not np.all(np.isfinite(g)):
            break
        updates, opt_state = optimizer.update(jnp.asarray(g), opt_state, u)
        u = u + updates
    hist["feasible"] = bool(np.isfinite(best[0]))
    return best[1]


# how far (in log p, or in logit of the bounded position) SLSQP may move a parameter from its
# start: a factor e^7 ~ 1100 either way
MINIMAX_REACH = 7.0


def _minimax(evaluate, u0, steps, hist, progress, callback):
    """``min t`` s.t. ``A_j(u) <= t`` for every peak slot ``j`` (SLSQP on the epigraph, the
    amplitudes scaled by the starting peak).  Failed slots give no constraint information:
    their value is the largest successful one, their gradient zero.  SLSQP stops once the
    scaled peak changes by less than the shooting tolerance (the evaluations' own accuracy;
    with ftol 1e-12 the TMD of tests/design/test_peak.py reached its optimum to 2e-13 in 11
    evaluations, then spent 36 more on steps inside the rounding noise)."""
    from scipy.optimize import minimize
    from tqdm.auto import tqdm

    u0 = np.asarray(u0, dtype=float)
    vals0, _, ok0, val0, _, _, feas0 = evaluate(u0, hist)
    if not ok0.any():
        raise ValueError("tune: the starting design's peak could not be computed "
                         "(no slot converged); check the band and the design")
    scale = float(val0)
    best = [val0 if ok0.all() and feas0 else np.inf, u0]
    bar = tqdm(total=steps, desc="tune (minimax)", disable=not progress)

    def slots(x):
        u = x[:-1]
        vals, jac, ok, val, _, p, feasible = evaluate(u, hist)
        if ok.all() and feasible and val < best[0]:
            best[0], best[1] = val, np.array(u)
        fill = np.max(vals[ok]) if ok.any() else 10.0 * scale
        return np.where(ok, vals, fill) / scale, np.where(ok[:, None], jac, 0.0) / scale

    def step_done(x):
        bar.update(1)
        if callback is not None:
            _, _, _, val, _, p, _ = evaluate(x[:-1], hist)
            callback(bar.n, val, p)

    n = u0.size
    x0 = np.concatenate([u0, [float(np.max(vals0[ok0])) / scale]])
    cons = {"type": "ineq", "fun": lambda x: x[-1] - slots(x)[0],
            "jac": lambda x: np.hstack([-slots(x)[1], np.ones((len(vals0), 1))])}
    grad_t = np.concatenate([np.zeros(n), [1.0]])
    bounds = [(v - MINIMAX_REACH, v + MINIMAX_REACH) for v in u0] + [(0.0, None)]
    if steps > 0:
        minimize(lambda x: x[-1], x0, jac=lambda x: grad_t, constraints=[cons], bounds=bounds,
                 method="SLSQP", callback=step_done,
                 options=dict(maxiter=steps, ftol=max(float(evaluate.tol), 1e-12)))
    bar.close()
    hist["feasible"] = bool(np.isfinite(best[0]))
    return jnp.asarray(best[1])


def _robust_rounds(evaluate, band, u0, steps, hist, progress, callback, optimizer, probe_kw,
                   rounds):
    """Objective ``"robust_peak"`` by exchange rounds: attractor maps at the current design
    find its stable responses; each period-1 one larger than the exact peak (slots and
    grid) is followed from then on by shooting at its frequency, its amplitude one more
    minimax constraint (its gradient from the implicit orbit).  A design where a followed
    response is not found again is not accepted (it may have vanished past a fold, or
    shooting may have lost it: the design never gains from a failure).  After each minimax
    the maps run again at the result and the followed set is rebuilt from them; the rounds
    end when the maps find nothing larger than the exact peak that is not followed, or after
    ``rounds``.  A response of longer period is reported, not followed."""

    hist.update(tracked=[], rounds=[])
    system, names, reparam = evaluate.args
    u = np.asarray(u0, dtype=float)
    followed = None
    for r in range(rounds + 1):
        sysu = design_system(system, names, reparam, u)
        found = stable_responses(sysu, band, float(evaluate.amplitude), **probe_kw)
        plain = evaluate.plain_peak(u)
        larger = [(w, a) for w, a in found
                  if a.period_multiple == 1 and a.amplitude > plain * (1 + 1e-3)]
        worst = max([plain] + [float(a.amplitude) for _, a in found])
        new = followed is None or any(
            not np.any(np.isclose(w, followed[0]) & np.isclose(a.amplitude, followed[1],
                                                               rtol=1e-3))
            for w, a in larger)
        hist["rounds"].append(dict(
            plain=plain, worst=worst,
            params=dict(zip(names, np.asarray(reparam.forward(u)).tolist())),
            found=[dict(omega=w, amplitude=float(a.amplitude),
                        period_multiple=int(a.period_multiple),
                        state=np.asarray(a.state).tolist()) for w, a in found],
            followed=len(larger)))
        if r == rounds or not larger or (r > 0 and not new):
            break
        evaluate.tracked = (np.array([w for w, _ in larger]),
                            np.array([np.asarray(sysu.to_internal(jnp.asarray(a.state)))
                                      for _, a in larger]))
        evaluate.cache = {}
        followed = (evaluate.tracked[0], np.array([float(a.amplitude) for _, a in larger]))
        if optimizer is None:
            u = np.asarray(_minimax(evaluate, u, steps, hist, progress, callback))
        else:
            u = np.asarray(_descend(evaluate, optimizer, jnp.asarray(u), steps, hist, progress,
                                    callback))
    last = hist["rounds"][-1]
    longer = [f["amplitude"] for f in last["found"] if f["period_multiple"] > 1]
    hist["robust"] = dict(value=last["worst"], plain=last["plain"],
                          source="branch" if last["worst"] <= last["plain"] * (1 + 1e-3)
                          else "coexisting", longer_period=max(longer, default=math.nan))
    return jnp.asarray(u)


def plot_tuning(system_before, tuned, hist, path=None, title=""):
    """Response curves before and after tuning (shooting lines, marching check markers) and
    the objective's history."""
    import matplotlib

    if path is not None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [2, 1]})
    om = hist["omegas"]
    axs[0].plot(om, hist["amplitude_before"] * 1e3, "-", color="tab:gray", label="before")
    axs[0].plot(om, hist["amplitude_after"] * 1e3, "-", color="tab:blue", label="after (tuned)")
    if "confirm" in hist:
        c = hist["confirm"]
        ok_b, ok_a = c["status_before"] == 0, c["status_after"] == 0
        axs[0].plot(c["omegas"][ok_b], c["before"][ok_b] * 1e3, "o", mfc="none", color="tab:gray",
                    label="before, marching check")
        axs[0].plot(c["omegas"][ok_a], c["after"][ok_a] * 1e3, "o", mfc="none", color="tab:blue",
                    label="after, marching check")
    axs[0].set(xlabel="ω [rad/s]", ylabel="primary amplitude [mm]", title=title)
    axs[0].legend(fontsize=8)
    axs[1].semilogy(np.asarray(hist["objective"]))
    axs[1].set(xlabel="step", ylabel="objective",
               title=", ".join(f"{k}={v:.4g}" for k, v in hist["best"].items()))
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return fig
