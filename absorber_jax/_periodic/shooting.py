"""Shooting: Newton on the period-``n`` map, ``Φ_{nT}(s) - s = 0``.

Newton's linear steps are solved by SVD (minimum norm): where the absorber floats without
touching the walls (or sticks, its relative position frozen), the orbits form a family,
``∂Φ/∂s - I`` is singular (a Floquet multiplier at exactly 1) and the minimum-norm step
converges to the member of the family nearest the guess.  Gradients of the orbit come from
the implicit function theorem on the shooting residual (optimistix ``ImplicitAdjoint``).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx

from .._core.checks import check_scalar
from .._core.status import Status
from .._integration.flow import period_map
from .._integration.rootfind import AbstractWrappedRootFinder
from .base import AbstractChainingMethod
from .orbit import finish_orbit, floquet_matrix, monodromy


def _keep_best(best, y, size, valid=True):
    """``best = (iterate, residual max-norm)`` with ``(y, size)`` in its place where
    ``size`` is smaller and counts: finite, and not the exact zero that ``_residual``
    gives for a failed integration (a true orbit's residual is never exactly zero, short of
    a rest state, where every iterate is one)."""
    better = valid & jnp.isfinite(size) & (size > 0) & (size < best[1])
    return (jax.tree_util.tree_map(lambda a, b: jnp.where(better, a, b), y, best[0]),
            jnp.where(better, size, best[1]))


class _GivesUp(AbstractWrappedRootFinder):
    """Wraps an optimistix Newton: it also stops, unconverged, once ``give_up`` steps have
    left its residual above ``far`` (max-norm): an iterate wandering that far after that
    many steps is not in Newton's basin, and a solve that will be retried (marching then
    shooting) loses nothing by stopping there."""

    solver: optx.AbstractRootFinder
    give_up: int = 8
    far: float = 1e-2

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        return self.solver.init(fn, y, args, options, f_struct, aux_struct, tags)

    def step(self, fn, y, args, options, state, tags):
        return self.solver.step(fn, y, args, options, state, tags)

    def terminate(self, fn, y, args, options, state, tags):
        done, result = self.solver.terminate(fn, y, args, options, state, tags)
        wander = (state.step >= self.give_up) & (self.norm(state.f) > self.far)
        return done | wander, optx.RESULTS.where(
            done, result, optx.RESULTS.where(wander, optx.RESULTS.nonlinear_divergence,
                                             result))

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        return self.solver.postprocess(fn, y, aux, args, options, state, tags, result)


class _KeepsBest(AbstractWrappedRootFinder):
    """Wraps an optimistix Newton or Chord (or ``_GivesUp`` around one): the iterate with
    the smallest residual evaluated is kept and returned, converged or not.

    A period map integrated adaptively is noisy at the integration tolerance (an accepted or
    rejected step near a contact moves the end state): on the Hunt–Crossley scene at 40
    rad/s (rtol 1e-9, contact smoothing 1 µm) Newton reaches residuals of 3e-8 .. 3e-6 and
    then wanders there, its steps (~1e-6) above its step tolerance; even a step below it
    can land on a residual of 3e-6.  The last iterate's residual is then a draw from that
    noise, above or below the shooting tolerance by chance (the rounding of one solver or
    another decided it); the best one is not.  A converged solve ends on an iterate whose
    residual is within ``atol`` (``0.1 tol`` in ``shoot``): the best one is at least
    that good, so the orbit meets ``tol`` with the same margin, though it forgoes the last
    (unevaluated) Newton step's further gain on a smooth map.  Unlike optimistix's
    ``BestSoFarRootFinder`` (best by the sum of squares), the exact zero residual that
    ``_residual`` gives for a failed integration never counts as best."""

    solver: optx.AbstractRootFinder

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        inner = self.solver.init(fn, y, args, options, f_struct, aux_struct, tags)
        return inner, (y, jnp.asarray(jnp.inf, dtype=jnp.result_type(float)))

    def step(self, fn, y, args, options, state, tags):
        inner, best = state
        y1, inner, aux = self.solver.step(fn, y, args, options, inner, tags)
        # the residual of this step's input y (f is evaluated there)
        return y1, (inner, _keep_best(best, y, self.norm(inner.f))), aux

    def terminate(self, fn, y, args, options, state, tags):
        return self.solver.terminate(fn, y, args, options, state[0], tags)

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        _, (best_y, best) = state
        y = jax.tree_util.tree_map(lambda a, b: jnp.where(jnp.isfinite(best), b, a), y, best_y)
        return y, aux, {}


def _root_solver(name, tol, give_up=None):
    if name == "newton":
        # Newton with a minimum-norm (SVD) step: quadratic convergence, and the singular
        # Jacobian of a floating absorber's orbit family is handled by the pseudo-inverse
        newton = optx.Newton(rtol=tol, atol=tol, linear_solver=lx.SVD())
        return _KeepsBest(newton if give_up is None else _GivesUp(newton, give_up))
    if name == "chord":
        # the Jacobian of the first iterate reused (one monodromy per solve instead of one
        # per Newton step): linear convergence, cheap where the state is large and the
        # guess close (a sweep seeded from its neighbour)
        return _KeepsBest(optx.Chord(rtol=tol, atol=tol, linear_solver=lx.SVD()))
    if name == "lm":
        return optx.LevenbergMarquardt(rtol=tol, atol=tol)
    raise ValueError(f"root solver must be 'newton', 'chord' or 'lm', got {name!r}")


def _residual(n, cfg):
    """The shooting residual ``Φ_{nT}(x) - x`` as a function of ``(x, (system, forcing))``."""

    def residual(x, args):
        sys_, forc_ = args
        xn, st = period_map(sys_, forc_, x, n, cfg)
        # a failed integration (max_steps, non-finite state) must not reach the linear solver
        # (lineax raises on NaN even with throw=False): give Newton a zero residual with a
        # zero Jacobian instead, so that it stops at once (a non-zero residual would make it
        # repeat the same failing, possibly max_steps-long integration newton_steps times);
        # the status below then flags the point
        bad = (st != Status.SUCCESS) | ~jnp.all(jnp.isfinite(xn))
        # (the flow's tangents are finite: see integrate_flow)
        return jnp.where(bad, jnp.zeros_like(x), xn - x)

    return residual


def shoot(system, forcing, x_guess, n, cfg, *, tol=1e-8, newton_steps=40, with_floquet=True,
          root="newton", give_up=None):
    """Shooting from the scaled guess ``x_guess`` for a period-``n`` orbit."""
    residual = _residual(n, cfg)
    solver = _root_solver(root, 0.1 * tol, give_up)
    # gradients of the orbit by the implicit function theorem on the shooting residual
    # (forward mode; the minimum-norm SVD solve copes with a floating absorber's null space)
    adjoint = optx.ImplicitAdjoint(linear_solver=lx.SVD())
    x_guess = jax.lax.stop_gradient(x_guess)
    if root in ("newton", "chord"):
        sol = optx.root_find(residual, solver, x_guess, (system, forcing), max_steps=newton_steps,
                             throw=False, adjoint=adjoint)
    else:
        sol = optx.least_squares(residual, solver, x_guess, (system, forcing),
                                 max_steps=newton_steps, throw=False, adjoint=adjoint)
    # the residual at the solution comes from the statistics' integration of the orbit (one
    # integration fewer: measured ~9 % of a vmapped Table 1 sweep)
    return finish_orbit(system, forcing, sol.value, n, cfg, None, None, sol.stats["num_steps"],
                   with_floquet, n_cap=n, tol=tol)


def _broyden(residual, x0, H0, args, tol, steps):
    """Quasi-Newton iterations ``x <- x - H r(x)`` from the inverse-Jacobian guess ``H0``,
    ``H`` improved by Broyden's ("good") rank-one update after every step, until a step is
    within ``tol`` (max-norm).  Returns the iterate after that last step, or, when the
    budget ran out first (or the last residual came from a failed integration), the
    iterate with the smallest residual evaluated (as ``_KeepsBest``: the period map is
    noisy at the integration tolerance); and the number of steps.  (The iterate after a
    step within ``tol`` is kept rather than the one it started from: its residual, up to
    ``|H^-1| tol``, may exceed the shooting tolerance that the one after meets.)  With the
    exact Jacobian inverse it is Newton; with a neighbour's it converges superlinearly
    where the plain chord (``H`` kept) converges linearly or not at all (a coarse
    frequency grid)."""

    def cond(c):
        k, done = c[4], c[5]
        return (k < steps) & ~done

    def update(x1, dx, r, H):
        r1 = residual(x1, args)
        dr = r1 - r
        Hdr = H @ dr
        den = dx @ Hdr
        ok = jnp.abs(den) > 1e-300
        H1 = H + jnp.outer(dx - Hdr, dx @ H) / jnp.where(ok, den, 1.0)
        return r1, jnp.where(ok & jnp.all(jnp.isfinite(H1)), H1, H)

    def body(c):
        x, r, H, best, k, _ = c
        dx = -H @ r
        x1 = x + dx
        done = jnp.max(jnp.abs(dx)) <= tol
        # the last step (within tol) needs no residual: the orbit's own integration follows
        # (run lane by lane, this saves one period integration per point; vmapped, cond
        # runs both branches)
        # a failed integration gives a zero residual (see _residual): the step is zero next
        r1, H1 = jax.lax.cond(done, lambda: (r, H), lambda: update(x1, dx, r, H))
        best = _keep_best(best, x1, jnp.max(jnp.abs(r1)), ~done)
        return x1, r1, H1, best, k + 1, done

    r0 = residual(x0, args)
    best = _keep_best((x0, jnp.asarray(jnp.inf, dtype=r0.dtype)), x0, jnp.max(jnp.abs(r0)))
    x, r, _, best, k, done = jax.lax.while_loop(
        cond, body, (x0, r0, H0, best, jnp.asarray(0), jnp.asarray(False)))
    # a zero step after a failed integration's zero residual is no convergence
    keep_last = done & ~(jnp.all(r == 0) & jnp.isfinite(best[1]))
    return jnp.where(keep_last, x, best[0]), k


def shoot_chord(system, forcing, x_guess, jacobian, n, cfg, *, tol=1e-8, steps=40,
                with_floquet=True):
    """Shooting from a given Jacobian of the period map (scaled): quasi-Newton steps
    ``x <- x - H r(x)`` from ``H = (J - I)^+`` (minimum-norm, as the SVD steps of
    ``shoot``), Broyden-updated (``_broyden``), until a step is within ``0.1 tol``.
    Returns the ``SteadyState`` and the Jacobian the next solve along a sweep may
    reuse: the Floquet monodromy at the orbit when it was computed and the orbit converged,
    else the Jacobian given.

    A sweep hands each point its neighbours' orbit and monodromy (``Shooting.chains``;
    extrapolated from the last two): the monodromy at an orbit serves its Floquet
    multipliers *and* the next points' start, one
    monodromy per point where ``shoot`` with ``root="chord"`` computes two (at the guess,
    at the orbit)."""
    residual = _residual(n, cfg)
    x_guess = jax.lax.stop_gradient(x_guess)
    H0 = jnp.linalg.pinv(jacobian - jnp.eye(x_guess.shape[0]))
    x, k = _broyden(residual, x_guess, H0, (system, forcing), 0.1 * tol, steps)
    mono, mult = (floquet_matrix(system, forcing, x, n, cfg, unroll=True) if with_floquet
                  else (None, None))
    res = finish_orbit(system, forcing, x, n, cfg, None, None, k, with_floquet, n_cap=n, tol=tol,
                  multipliers=mult)
    if mono is None:
        return res, jacobian
    return res, jnp.where(res.status == Status.SUCCESS, mono, jacobian)


class Shooting(AbstractChainingMethod):
    """Newton shooting on the period-``n`` map (minimum-norm SVD steps).

    **Arguments**

    - ``n``: period multiple sought (1 = the forcing period).
    - ``tol``: residual tolerance on the state scaled to order one (the period map of an
      impacting orbit is accurate to ~1e-7 at the default rtol, which bounds what Newton
      can reach).
    - ``newton_steps``: Newton iteration budget.
    - ``root``: ``"newton"`` (minimum-norm SVD steps), ``"chord"`` (the first Jacobian
      reused: one monodromy per solve, for large structural states with close guesses; in
      a parallel sweep the points run in lanes of neighbours, each from the previous orbits
      with the previous Floquet monodromies as its Jacobian (extrapolated from the last
      two), improved by Broyden updates) or ``"lm"`` (Levenberg–Marquardt).
    - ``retry``: a failed solve is retried by marching from rest and polishing the marched
      orbit by shooting, before it is flagged.
    - ``give_up``: with ``root="newton"``, stop after this many Newton steps if the scaled
      residual is still above 1e-2 (an iterate wandering outside Newton's basin); None:
      use the whole budget.  ``steady_state`` sets 8 when it will retry, so that the
      marching retry starts at once (LuGre with sigma0 = 1e8 and |v| smoothed at eps = 1e-4: 40
      wandering steps cost 50 s).
    """

    n: int = eqx.field(static=True, default=1)
    tol: float = eqx.field(static=True, default=1e-6)
    newton_steps: int = eqx.field(static=True, default=40)
    root: str = eqx.field(static=True, default="newton")
    retry: bool = eqx.field(static=True, default=True)
    give_up: int | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        if not isinstance(self.n, int) or not 1 <= self.n <= 64:
            raise ValueError(f"Shooting.n must be an integer in [1, 64], got {self.n!r}")
        check_scalar("Shooting", "tol", self.tol, lo=0.0, lo_open=True)
        if not isinstance(self.newton_steps, int) or self.newton_steps < 1:
            raise ValueError("Shooting.newton_steps must be a positive integer, got "
                             f"{self.newton_steps!r}")
        _root_solver(self.root, 1.0)
        if self.give_up is not None and (not isinstance(self.give_up, int)
                                         or self.give_up < 1):
            raise ValueError("Shooting.give_up must be None or a positive integer, got "
                             f"{self.give_up!r}")

    def initial_state(self, system, forcing):
        return system.linear_guess(forcing)

    def _first_steps(self, budget):
        # a chord step is one integration without tangents (~1/25 of a Newton step on the
        # 44-state building of scripts/benchmark_structure.py) and converges linearly: its
        # first pass takes 4x the Newton budget before a lane counts as a straggler (8x is
        # slower: 40.8 s against 19.7 s on 64 points of that building, the lanes resumed with a
        # fresh Jacobian converge in fewer steps than those left on the first one)
        return budget * (4 if self.root == "chord" else 1)

    def first_pass(self, budget):
        return dataclasses.replace(self, newton_steps=min(self.newton_steps,
                                                          self._first_steps(budget)))

    def giving_up(self, steps):
        if not self.retry or self.root != "newton" or self.give_up is not None:
            return self
        return dataclasses.replace(self, give_up=min(steps, self.newton_steps))

    def resume(self, budget):
        used = self._first_steps(budget)
        if self.newton_steps <= used:
            return None
        return dataclasses.replace(self, newton_steps=self.newton_steps - used)

    @property
    def chains(self):
        # the chord reuses a Jacobian: along a sweep, the neighbour's monodromy
        return self.root == "chord"

    def chain_jacobian(self, system, forcing, x0, cfg):
        return monodromy(system, forcing, x0, self.n, cfg)

    def solve_chained(self, system, forcing, x0, jacobian, cfg, *, with_floquet=True):
        return shoot_chord(system, forcing, x0, jacobian, self.n, cfg, tol=self.tol,
                           steps=self.newton_steps, with_floquet=with_floquet)

    def solve(self, system, forcing, x0, cfg, *, with_floquet=True):
        return shoot(system, forcing, x0, self.n, cfg, tol=self.tol,
                     newton_steps=self.newton_steps, with_floquet=with_floquet, root=self.root,
                     give_up=self.give_up)
