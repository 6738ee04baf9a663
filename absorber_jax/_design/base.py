"""Design primitives shared by the objectives and the optimisers: band objectives of grid
amplitudes, the reparametrisation of bounded and positive parameters, the design's checks and
the vmapped band amplitudes (shooting, forward-mode differentiable)."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.legacy import moved
from .._core.status import Status
from .._periodic.harmonic import HarmonicBalance
from .._periodic.shooting import Shooting
from .._periodic.steady import method_from, solve_point
from .._systems.forcing import Harmonic
from .._systems.params import resolve

OBJECTIVES = ("peak", "mean_square", "amplitude", "exact_peak", "robust_peak")


def smooth_max(a, softness=2e-3):
    """``τ logsumexp(a/τ) - τ log F`` with ``τ = softness · max(a)`` (a smooth lower bound of
    ``max(a)``, within ``τ log F`` of it)."""
    tau = softness * jnp.max(a)
    return tau * jax.nn.logsumexp(a / tau) - tau * jnp.log(a.shape[-1])


def band_objective(amplitudes, objective="peak", softness=2e-3):
    """A band objective of grid amplitudes: ``amplitudes`` [m] are steady-state amplitudes at
    the frequencies of a grid (last axis), ``objective`` one of

    - ``"peak"``: their smooth maximum, [`smooth_max`][absorber_jax.smooth_max] with
      ``softness`` (a lower bound of the largest, within ``τ log F``, ``τ = softness · max``)
      [m];
    - ``"mean_square"``: ``mean(a²)`` [m²], an H2-like band average;
    - ``"amplitude"``: the first amplitude (a single frequency) [m].

    Differentiable with JAX, for design loops of your own over grid amplitudes.  The exact
    and robust peaks are not functions of grid amplitudes (``ValueError``): use
    [`exact_peak`][absorber_jax.exact_peak], [`robust_peak`][absorber_jax.robust_peak] or
    ``tune(..., objective=...)``.

    ```python
    aj.band_objective(jnp.array([1e-3, 3e-3, 2e-3]), "peak")           # 2.993e-3
    aj.band_objective(jnp.array([1e-3, 3e-3, 2e-3]), "mean_square")    # 4.667e-6
    ```
    """
    if objective == "peak":
        return smooth_max(amplitudes, softness)
    if objective == "mean_square":
        return jnp.mean(amplitudes**2)
    if objective == "amplitude":
        return amplitudes[0]
    if objective in ("exact_peak", "robust_peak"):
        raise ValueError(f"objective {objective!r} is not a function of grid amplitudes: use "
                         f"{objective}(...) or tune(..., objective={objective!r})")
    raise ValueError(f"objective must be one of {OBJECTIVES}, got {objective!r}")


class Reparam(eqx.Module):
    """Unconstrained ``u`` → parameter: ``lo + (hi - lo) sigmoid(u)`` with bounds, else
    ``exp(u)`` (positive); where ``identity``, ``u`` is the parameter itself (exact_peak's
    plain evaluation, which then shares tune's compilation)."""

    lo: jax.Array
    hi: jax.Array
    bounded: jax.Array
    identity: jax.Array

    @classmethod
    def plain(cls, n):
        """The identity map on ``n`` parameters."""
        return cls(lo=jnp.zeros(n), hi=jnp.ones(n), bounded=jnp.zeros(n, bool),
                   identity=jnp.ones(n, bool))

    def forward(self, u):
        scaled = jnp.where(self.bounded, self.lo + (self.hi - self.lo) * jax.nn.sigmoid(u),
                           jnp.exp(jnp.where(self.identity, 0.0, u)))
        return jnp.where(self.identity, u, scaled)

    def inverse(self, p):
        q = jnp.clip((p - self.lo) / jnp.where(self.bounded, self.hi - self.lo, 1.0),
                     1e-9, 1 - 1e-9)
        u = jnp.where(self.bounded, jnp.log(q) - jnp.log1p(-q), jnp.log(jnp.maximum(p, 1e-300)))
        return jnp.where(self.identity, p, u)


def closed_form(system, forcing):
    """Whether ``system``'s amplitude under ``forcing`` comes from ``linear_amplitude``: a
    ``linear`` system under a single exact harmonic."""
    return (system.linear and forcing.harmonics_exact
            and len(forcing.harmonics()[0]) == 1)


def linear_amplitude(system, forcing):
    """Half peak-to-peak of the observable of a ``linear`` system's periodic response to
    the harmonic ``forcing`` (``harmonic_response``, no integration): ``|Y|``, ``Y`` the
    observable's complex amplitude; the internal state at ``t = 0`` and the status
    (``NONFINITE`` where the response is not finite: an undamped resonance)."""
    X = system.harmonic_response(forcing)[1][0]
    x0 = jnp.imag(X)
    # the observable is linear: its complex amplitude from the real and imaginary parts
    Y = system.observable(jnp.real(X)) + 1j * system.observable(x0)
    amp = jnp.abs(Y)
    ok = jnp.isfinite(amp) & jnp.all(jnp.isfinite(x0))
    return amp, (x0, jnp.where(ok, Status.SUCCESS, Status.NONFINITE))


def band_amplitudes(system, omegas, amplitude, guesses, cfg, method):
    """Steady primary amplitudes at ``omegas`` (vmapped ``method``: the design's shooting, or
    a ``HarmonicBalance``; differentiable in forward mode, implicitly through each orbit
    solve; a ``linear`` system's from its closed-form response, ``linear_amplitude``).
    ``guesses``: internal states (NaN: use the linear guess)."""

    def one(w, g):
        forcing = Harmonic(amplitude=amplitude, omega=w)
        if closed_form(system, forcing):
            a, (x, status) = linear_amplitude(system, forcing)
            return a, x, status, jnp.ones((), int)
        res = solve_point(system, forcing, method, cfg, guess=g, with_floquet=False)
        return res.amplitude, system.to_internal(res.state), res.status, res.period_multiple

    return jax.vmap(one)(omegas, guesses)


def legacy_objective(obj, where, legacy, options=("n_freq", "softness", "peaks", "modes",
                                                  "stability_margin", "probes", "probe_samples",
                                                  "rounds", "xtol", "max_iter", "spread", "seed",
                                                  "max_periods"), renamed=None):
    """``obj`` with the objective options given as deprecated keywords of ``where`` popped
    from ``legacy`` and set on it (a ``DeprecationWarning`` names the new form);
    ``renamed`` maps a former keyword to the objective's field."""
    renamed = renamed or {}
    given = {k: legacy.pop(k) for k in (*options, *renamed) if k in legacy}
    if not given:
        return obj
    moved(where, given, f"objective=aj.objectives.{type(obj).__name__}({{}})")
    names = {f.name for f in dataclasses.fields(obj)}
    values = {renamed.get(k, k): v for k, v in given.items()}
    return dataclasses.replace(obj, **{k: v for k, v in values.items() if k in names})


def design_method(method, where, legacy, default_tol=1e-7, balance=False):
    """The ``Shooting`` of a design entry point: ``method`` (default
    ``Shooting(tol=default_tol, newton_steps=40)``), with the deprecated keywords ``tol`` and
    ``newton_steps`` popped from ``legacy`` (``method_from``: a warning names the new form);
    a ``HarmonicBalance`` too where ``balance``."""
    options = {k: legacy.pop(k) for k in ("tol", "newton_steps") if k in legacy}
    method = method_from(method, where, options,
                         default=Shooting(tol=default_tol, newton_steps=40))
    if isinstance(method, HarmonicBalance) and balance:
        return method
    if not isinstance(method, Shooting):
        also = " or an aj.HarmonicBalance(...)" if balance else ""
        raise ValueError(f"{where}.method must be an aj.Shooting(...){also}: design "
                         f"differentiates orbits implicitly through their solve, got "
                         f"{type(method).__name__}")
    return method


def shooting_for_design(tol, newton_steps):
    """The shooting method of design evaluations: no marching retry (a retry's branch switch
    would make the objective discontinuous; failed points are reseeded instead)."""
    return Shooting(tol=tol, newton_steps=newton_steps, retry=False)


def check_design(system, params, omegas, objective):
    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
    if not params:
        raise ValueError("params must name at least one parameter, e.g. ['k1', 'c1']")
    names = tuple(params)
    for k in names:
        resolve(system, k)
    om = np.atleast_1d(np.asarray(omegas, dtype=float))
    if om.ndim != 1 or om.size == 0 or np.any(om <= 0) or np.any(np.diff(om) <= 0):
        raise ValueError("omegas must be a non-empty, strictly increasing grid of positive "
                         "frequencies [rad/s]")
    return names, om
