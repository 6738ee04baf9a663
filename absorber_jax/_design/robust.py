"""The worst response a design can show over a band: the exact peak of the response shooting
follows, and every stable coexisting response found by marching from many initial states.

A design objective that sees one orbit per frequency (the one Newton converged to) misses a
larger response that coexists with it (a hardening resonance's upper branch inside its
hysteresis, Table 1's period-5 orbit at 55 rad/s).  ``robust_peak`` adds an attractor
map (``absorber_jax.attractors``) at ``probes`` frequencies across the band: each stable
periodic response found there is a candidate, and the robust value is the largest of the
exact peak and those responses' amplitudes.  A period-1 candidate is polished by shooting
from its marched state and differentiated there at its fixed frequency (its gradient is the
gradient of a response the structure can really settle on); a response of longer period
enters the value, with no gradient (``gradient`` then holds NaN).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._core.legacy import no_more
from .._core.status import Status
from .._integration.settings import Integrator, integrator_from
from .._periodic.attractors import attractors
from .._periodic.marching import Marching
from .._periodic.steady import make_config
from .._systems.forcing import at_frequency, sweep_shape
from .._systems.params import get_param
from .base import Reparam, design_method, legacy_objective
from .objectives import RobustPeak as RobustPeakObjective
from .peak import evaluate_points, exact_peak_of


class Coexisting(eqx.Module):
    """A stable response found by the attractor map at ``omega`` [rad/s]: its
    ``amplitude``, ``period_multiple``, ``share`` of the initial states, ``stable`` and the
    public ``state`` on it at ``t = 0 mod T``."""

    omega: float
    amplitude: float
    period_multiple: int
    share: float
    stable: bool
    state: np.ndarray


class RobustPeak(eqx.Module):
    """[`robust_peak`][absorber_jax.robust_peak]'s result.

    ``value``/``omega``: the worst response over the band and its frequency; ``source``:
    ``"branch"`` (the exact peak of the response shooting follows) or ``"coexisting"`` (a
    response found by marching that is larger); ``gradient``: ``d value / d parameter``;
    ``plain``: the exact peak alone ([`BandPeak`][absorber_jax.BandPeak]), what a plain objective
    reports; ``coexisting``: every stable periodic response of the attractor maps."""

    value: float
    omega: float
    source: str
    gradient: dict
    plain: object
    coexisting: tuple

    def summary(self):
        """The result as a JSON-ready dict (value, frequency, source, the plain peak, the
        gradient and the coexisting responses)."""
        return dict(value=self.value, omega=self.omega, source=self.source,
                    plain=self.plain.value, gradient=self.gradient,
                    coexisting=[dict(omega=c.omega, amplitude=c.amplitude,
                                     period_multiple=c.period_multiple, share=c.share)
                                for c in self.coexisting])


def stable_responses(system, band, amplitude, *, probes, samples, spread=3.0, seed=0,
                     max_periods=2000, solver=None, rtol=1e-10, atol=1e-10):
    """``[(ω, attractor)]``: the stable periodic responses of attractor maps at ``probes``
    frequencies uniform over ``band``."""

    found = []
    for w in np.linspace(float(band[0]), float(band[1]), probes):
        amap = attractors(system, at_frequency(amplitude, float(w)),
                          samples=samples, spread=spread, seed=seed,
                          method=Marching(n_max=8, max_periods=max_periods, tol=1e-6),
                          integrator=Integrator(solver=solver, rtol=rtol, atol=atol))
        for att in amap.attractors:
            if att.periodic and att.converged and att.stable:
                found.append((float(w), att))
    return found


def robust_peak(system, band, *, amplitude, params=(), objective=None, method=None,
                integrator=None, **legacy) -> RobustPeak:
    """The worst stable response over ``band`` [rad/s] (``RobustPeak``): the exact peak of the
    branch shooting follows (``exact_peak``) or a larger stable response that attractor maps
    at ``probes`` frequencies find coexisting with it, with its gradient in ``params`` (for
    a period-1 coexisting response, differentiated on its orbit at its frequency).

    - ``objective``: an ``objectives.RobustPeak`` carrying the exact peak's options
      (``n_freq``, ``peaks``, ``modes``, ``xtol``, ``max_iter``) and the maps' (``probes``,
      ``probe_samples`` initial states each, uniform in a box of ``±spread`` state scales,
      ``seed``, ``max_periods`` of marching); default ``RobustPeak()``.
    - ``method``: the ``Shooting`` of each orbit, default ``Shooting(tol=1e-7,
      newton_steps=40)``; ``integrator``: default the design tolerances (1e-10).
    """
    obj = RobustPeakObjective() if objective is None else objective
    if not isinstance(obj, RobustPeakObjective):
        raise ValueError(f"robust_peak.objective must be an aj.objectives.RobustPeak(...), got "
                         f"{type(obj).__name__}")
    obj = legacy_objective(obj, "robust_peak", legacy, renamed={"samples": "probe_samples"})
    method = design_method(method, "robust_peak", legacy)
    integ = integrator_from(integrator, "design", "robust_peak", legacy,
                            fields=("solver", "rtol", "atol", "max_steps"))
    no_more("robust_peak", legacy)
    return robust_peak_of(system, band, amplitude=amplitude, params=params, n_freq=obj.n_freq,
                          peaks=obj.peaks, probes=obj.probes, samples=obj.probe_samples,
                          spread=obj.spread, seed=obj.seed, max_periods=obj.max_periods,
                          tol=method.tol, rtol=integ.rtol, atol=integ.atol,
                          newton_steps=method.newton_steps, solver=integ.solver,
                          xtol=obj.xtol, max_iter=obj.max_iter, modes=obj.modes,
                          max_steps=integ.max_steps)


def robust_peak_of(system, band, *, amplitude, params, n_freq, peaks, probes, samples, spread,
                   seed, max_periods, tol, rtol, atol, newton_steps, solver, xtol=1e-10,
                   max_iter=40, modes=True, max_steps=200_000) -> RobustPeak:
    """``robust_peak`` with its options unpacked."""
    if not isinstance(probes, int) or probes < 1:
        raise ValueError(f"robust_peak.probes must be a positive integer, got {probes!r}")
    plain = exact_peak_of(system, band, amplitude=amplitude, params=params, n_freq=n_freq,
                          peaks=peaks, tol=tol, rtol=rtol, atol=atol,
                          newton_steps=newton_steps, solver=solver, xtol=xtol,
                          max_iter=max_iter, modes=modes, max_steps=max_steps)
    names = tuple(params)
    found = stable_responses(system, band, amplitude, probes=probes, samples=samples,
                             spread=spread, seed=seed, max_periods=max_periods, solver=solver,
                             rtol=rtol, atol=atol)
    coexisting = tuple(Coexisting(omega=w, amplitude=float(a.amplitude),
                                  period_multiple=int(a.period_multiple), share=float(a.share),
                                  stable=bool(a.stable), state=np.asarray(a.state))
                       for w, a in found)
    value, omega, source, grad = plain.value, plain.omega, "branch", plain.gradient
    if found:
        w, att = max(found, key=lambda f: f[1].amplitude)
        if att.amplitude > value * (1 + 1e-6):
            value, omega, source = float(att.amplitude), w, "coexisting"
            grad = {k: float("nan") for k in names}
            if att.period_multiple == 1:
                forcing = at_frequency(amplitude, w)
                cfg = make_config(system, forcing, solver, rtol, atol, max_steps)
                p = jnp.array([float(get_param(system, k)) for k in names])
                guess = system.to_internal(jnp.asarray(att.state))[None]
                # in batches of the exact peak's slots: its compiled program, reused
                a, g, _, st = evaluate_points(
                    system, names, Reparam.plain(len(names)), p, [w],
                    sweep_shape(amplitude, "robust_peak"), guess, cfg, float(tol),
                    int(newton_steps), peaks)
                if int(st[0]) == Status.SUCCESS:
                    value = float(a[0])
                    grad = {k: float(g[0, 1 + i]) for i, k in enumerate(names)}
    return RobustPeak(value=value, omega=omega, source=source, gradient=grad, plain=plain,
                      coexisting=coexisting)
