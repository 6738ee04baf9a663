"""Design objectives: what ``tune`` minimises over a frequency band, as objects carrying
their options.

All objectives measure the steady-state amplitude of the system's observable (the primary's
displacement for the two-mass absorbers, ``observe=`` of a structure) [m] under a harmonic
force of amplitude ``F0`` [N], over a band ``(lo, hi)`` [rad/s] sampled at ``n_freq`` points.

- ``ExactPeak`` (the default of ``tune``): the band's largest amplitude, its peaks
  located exactly where ``dA/dω = 0`` on the orbit family and differentiated by the envelope
  theorem; minimised as the minimax problem it is (``min t`` subject to ``A_j(θ) <= t``, by
  SLSQP on the epigraph).  Reaches equal-peak (H∞) optima to the solver's tolerance.
- ``RobustPeak``: ``ExactPeak`` plus the stable coexisting responses found by
  attractor maps: the worst response the structure can settle on.
- ``SmoothPeak``: the smooth maximum of the grid amplitudes,
  ``τ log Σ exp(a_i/τ) - τ log F`` with ``τ = softness · max a``: a lower bound of the grid's
  maximum within ``τ log n_freq``, and the grid itself misses peaks between its points.
  Cheaper per step; its optimum is biased (a few per cent on a tuned mass damper).
- ``MeanSquare``: ``mean(a_i²)`` over the grid (an H2-like band average).

```python
import absorber_jax as aj
system, _ = aj.presets.impact("kelvin_voigt")
tuned, hist = aj.tune(system, ["k1", "c1"], (25.0, 45.0), amplitude=2.0)   # ExactPeak()
tuned, hist = aj.tune(system, ["k1", "c1"], (25.0, 45.0), amplitude=2.0,
                      objective=aj.objectives.SmoothPeak(n_freq=64))
```
"""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx

from .._core.checks import check_scalar


def _positive_int(owner, name, value, lo):
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise ValueError(f"{owner}.{name} must be an integer >= {lo}, got {value!r}")


class AbstractObjective(eqx.Module):
    """A band objective for ``tune``: the amplitudes it looks at (``n_freq`` grid points
    over the band) and how they are reduced to one number.

    ``kind`` names the reduction the optimisers dispatch on; ``options()`` gives the keyword
    options the design machinery needs."""

    kind: ClassVar[str]
    n_freq: eqx.AbstractVar[int]

    @abc.abstractmethod
    def options(self) -> dict:
        """The objective's options as keywords of the design machinery."""


class ExactPeak(AbstractObjective):
    """The band's largest amplitude, located exactly (the zero of ``dA/dω`` bracketed on the
    grid and refined by the Illinois method: M. Dowell, P. Jarratt, *BIT* 11 (1971) 168) and
    differentiated by the envelope theorem (P. Milgrom, I. Segal, *Econometrica* 70 (2002)
    583), minimised as a minimax problem.

    - ``n_freq``: grid points that bracket the peaks (enough to separate them; the grid also
      follows the design's lightly damped modes when ``modes``).
    - ``peaks``: slots located: the tallest local maxima (2 for a tuned mass damper).
    - ``modes``: add grid points at the lightly damped modes of the linearisation at rest and
      their half-power points, so that a resonance narrower than the grid is not missed.
    - ``stability_margin``: a design whose orbit at a located peak has a Floquet multiplier
      of modulus above ``1 - stability_margin`` is infeasible (``None``: no margin).
    - ``xtol``, ``max_iter``: relative tolerance on a located frequency and the most
      Illinois steps per peak.
    """

    kind: ClassVar[str] = "exact_peak"
    n_freq: int = 32
    peaks: int = 2
    modes: bool = True
    stability_margin: float | None = None
    xtol: float = 1e-10
    max_iter: int = 40

    def __check_init__(self):
        _positive_int(type(self).__name__, "n_freq", self.n_freq, 3)
        _positive_int(type(self).__name__, "peaks", self.peaks, 1)
        if self.peaks > self.n_freq:
            raise ValueError(f"{type(self).__name__}.peaks must be in [1, n_freq], got "
                             f"{self.peaks}")
        if self.stability_margin is not None:
            check_scalar(type(self).__name__, "stability_margin", self.stability_margin,
                         lo=0.0, hi=1.0, hi_open=True)

    def options(self):
        return dict(n_freq=self.n_freq, peaks=self.peaks, modes=self.modes,
                    stability_margin=self.stability_margin)


class RobustPeak(AbstractObjective):
    """The worst *stable* response the structure can settle on over the band: the exact
    peak of the branch shooting follows, plus the coexisting responses attractor maps find
    at ``probes`` frequencies (``probe_samples`` initial states each).  A period-1 response
    larger than what the objective sees is followed by shooting as the design moves (one
    more minimax constraint); the maps run again at each result, and a new larger response
    starts another of at most ``rounds`` minimax rounds.  ``spread``, ``seed``,
    ``max_periods``: the maps' initial states (uniform in a box of ``±spread`` state scales
    around rest) and marching budget [forcing periods].  ``n_freq``, ``peaks``, ``modes``,
    ``stability_margin``, ``xtol``, ``max_iter``: as ``ExactPeak``."""

    kind: ClassVar[str] = "robust_peak"
    n_freq: int = 32
    peaks: int = 2
    modes: bool = True
    stability_margin: float | None = None
    xtol: float = 1e-10
    max_iter: int = 40
    probes: int = 8
    probe_samples: int = 16
    rounds: int = 3
    spread: float = 3.0
    seed: int = 0
    max_periods: int = 2000

    def __check_init__(self):
        ExactPeak.__check_init__(self)
        for name in ("probes", "probe_samples", "rounds"):
            _positive_int(type(self).__name__, name, getattr(self, name), 1)

    def options(self):
        return dict(n_freq=self.n_freq, peaks=self.peaks, modes=self.modes,
                    stability_margin=self.stability_margin, probes=self.probes,
                    probe_samples=self.probe_samples, rounds=self.rounds)


class SmoothPeak(AbstractObjective):
    """The smooth maximum of the amplitudes at ``n_freq`` evenly spaced frequencies,
    ``τ log Σ exp(a_i/τ) - τ log n_freq`` with ``τ = softness · max a`` (within
    ``τ log n_freq`` below the grid's maximum), minimised by a gradient optimiser (optax)."""

    kind: ClassVar[str] = "peak"
    n_freq: int = 64
    softness: float = 2e-3

    def __check_init__(self):
        _positive_int(type(self).__name__, "n_freq", self.n_freq, 1)
        check_scalar(type(self).__name__, "softness", self.softness, lo=0.0, lo_open=True)

    def options(self):
        return dict(n_freq=self.n_freq, softness=self.softness)


class MeanSquare(AbstractObjective):
    """``mean(a_i²)`` [m²] over ``n_freq`` evenly spaced frequencies, minimised by a gradient
    optimiser (optax).  With a band of one frequency ``(ω, ω)``, the squared amplitude at
    that frequency."""

    kind: ClassVar[str] = "mean_square"
    n_freq: int = 64

    def __check_init__(self):
        _positive_int(type(self).__name__, "n_freq", self.n_freq, 1)

    def options(self):
        return dict(n_freq=self.n_freq)


BY_NAME = {"exact_peak": ExactPeak, "robust_peak": RobustPeak, "peak": SmoothPeak,
           "mean_square": MeanSquare}


def as_objective(objective, where):
    """An ``AbstractObjective`` from an objective object or one of the names
    ``"exact_peak"``, ``"robust_peak"``, ``"peak"`` (``SmoothPeak``), ``"mean_square"``
    (each with its default options)."""
    if objective is None:
        return ExactPeak()
    if isinstance(objective, AbstractObjective):
        return objective
    if isinstance(objective, str) and objective in BY_NAME:
        return BY_NAME[objective]()
    raise ValueError(f"{where}.objective must be an objective object (aj.objectives.ExactPeak(), "
                     f"RobustPeak(), SmoothPeak(), MeanSquare()) or one of "
                     f"{tuple(BY_NAME)}, got {objective!r}")
