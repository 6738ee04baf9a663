"""Periodic steady states: shooting with Floquet multipliers, and marching with a
periodicity test.

Both work on the *internal* state scaled to order one (positions by a length ``L``,
velocities by ``Lω``) so that one tolerance means the same thing for every component.

- **Shooting** solves ``Φ_{nT}(s) - s = 0`` for the period-``n`` map ``Φ`` with optimistix's
  Newton, its linear steps solved by SVD (minimum norm).  Where the absorber floats without
  touching the walls (or sticks, with its relative position frozen), its position is
  arbitrary: the orbits form a family, ``∂Φ/∂s - I`` is singular (a Floquet multiplier at
  exactly 1) and the minimum-norm step converges to the member of the family nearest the
  guess.  A shooting solve that fails is retried by marching then shooting
  (``march_then_shoot``).  The monodromy matrix is the
  Jacobian of ``Φ`` (``_integration.flow``); its eigenvalues are the Floquet
  multipliers.  Derivatives of a solved orbit with respect to parameters are implicit,
  ``ds/dθ = (I - M)^+ ∂Φ/∂θ`` (optimistix's ``ImplicitAdjoint`` for shooting,
  ``_periodic.orbit.implicit_orbit`` for marching), never taped
  through the Newton or marching loop; forward and reverse mode both work.
- **Marching** integrates forward in chunks of periods and samples the Poincaré section
  ``t = kT``.  It stops when, for the smallest ``n <= n_max``, the samples repeat with period
  ``n`` to within ``tol``, *and* the estimated distance to the limit (a geometric tail
  ``d ρ/(1-ρ)`` from the observed contraction ``ρ``) is below ``tol`` too: slow transients
  (a multiplier of 0.994 per period) are not mistaken for convergence.

Amplitudes (over one full response period ``nT``, from uniform samples
refined by parabolic interpolation at the extremes; ``SAMPLES_PER_PERIOD`` per forcing period
for the largest period multiple allowed): ``amplitude`` = half peak-to-peak of
``x1``; ``rms`` = RMS of ``x1`` about zero; ``harmonic`` = magnitude of ``x1``'s component at
the forcing frequency; ``absorber_amplitude`` and ``absorber_rms`` the same for the
absorber's motion relative to the primary (``x2 - x1``).
"""


from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp

from .._core.checks import check_state, is_traced, require_x64
from .._core.legacy import moved, no_more
from .._core.status import Status
from .._integration.flow import Config, integrate_flow, make_config, period_map, state_scale  # noqa: F401
from .._integration.settings import integrator_from
from .._systems.base import AbstractSystem
from .._systems.forcing import check_periodic
from .._systems.scales import warn_scales
from .base import AbstractSteadyMethod
from .marching import Marching
from .orbit import SAMPLES_PER_PERIOD, SteadyState, orbit_statistics  # noqa: F401
from .shooting import Shooting

# Periods marched by the retry before it polishes by shooting: enough to settle near a stable
# orbit or onto a chaotic attractor's neighbourhood, where shooting from the marched state
# converges; not the 4000 of a Marching solve, which a response that never becomes periodic
# spends in full (LuGre σ0 = 1e8 smoothed at eps = 1e-4: 4000 periods of 145k steps each).
RETRY_MARCH_PERIODS = 200


def march_then_shoot(system, forcing, cfg, shooting: Shooting, *, with_floquet=True,
                     marching: Marching | None = None):
    """The robust fallback of a shooting solve that failed: march from rest onto the orbit
    the structure settles on, then polish it by shooting from there (Newton converges in
    one or two steps from a marched state).  The shooting result is kept when it converged
    with the marched period multiple; otherwise marching's own result.

    Newton from the linear guess is not globally convergent on the piecewise-smooth period
    map of a sticking absorber (it wandered for 40 steps near the best normal force);
    marching is, for a stable orbit."""
    ma, xm = march_from_rest(system, forcing, cfg, with_floquet=with_floquet, marching=marching)
    sh = shooting.solve(system, forcing, xm, cfg, with_floquet=with_floquet)
    return polished(ma, sh, shooting.n)


def march_from_rest(system, forcing, cfg, *, with_floquet=True, marching=None):
    """``march_then_shoot``'s march (``RETRY_MARCH_PERIODS`` periods at most, from rest):
    its result and the marched state, scaled, to polish from (the rest state where the
    march gave no finite state)."""
    marching = Marching(max_periods=RETRY_MARCH_PERIODS) if marching is None else marching
    scale = state_scale(system, forcing)
    x0 = system.rest_state() / scale
    ma = marching.solve(system, forcing, x0, cfg, with_floquet=with_floquet)
    xm = system.to_internal(ma.state) / scale
    return ma, jnp.where(jnp.all(jnp.isfinite(xm)), xm, x0)


def polished(ma, sh, n, xp=jnp):
    """``march_then_shoot``'s choice between the march ``ma`` and the shooting ``sh`` from
    its state (period multiple ``n``): the shot where it converged with the marched period
    multiple (or the march failed), else the march; the iterations of both add up.
    ``xp``: ``jnp`` (traced results) or ``numpy`` (results of a batch, points first)."""
    use_shot = (sh.status == Status.SUCCESS) & ((ma.status != Status.SUCCESS)
                                                | (ma.period_multiple == n))

    def pick(a, b):
        a, b = xp.asarray(a), xp.asarray(b)
        return xp.where(xp.reshape(use_shot, use_shot.shape + (1,) * (a.ndim - use_shot.ndim)),
                        a, b)

    out = jax.tree_util.tree_map(pick, sh, ma)
    return eqx.tree_at(lambda r: r.iterations, out, sh.iterations + ma.iterations)


def solve_point(system, forcing, method: AbstractSteadyMethod, cfg, *, guess=None,
                with_floquet=True):
    """One periodic orbit: ``method`` from ``guess`` (internal state; None or non-finite:
    the method's own start).  The one point solve that ``steady_state``,
    ``frequency_response`` and the design objectives share; vmappable (no retry here: a
    single solve retries with ``march_then_shoot``, sweeps retry their failed points
    after the vmapped pass)."""
    scale = state_scale(system, forcing)
    start = method.initial_state(system, forcing)
    if guess is not None:
        start = jnp.where(jnp.all(jnp.isfinite(guess)), guess, start)
    return method.solve(system, forcing, start / scale, cfg, with_floquet=with_floquet)


_METHOD_OPTIONS = ("n", "tol", "newton_steps", "root", "retry", "n_max", "max_periods",
                   "chunk", "give_up")


def method_from(method, where, legacy, default=None):
    """The steady-state method of an entry point: ``method`` (an ``AbstractSteadyMethod``,
    or the names ``"shooting"``/``"marching"`` for ``Shooting()``/``Marching()``; ``None``:
    ``default``, else ``Shooting()``), with the deprecated option keywords popped from
    ``legacy`` set on it (a ``DeprecationWarning`` names the new form)."""
    given = {k: legacy.pop(k) for k in _METHOD_OPTIONS if k in legacy}
    given = {k: v for k, v in given.items() if v is not None}
    if given and not (method is None or isinstance(method, str)):
        raise ValueError(f"{where}: give {sorted(given)} on the method object "
                         f"({type(method).__name__}(...)), not as keywords")
    if method is None:
        method = Shooting() if default is None else default
    elif isinstance(method, str):
        if method not in ("shooting", "marching"):
            raise ValueError(f"{where}.method must be aj.Shooting(...), aj.Marching(...) (or "
                             f"'shooting', 'marching'), got {method!r}")
        method = Shooting() if method == "shooting" else Marching()
    elif not isinstance(method, AbstractSteadyMethod):
        raise ValueError(f"{where}.method must be a steady-state method such as "
                         f"aj.Shooting(...) or aj.Marching(...), got {type(method).__name__}")
    if given:
        moved(where, given, f"method=aj.{type(method).__name__}({{}})")
        # as the former keywords did: the options of the other method are not used
        fields = {f.name for f in dataclasses.fields(method)}
        given = {k: v for k, v in given.items() if k in fields}
        method = dataclasses.replace(method, **given)
    return method


def check_system_and_forcing(system, forcing, where="steady_state"):
    if not isinstance(system, AbstractSystem):
        raise ValueError(f"system must be an ImpactAbsorber, FrictionAbsorber or "
                         f"StructuralSystem, got {type(system).__name__}")
    check_periodic(forcing, where)


# Newton steps after which a single solve that will be retried gives up if its iterate is
# still far from an orbit (Shooting.give_up): the marching retry starts at once
GIVE_UP_NEWTON = 8


@eqx.filter_jit
def _steady_jit(system, forcing, guess, cfg, method, with_floquet):
    return solve_point(system, forcing, method.giving_up(GIVE_UP_NEWTON), cfg, guess=guess,
                       with_floquet=with_floquet)


@eqx.filter_jit
def _retry_jit(system, forcing, cfg, method, with_floquet):
    return march_then_shoot(system, forcing, cfg, method, with_floquet=with_floquet)


def _steady(system, forcing, guess, cfg, method, with_floquet):
    """Shooting, then (``method.retry``) marching and polishing where it failed.  The retry
    is compiled only when a point needs it: compiled together (a ``lax.cond``), the single
    KV point of the Table 1 scene took 17.8 s to compile and run instead of 6.0 s."""
    res = _steady_jit(system, forcing, guess, cfg, method, with_floquet)
    if not method.retry:
        return res
    if is_traced(res.status):
        # inside a caller's jit: both branches in the program
        return jax.lax.cond(res.status == Status.SUCCESS, lambda: res,
                            lambda: _retry_jit(system, forcing, cfg, method, with_floquet))
    if int(res.status) == Status.SUCCESS:
        return res
    return _retry_jit(system, forcing, cfg, method, with_floquet)


def steady_state(system, forcing, *, method=None, integrator=None, guess=None, floquet=True,
                 **legacy) -> SteadyState:
    """The periodic response of ``system`` under a periodic ``forcing`` (any
    ``AbstractPeriodicForcing``: ``Harmonic``, ``MultiHarmonic``,
    ``PeriodicForcing`` ...; its period is the fundamental ``2π/forcing.omega``).

    **Arguments**

    - ``method``: ``Shooting(...)`` (the default: Newton on the period-``n`` map from
      ``guess``, default the linear limit of the scene, see ``linear_guess``; a failed solve
      is retried by marching then shooting) or ``Marching(...)`` (integrate from ``guess``,
      default rest, until the Poincaré samples repeat with a period ``n <= n_max``), each
      carrying its options (tolerances on the state scaled to order one).
    - ``integrator``: an ``Integrator`` (default: the periodic tolerances, rtol = atol = 1e-9
      on the scaled state, ``max_steps`` per forcing period).
    - ``guess``: public state at ``t = 0`` (``system.state_names`` gives its layout).
    - ``floquet``: compute the Floquet multipliers (one forward-mode Jacobian); without
      them ``stable`` is False (not shown stable).

    **Returns** a ``SteadyState``; check ``status`` (0 = success).  ``iterations``
    counts Newton steps, plus periods marched when the retry marched.

    ```python
    import absorber_jax as aj
    system, forcing = aj.presets.impact("kelvin_voigt", omega=60.0)
    ss = aj.steady_state(system, forcing)
    ss = aj.steady_state(system, forcing, method=aj.Shooting(n=5, tol=1e-7))
    float(ss.amplitude), bool(ss.stable), ss.multipliers
    ```
    """
    require_x64("steady_state")
    check_system_and_forcing(system, forcing)
    method = method_from(method, "steady_state", legacy)
    integ = integrator_from(integrator, "periodic", "steady_state", legacy)
    no_more("steady_state", legacy)
    check_state("guess", guess, system.num_states)
    warn_scales(system, forcing, "steady_state")
    cfg = make_config(system, forcing, integ.solver, integ.rtol, integ.atol, integ.max_steps)
    g = None if guess is None else system.to_internal(jnp.asarray(guess, dtype=float))
    return _steady(system, forcing, g, cfg, method, bool(floquet))
