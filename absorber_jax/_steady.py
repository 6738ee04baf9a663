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
  (:func:`march_then_shoot`).  The monodromy matrix is
  ``jax.jacfwd`` of ``Φ`` (diffrax ``ForwardMode``); its eigenvalues are the Floquet
  multipliers.
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

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx

from ._checks import check_scalar, check_state, is_traced, require_x64
from ._forcing import Harmonic
from ._linear import linear_guess
from ._simulate import _resolve_solver
from ._status import Status, from_diffrax
from ._stickslip import SEGMENTS_PER_PERIOD, hybrid_solve
from ._system import AbstractAbsorberSystem

SAMPLES_PER_PERIOD = 256
# stick–slip segments allowed in one integration (the loop ends at t1 long before, unless
# the motion chatters)
MAX_SEGMENTS = SEGMENTS_PER_PERIOD * 64


class SteadyState(eqx.Module):
    """A periodic response (see the module docstring for the definitions).

    ``state``: public state ``[x1, v1, x2, v2, (z)]`` on the orbit at ``t = 0 mod nT``;
    ``multipliers``: Floquet multipliers of the period-``nT`` map; ``stable``: all
    ``|μ| <= 1 + 1e-6``, except, on an orbit where the absorber floats without touching the
    walls, the structural double multiplier 1 of its free position;
    ``status``: :class:`Status`; ``iterations``: Newton steps (shooting) or periods marched.
    """

    amplitude: jax.Array
    rms: jax.Array
    harmonic: jax.Array
    absorber_amplitude: jax.Array
    absorber_rms: jax.Array
    period_multiple: jax.Array
    state: jax.Array
    multipliers: jax.Array
    stable: jax.Array
    status: jax.Array
    residual: jax.Array
    iterations: jax.Array

    @property
    def ok(self):
        return self.status == Status.SUCCESS


class _Config(eqx.Module):
    solver: diffrax.AbstractSolver
    rtol: float = eqx.field(static=True)
    atol: float = eqx.field(static=True)
    max_steps: int = eqx.field(static=True)
    # derivatives of the flow by sensitivity equations whose steps are controlled on the
    # tangents too (explicit solvers on stiff-ish scenes, see make_config)
    tangent_control: bool = eqx.field(static=True, default=False)


# An explicit solver's monodromy is taken from sensitivity equations with steps controlled on
# the tangents as well as the state once (largest linearised rate × period) exceeds this.
# Below it, diffrax ForwardMode (state-controlled steps, ~4x cheaper) is right; above it
# the stiff direction has decayed in the state, so the state's error estimate lets the steps
# reach the edge of the explicit stability region, where the O(1) tangent seeded in that
# direction grows: the stick–slip case (smoothed Coulomb eps = 1e-4, 70 rad/s, λT =
# 2e4) had |μ| = 1e66 from shooting and 2.8e9 from marching on a stable orbit (|μ| = 0.86).
TANGENT_CONTROL_STEPS_PER_PERIOD = 2.0e3


def state_scale(system, forcing):
    """Per-component scale of the internal state (the system's own, see
    :meth:`AbstractAbsorberSystem.state_scale`)."""
    return system.state_scale(forcing)


def _scaled_rate(dyn, t, x):
    system, forcing = dyn
    scale = state_scale(system, forcing)
    return system.vector_field(t, x * scale, forcing) / scale


def _diffeqsolve(rate, x0, t0, t1, ts, cfg, norm=optx.rms_norm):
    saveat = diffrax.SaveAt(t1=True) if ts is None else diffrax.SaveAt(ts=ts)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(rate), cfg.solver, t0, t1, None, x0, saveat=saveat,
        stepsize_controller=diffrax.PIDController(rtol=cfg.rtol, atol=cfg.atol, norm=norm),
        max_steps=cfg.max_steps, throw=False, adjoint=diffrax.ForwardMode(),
    )
    return sol.ys, from_diffrax(sol.result)


def _integrate(dyn, x0, t0, t1, ts, cfg):
    """Scaled states of ``dyn`` from ``x0`` at ``t0`` saved at ``ts`` (or at ``t1`` only when
    ``ts`` is None), and the status: smooth systems by one diffrax solve, hybrid ones
    (exact stick–slip) segment by segment (:mod:`absorber_jax._stickslip`)."""
    system, forcing = dyn
    if system.hybrid:
        ys, x, status, _, _ = hybrid_solve(
            system, forcing, x0, t0, t1, ts, solver=cfg.solver, rtol=cfg.rtol, atol=cfg.atol,
            max_steps=cfg.max_steps, scale=state_scale(system, forcing),
            max_segments=MAX_SEGMENTS)
        return (x[None] if ts is None else ys), status
    return _diffeqsolve(lambda t, x, a: _scaled_rate(dyn, t, x), x0, t0, t1, ts, cfg)


def _flow(dyn, x0, t1, ts, *, cfg):
    """Scaled states of ``dyn = (system, forcing)`` from ``x0`` at ``t = 0`` saved at ``ts``
    (or at ``t1`` only when ``ts`` is None), and the integrator's status; differentiable in
    forward mode (shooting's Jacobian, Floquet multipliers, design gradients).

    An explicit solver is differentiated through its steps (diffrax ``ForwardMode``: the
    state is integrated once, its tangents ride along).  An implicit solver is not, see
    :func:`_flow_sensitivity`."""
    implicit = isinstance(cfg.solver, diffrax.AbstractImplicitSolver)
    if (implicit or cfg.tangent_control) and not dyn[0].hybrid:
        return _flow_sensitivity(dyn, x0, t1, ts, cfg=cfg)
    return _integrate(dyn, x0, 0.0, t1, ts, cfg)


@eqx.filter_custom_jvp
def _flow_sensitivity(dyn, x0, t1, ts, *, cfg):
    """:func:`_flow` for implicit solvers.  Its derivatives (in ``x0``, the system's and
    forcing's parameters and the times) are the forward sensitivity equations
    ``δẋ = ∂f/∂x δx + ∂f/∂p δp``, integrated together with the state by the same solver
    (steps controlled on the state), rather than derivatives of the solver's internals: no
    derivative ever passes through an implicit solver's stage Newton solve (whose
    forward-mode derivative raises inside lineax when a trial stage diverges, as on LuGre
    with sigma0 >= 1e6).  Explicit solvers keep diffrax's ``ForwardMode``, which integrates
    the state once for all tangent directions."""
    return _diffeqsolve(lambda t, x, a: _scaled_rate(dyn, t, x), x0, 0.0, t1, ts, cfg)


@_flow_sensitivity.def_jvp
def _flow_sensitivity_jvp(primals, tangents, *, cfg):
    dyn, x0, t1, ts = primals
    t_dyn, t_x0, t_t1, t_ts = tangents
    # the primal comes from its own state-only solve: jax.linearize (Newton) needs primal
    # outputs computable without the tangents
    ys, status = _flow_sensitivity(dyn, x0, t1, ts, cfg=cfg)
    t_x0 = jnp.zeros_like(x0) if t_x0 is None else t_x0

    def augmented(t, y, a):
        x, dx = y
        # the sensitivity rate is linear in dx; its dependence on x is hidden from the
        # implicit solver's Jacobian (stop_gradient), which is then block-diagonal: the
        # second derivatives of the contact law (singular for Hertz at first contact) would
        # otherwise stall the stage Newton iterations
        _, df = eqx.filter_jvp(lambda x_, d_: _scaled_rate(d_, t, x_),
                               (jax.lax.stop_gradient(x), dyn), (dx, t_dyn))
        return _scaled_rate(dyn, t, x), df

    # steps controlled on the state only: the sensitivities ride along, as in forward mode
    # (explicit solvers with tangent_control: on the state and the tangents)
    norm = optx.rms_norm if cfg.tangent_control else (lambda e: optx.rms_norm(e[0]))
    (_, dys), st2 = _diffeqsolve(augmented, (x0, t_x0), 0.0, t1, ts, cfg, norm=norm)
    # moving save times (they depend on the forcing period): add the state's rate there
    t_save, t_times = (t1[None], t_t1) if ts is None else (ts, t_ts)
    if t_times is not None:
        f = jax.vmap(lambda t, x: _scaled_rate(dyn, t, x))(t_save, ys)
        dys = dys + f * jnp.reshape(t_times, (-1, 1))
    # a sensitivity integration that failed gives no derivative (the status flags the point)
    dys = jnp.where((st2 == Status.SUCCESS) & jnp.isfinite(dys), dys, 0.0)
    return (ys, status), (dys, None)


def period_map(system, forcing, x0, n, cfg: _Config, t0=0.0):
    """Scaled state after ``n`` forcing periods from ``t = 0``, and the integrator's status
    (``t0`` must be a multiple of the forcing period)."""
    del t0
    T = 2 * jnp.pi / forcing.omega
    ys, status = _flow((system, forcing), x0, n * T, None, cfg=cfg)
    return ys[-1], status


def _parabolic_peak(y, i):
    """Extreme value of the periodic samples ``y`` near index ``i`` (parabola through 3)."""
    n = y.shape[0]
    a, b, c = y[(i - 1) % n], y[i], y[(i + 1) % n]
    den = a - 2 * b + c
    return b - 0.125 * (a - c) ** 2 / jnp.where(den == 0, 1.0, den) * (den != 0)


def _half_p2p(y):
    return 0.5 * (_parabolic_peak(y, jnp.argmax(y)) - _parabolic_peak(y, jnp.argmin(y)))


def orbit_statistics(system, forcing, x0, n, cfg, n_cap=1):
    """Amplitudes over one response period ``nT`` starting from scaled state ``x0``
    (``n`` may be traced; ``n_cap`` is its static upper bound)."""
    scale = state_scale(system, forcing)
    T = 2 * jnp.pi / forcing.omega
    N = SAMPLES_PER_PERIOD * n_cap
    ts = jnp.arange(N) * (n * T / N)
    ys, st = _flow((system, forcing), x0, n * T, ts, cfg=cfg)
    s = ys * scale
    x1, u = s[:, 0], s[:, 2]
    phase = jnp.exp(-1j * forcing.omega * ts)
    harmonic = 2.0 * jnp.abs(jnp.mean(x1 * phase))
    stats = dict(amplitude=_half_p2p(x1), rms=jnp.sqrt(jnp.mean(x1**2)), harmonic=harmonic,
                 absorber_amplitude=_half_p2p(u), absorber_rms=jnp.sqrt(jnp.mean(u**2)))
    return stats, st, jnp.max(jnp.abs(u))


def floquet(system, forcing, x0, n, cfg):
    """Floquet multipliers (eigenvalues of the monodromy matrix, by forward-mode AD)."""
    J = jax.jacfwd(lambda x: period_map(system, forcing, x, n, cfg)[0])(x0)
    return jnp.linalg.eigvals(jax.lax.stop_gradient(J))


def _finish(system, forcing, x, n, cfg, status, residual, iterations, with_floquet=True,
            n_cap=1):
    scale = state_scale(system, forcing)
    stats, st2, umax = orbit_statistics(system, forcing, x, n, cfg, n_cap)
    if with_floquet:
        mult = floquet(system, forcing, x, n, cfg)
    else:
        mult = jnp.full((system.num_states,), jnp.nan + 0j)
    # an absorber floating without touching the walls: its free position and velocity give a
    # structural double multiplier 1 (a Jordan block, split by ~sqrt(rounding) numerically);
    # stability is judged on the other multipliers
    floating = system.floats(umax)
    dist = jnp.abs(mult - 1.0)
    structural = floating & (dist <= jnp.sort(dist)[1]) & (dist < 1e-2)
    status = jnp.where(status == Status.SUCCESS, st2, status)
    vals = jnp.stack([stats[k] for k in stats])
    finite = jnp.all(jnp.isfinite(vals)) & jnp.all(jnp.isfinite(x))
    status = jnp.where((status == Status.SUCCESS) & ~finite, Status.NONFINITE, status)
    # a failed point (or multipliers not computed) is never called stable
    stable = (jnp.all((jnp.abs(mult) <= 1.0 + 1e-6) | structural) & (status == Status.SUCCESS)
              & jnp.all(jnp.isfinite(mult)))
    return SteadyState(**stats, period_multiple=jnp.asarray(n), state=system.to_public(x * scale),
                       multipliers=mult, stable=stable, status=status, residual=residual,
                       iterations=jnp.asarray(iterations))


@jax.custom_jvp
def _finite_tangents(y):
    return y


@_finite_tangents.defjvp
def _finite_tangents_jvp(primals, tangents):
    # a non-finite tangent (an integration gone wrong at a trial Newton iterate) becomes 0, so
    # the linear solve sees finite input; the iterate then fails to converge and is flagged
    (y,), (dy,) = primals, tangents
    return y, jnp.where(jnp.isfinite(dy), dy, 0.0)


def _root_solver(name, tol):
    if name == "newton":
        # Newton with a minimum-norm (SVD) step: quadratic convergence, and the singular
        # Jacobian of a floating absorber's orbit family is handled by the pseudo-inverse
        return optx.Newton(rtol=tol, atol=tol, linear_solver=lx.SVD())
    if name == "lm":
        return optx.LevenbergMarquardt(rtol=tol, atol=tol)
    raise ValueError(f"root solver must be 'newton' or 'lm', got {name!r}")


def shoot(system, forcing, x_guess, n, cfg, *, tol=1e-8, newton_steps=40, with_floquet=True,
          root="newton"):
    """Shooting from the scaled guess ``x_guess`` for a period-``n`` orbit."""

    def residual(x, args):
        sys_, forc_ = args
        xn, st = period_map(sys_, forc_, x, n, cfg)
        # a failed integration (max_steps, non-finite state) must not reach the linear solver
        # (lineax raises on NaN even with throw=False): give Newton a zero residual with a
        # zero Jacobian instead, so that it stops at once (a non-zero residual would make it
        # repeat the same failing, possibly max_steps-long integration newton_steps times);
        # the status below then flags the point
        bad = (st != Status.SUCCESS) | ~jnp.all(jnp.isfinite(xn))
        return _finite_tangents(jnp.where(bad, jnp.zeros_like(x), xn - x))

    solver = _root_solver(root, 0.1 * tol)
    # gradients of the orbit by the implicit function theorem on the shooting residual
    # (forward mode; the minimum-norm SVD solve copes with a floating absorber's null space)
    adjoint = optx.ImplicitAdjoint(linear_solver=lx.SVD())
    x_guess = jax.lax.stop_gradient(x_guess)
    if root == "newton":
        sol = optx.root_find(residual, solver, x_guess, (system, forcing), max_steps=newton_steps,
                             throw=False, adjoint=adjoint)
    else:
        sol = optx.least_squares(residual, solver, x_guess, (system, forcing),
                                 max_steps=newton_steps, throw=False, adjoint=adjoint)
    x = sol.value
    xn, st = period_map(system, forcing, x, n, cfg)
    res = jnp.max(jnp.abs(xn - x))
    status = jnp.where(st != Status.SUCCESS, st,
                       jnp.where(res <= tol, Status.SUCCESS, Status.NO_CONVERGENCE))
    return _finish(system, forcing, x, n, cfg, status, res, sol.stats["num_steps"], with_floquet,
                   n_cap=n)


def march(system, forcing, x0, cfg, *, n_max=6, tol=1e-6, max_periods=4000, chunk=40,
          with_floquet=True):
    """March from scaled state ``x0`` until the Poincaré samples repeat with period ``n``."""
    H = n_max + 2
    T = 2 * jnp.pi / forcing.omega
    ns = jnp.arange(1, n_max + 1)

    def distances(buf):
        # d_n = max over the last two samples of |P_k - P_{k-n}|
        last = buf[-1][None] - buf[-1 - ns]
        prev = buf[-2][None] - buf[-2 - ns]
        return jnp.maximum(jnp.max(jnp.abs(last), axis=1), jnp.max(jnp.abs(prev), axis=1))

    def body(c):
        t, x, buf, d_prev, d_prev2, k, _, _, _ = c
        ts = t + T * jnp.arange(1, chunk + 1)
        ys, st = _integrate((system, forcing), x, t, ts[-1], ts, cfg)
        buf = jnp.concatenate([buf, ys])[-H:]
        d = distances(buf)
        # contraction per period, judged pessimistically over one and two chunks (the ratio
        # of one chunk is noisy once d nears the integration noise), and the tail estimate
        tiny = 1e-300
        r1 = (d / jnp.maximum(d_prev, tiny)) ** (1.0 / chunk)
        r2 = (d / jnp.maximum(d_prev2, tiny)) ** (0.5 / chunk)
        rho = jnp.clip(jnp.maximum(r1, r2), 0.0, 0.999999)
        rho_n = rho**ns
        tail = d * rho_n / (1 - rho_n)
        ok = (d < tol) & (tail < tol) & (k > 1)
        found = jnp.any(ok)
        n_found = ns[jnp.argmax(ok)]
        # the smallest period consistent with the samples: a decaying transient can let a
        # multiple of the true period pass first; a genuine period-n orbit has d_m of the
        # orbit's size for the divisors m of n, so accept any divisor within 50x of d_n
        d_n = d[n_found - 1]
        divides = (n_found % ns) == 0
        near = divides & (d <= jnp.maximum(50 * d_n, 10 * tol))
        n = jnp.where(found, ns[jnp.argmax(near)], 0)
        return (ts[-1], ys[-1], buf, d, d_prev, k + 1, found, n, st)

    def cond(c):
        _, _, _, _, _, k, found, _, st = c
        return (~found) & (k * chunk < max_periods) & (st == Status.SUCCESS)

    buf0 = jnp.tile(x0[None], (H, 1)) + jnp.inf  # no history yet
    inf = jnp.full((n_max,), jnp.inf)
    c0 = (jnp.zeros(()), x0, buf0, inf, inf, jnp.zeros((), int), jnp.zeros((), bool),
          jnp.zeros((), int), jnp.asarray(Status.SUCCESS))
    t, x, buf, d, _, k, found, n, st = jax.lax.while_loop(cond, body, c0)
    # restart the orbit at phase 0 (t is a multiple of T; the forcing is T-periodic)
    periodic_like = jnp.min(d) < 1e3 * tol
    status = jnp.where(st != Status.SUCCESS, st,
                       jnp.where(found, Status.SUCCESS,
                                 jnp.where(periodic_like, Status.NO_CONVERGENCE,
                                           Status.NOT_PERIODIC)))
    n_eff = jnp.where(found, n, 1)
    res = jnp.where(found, d[n_eff - 1], jnp.min(d))
    return _finish(system, forcing, x, n_eff, cfg, status, res, k * chunk, with_floquet,
                   n_cap=n_max)


def march_then_shoot(system, forcing, cfg, *, n, tol, newton_steps, n_max=6, march_tol=1e-5,
                     max_periods=4000, chunk=40, with_floquet=True, root="newton"):
    """The robust fallback of a shooting solve that failed: march from rest onto the orbit
    the structure settles on, then polish it by shooting from there (Newton converges in
    one or two steps from a marched state).  The shooting result is kept when it converged
    with the marched period multiple ``n``; otherwise marching's own result.

    Newton from the linear guess is not globally convergent on the piecewise-smooth period
    map of a sticking absorber (it wanders for 40 steps); marching is, for a stable orbit."""
    x0 = system.rest_state() / state_scale(system, forcing)
    ma = march(system, forcing, x0, cfg, n_max=n_max, tol=march_tol, max_periods=max_periods,
               chunk=chunk, with_floquet=with_floquet)
    xm = system.to_internal(ma.state) / state_scale(system, forcing)
    xm = jnp.where(jnp.all(jnp.isfinite(xm)), xm, x0)
    sh = shoot(system, forcing, xm, n, cfg, tol=tol, newton_steps=newton_steps,
               with_floquet=with_floquet, root=root)
    use_shot = (sh.status == Status.SUCCESS) & ((ma.status != Status.SUCCESS)
                                                | (ma.period_multiple == n))
    out = jax.tree_util.tree_map(lambda a, b: jnp.where(use_shot, a, b), sh, ma)
    return eqx.tree_at(lambda r: r.iterations, out, sh.iterations + ma.iterations)


def _check(system, forcing):
    if not isinstance(system, AbstractAbsorberSystem):
        raise ValueError(f"system must be an ImpactAbsorber or FrictionAbsorber, got "
                         f"{type(system).__name__}")
    if not isinstance(forcing, Harmonic):
        raise ValueError("steady_state needs a periodic forcing: forcing must be a Harmonic, "
                         f"got {type(forcing).__name__}")


def make_config(system, forcing, solver=None, rtol=1e-9, atol=1e-9, max_steps=200_000):
    _, solver_obj = _resolve_solver(solver, system, forcing)
    explicit = not isinstance(solver_obj, diffrax.AbstractImplicitSolver)
    lam, period = system.stiffness_rate(), forcing.period
    stiffish = (not is_traced(lam) and not is_traced(period)
                and float(lam) * float(period) > TANGENT_CONTROL_STEPS_PER_PERIOD)
    return _Config(solver=solver_obj, rtol=float(rtol), atol=float(atol), max_steps=int(max_steps),
                   tangent_control=bool(explicit and stiffish and not system.hybrid))


@eqx.filter_jit
def _steady_jit(system, forcing, guess, cfg, method, n, n_max, tol, newton_steps,
                max_periods, chunk, with_floquet, root, retry):
    scale = state_scale(system, forcing)
    if guess is None:
        x0 = linear_guess(system, forcing) / scale if method == "shooting" else \
            system.rest_state() / scale
    else:
        x0 = system.to_internal(guess) / scale
    if method == "shooting":
        res = shoot(system, forcing, x0, n, cfg, tol=tol, newton_steps=newton_steps,
                    with_floquet=with_floquet, root=root)
        if not retry:
            return res
        # a failed point is retried by marching then polishing (runs only when needed)
        return jax.lax.cond(
            res.status == Status.SUCCESS, lambda: res,
            lambda: march_then_shoot(system, forcing, cfg, n=n, tol=tol,
                                     newton_steps=newton_steps, n_max=n_max,
                                     max_periods=max_periods, chunk=chunk,
                                     with_floquet=with_floquet, root=root))
    return march(system, forcing, x0, cfg, n_max=n_max, tol=tol, max_periods=max_periods,
                 chunk=chunk, with_floquet=with_floquet)


def steady_state(system, forcing, *, method="shooting", n=1, guess=None, n_max=6, tol=None,
                 solver=None, rtol=1e-9, atol=1e-9, max_steps=200_000, newton_steps=40,
                 max_periods=4000, chunk=40, floquet=True, root="newton",
                 retry=True) -> SteadyState:
    """The periodic response of ``system`` under a :class:`Harmonic` ``forcing``.

    **Arguments**

    - ``method``: ``"shooting"`` (Newton on the period-``n`` map from ``guess``,
      default the linear limit of the scene, see :func:`linear_guess`) or ``"marching"``
      (integrate from ``guess``, default rest, until the Poincaré samples repeat with a
      period ``n <= n_max``).
    - ``n``: period multiple sought by shooting (1 = the forcing period).
    - ``guess``: public state ``[x1, v1, x2, v2, (z)]`` at ``t = 0``.
    - ``tol``: on the state scaled to order one: shooting residual (default 1e-6) or the
      Poincaré recurrence and tail estimate of marching (1e-5). The period map of an
      impacting orbit is accurate to ~1e-7 at the default rtol (global error over ~1000
      steps), which bounds what Newton can reach.
    - ``solver``, ``rtol``, ``atol``, ``max_steps``: integrator settings (scaled state).
    - ``newton_steps``; ``max_periods``, ``chunk`` (marching budget and Poincaré chunk).
    - ``floquet``: compute the Floquet multipliers (one forward-mode Jacobian).
    - ``root``: shooting's solver, ``"newton"`` (minimum-norm SVD steps) or ``"lm"``
      (Levenberg–Marquardt).
    - ``retry``: shooting that fails is retried by marching from rest and polishing the
      marched orbit by shooting (:func:`march_then_shoot`) before the point is flagged;
      ``iterations`` then counts Newton steps plus periods marched.

    **Returns** a :class:`SteadyState`; check ``status`` (0 = success).

    ```python
    import absorber_jax as aj
    system, forcing = aj.presets.impact("kelvin_voigt", omega=60.0)
    ss = aj.steady_state(system, forcing)
    float(ss.amplitude), bool(ss.stable), ss.multipliers
    ```
    """
    require_x64("steady_state")
    _check(system, forcing)
    if method not in ("shooting", "marching"):
        raise ValueError(f"method must be 'shooting' or 'marching', got {method!r}")
    if not isinstance(n, int) or not 1 <= n <= 64:
        raise ValueError(f"n must be an integer in [1, 64], got {n!r}")
    if not isinstance(n_max, int) or not 1 <= n_max <= 64:
        raise ValueError(f"n_max must be an integer in [1, 64], got {n_max!r}")

    check_state("guess", guess, system.num_states)
    tol = (1e-6 if method == "shooting" else 1e-5) if tol is None else tol
    check_scalar("steady_state", "tol", tol, lo=0.0, lo_open=True)
    cfg = make_config(system, forcing, solver, rtol, atol, max_steps)
    g = None if guess is None else jnp.asarray(guess, dtype=float)
    _root_solver(root, 1.0)
    return _steady_jit(system, forcing, g, cfg, method, n, n_max, float(tol), int(newton_steps),
                       int(max_periods), int(chunk), bool(floquet), root, bool(retry))
