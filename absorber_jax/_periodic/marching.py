"""Marching: integrate forward in chunks of periods and sample the Poincaré section
``t = kT`` until, for the smallest ``n <= n_max``, the samples repeat with period ``n`` to
within ``tol`` *and* the estimated distance to the limit (a geometric tail ``d ρ/(1-ρ)``
from the observed contraction ``ρ``) is below ``tol`` too: slow transients (a multiplier of
0.994 per period) are not mistaken for convergence.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._core.checks import check_scalar
from .._core.status import Status
from .._integration.flow import integrate
from .base import AbstractSinglePassMethod
from .orbit import _no_gradient, finish_orbit, implicit_orbit

# a response whose closest recurrence min_n d_n is below this many tol is near periodic: a
# march that ends there is NO_CONVERGENCE (not NOT_PERIODIC), and give_up lets it march on
NEAR_PERIODIC = 1e3


def march(system, forcing, x0, cfg, *, n_max=6, tol=1e-6, max_periods=4000, chunk=40,
          give_up=None, with_floquet=True):
    """March from scaled state ``x0`` until the Poincaré samples repeat with period ``n``
    (or, with ``give_up``, until the response is seen not to settle within the budget:
    ``Marching``).  The loop is not differentiated: the orbit's derivatives are the
    implicit function theorem's at the marched fixed point (``implicit_orbit``)."""
    dyn_in = (system, forcing)
    system, forcing, x0 = _no_gradient((system, forcing, x0))
    H = n_max + 2
    T = 2 * jnp.pi / forcing.omega
    ns = jnp.arange(1, n_max + 1)

    def distances(buf):
        # d_n = max over the last two samples of |P_k - P_{k-n}|
        last = buf[-1][None] - buf[-1 - ns]
        prev = buf[-2][None] - buf[-2 - ns]
        return jnp.maximum(jnp.max(jnp.abs(last), axis=1), jnp.max(jnp.abs(prev), axis=1))

    def body(c):
        t, x, buf, d_prev, d_prev2, k, _, _, _, best, (d_first, p_first), _ = c
        ts = t + T * jnp.arange(1, chunk + 1)
        ys, st = integrate((system, forcing), x, t, ts[-1], ts, cfg.over_periods(chunk))
        # the section sample closest to its own image one period later, in the second half
        # of the budget (after the transient): where a response that never settles passes
        # nearest a period-1 orbit, the start that a failed march hands to shooting
        ret = jnp.max(jnp.abs(ys - jnp.concatenate([buf[-1:], ys[:-1]])), axis=1)
        late = 2 * (k + 1) * chunk > (max_periods if give_up is None else give_up)
        ret = jnp.where(late & jnp.all(jnp.isfinite(ys), axis=1), ret, jnp.inf)
        i = jnp.argmin(ret)
        best = jax.tree_util.tree_map(lambda a, b: jnp.where(ret[i] < best[0], a, b),
                                      (ret[i], ys[i]), best)
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
        # hopeless (give_up): the closest recurrence, at its average contraction per period
        # since it was first measured, would still be above 10 tol when the budget runs out
        marched = (k + 1) * chunk
        d_min = jnp.min(d)
        first = ~jnp.isfinite(d_first)
        d_first = jnp.where(first, d_min, d_first)
        p_first = jnp.where(first, marched, p_first)
        rho_avg = (d_min / jnp.maximum(d_first, 1e-300)) ** (
            1.0 / jnp.maximum(marched - p_first, 1))
        reach = d_min * jnp.minimum(rho_avg, 1.0) ** (max_periods - marched)
        # (a response already near periodic, min_n d_n < 1e3 tol, as a floating absorber's
        # slowly drifting family, marches on: more periods still sharpen its statistics)
        hopeless = (jnp.asarray(False) if give_up is None else
                    (marched >= give_up) & ~found & ~(reach < 10 * tol)
                    & ~(d_min < NEAR_PERIODIC * tol))
        return (ts[-1], ys[-1], buf, d, d_prev, k + 1, found, n, st, best, (d_first, p_first),
                hopeless)

    def cond(c):
        _, _, _, _, _, k, found, _, st, _, _, hopeless = c
        return (~found) & (k * chunk < max_periods) & (st == Status.SUCCESS) & ~hopeless

    buf0 = jnp.tile(x0[None], (H, 1)) + jnp.inf  # no history yet
    inf = jnp.full((n_max,), jnp.inf)
    c0 = (jnp.zeros(()), x0, buf0, inf, inf, jnp.zeros((), int), jnp.zeros((), bool),
          jnp.zeros((), int), jnp.asarray(Status.SUCCESS), (jnp.asarray(jnp.inf), x0),
          (jnp.asarray(jnp.inf), jnp.zeros((), int)), jnp.zeros((), bool))
    t, x, buf, d, _, k, found, n, st, (ret_best, x_best), _, _ = jax.lax.while_loop(
        cond, body, c0)
    # restart the orbit at phase 0 (t is a multiple of T; the forcing is T-periodic)
    periodic_like = jnp.min(d) < NEAR_PERIODIC * tol
    status = jnp.where(st != Status.SUCCESS, st,
                       jnp.where(found, Status.SUCCESS,
                                 jnp.where(periodic_like, Status.NO_CONVERGENCE,
                                           Status.NOT_PERIODIC)))
    # a response that never came near periodic returns its closest return to a period-1
    # orbit (a better start for shooting than wherever the budget ran out; a slow but
    # periodic-like approach keeps its last state, the nearest to its limit)
    wander = (st == Status.SUCCESS) & ~found & ~periodic_like
    x = jnp.where(wander & jnp.isfinite(ret_best) & jnp.all(jnp.isfinite(x_best)), x_best, x)
    n_eff = jnp.where(found, n, 1)
    res = jnp.where(found, d[n_eff - 1], jnp.min(d))
    system, forcing = dyn_in
    x = implicit_orbit(x, system, forcing, n_eff, cfg=cfg, n_cap=n_max)
    return finish_orbit(system, forcing, x, n_eff, cfg, status, res, k * chunk, with_floquet,
                   n_cap=n_max)


class Marching(AbstractSinglePassMethod):
    """March from the start (default rest) until the Poincaré samples repeat.

    **Arguments**

    - ``n_max``: largest period multiple recognised.
    - ``tol``: recurrence and tail-estimate tolerance on the scaled state.
    - ``max_periods``: budget in forcing periods; ``chunk``: periods per integration.
    - ``give_up``: ``None`` (march the whole budget) or a number of periods after which a
      response that is not settling stops early, ``NOT_PERIODIC`` (or ``NO_CONVERGENCE``
      when it came near periodic): one whose closest recurrence ``min_n d_n``, shrinking at
      its average rate per period since the first chunk, would still exceed ``10 tol`` at
      the end of the budget, and which is not near periodic either (``min_n d_n >= 1e3
      tol``: a floating absorber's slowly drifting family marches on).  A chaotic or
      quasi-periodic response does not shrink at all; a periodic one that converges within
      the budget passes (the test is on the average over all periods marched, not on one
      chunk's noise).  What it gives away: a transient
      that wanders chaotically for more than ``give_up`` periods before it falls onto a
      periodic orbit (transient chaos) is reported as not periodic.
    """

    n_max: int = eqx.field(static=True, default=6)
    tol: float = eqx.field(static=True, default=1e-5)
    max_periods: int = eqx.field(static=True, default=4000)
    chunk: int = eqx.field(static=True, default=40)
    give_up: int | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        if not isinstance(self.n_max, int) or not 1 <= self.n_max <= 64:
            raise ValueError(f"Marching.n_max must be an integer in [1, 64], got "
                             f"{self.n_max!r}")
        check_scalar("Marching", "tol", self.tol, lo=0.0, lo_open=True)
        for name in ("max_periods", "chunk"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 1:
                raise ValueError(f"Marching.{name} must be a positive integer, got {v!r}")
        if self.give_up is not None and (not isinstance(self.give_up, int) or self.give_up < 1):
            raise ValueError(f"Marching.give_up must be None or a positive integer (periods), "
                             f"got {self.give_up!r}")

    @property
    def retry(self):
        return False

    def initial_state(self, system, forcing):
        return system.rest_state()

    def solve(self, system, forcing, x0, cfg, *, with_floquet=True):
        return march(system, forcing, x0, cfg, n_max=self.n_max, tol=self.tol,
                     max_periods=self.max_periods, chunk=self.chunk, give_up=self.give_up,
                     with_floquet=with_floquet)
