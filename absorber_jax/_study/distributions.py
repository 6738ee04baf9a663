"""Distributions of uncertain parameters, for the sampled design sets (``MonteCarlo``,
``LatinHypercube``).

Each distribution maps probabilities ``q ∈ (0, 1)`` to values through its inverse
cumulative distribution function, so that plain Monte Carlo (``q`` uniform) and Latin
hypercube sampling (``q`` stratified) share one code path.  With ``relative=True`` the
values are factors of the parameter's nominal value in the study's system
(``Uniform(0.95, 1.05, relative=True)`` is ±5 % around it).
"""

from __future__ import annotations

import abc
import statistics

import equinox as eqx
import numpy as np


class AbstractDistribution(eqx.Module):
    """A distribution of one uncertain parameter: ``quantile(q)`` maps probabilities to
    values (factors of the nominal value where ``relative``)."""

    relative: eqx.AbstractVar[bool]
    @abc.abstractmethod
    def quantile(self, q: np.ndarray) -> np.ndarray:
        """Values at probabilities ``q`` (the inverse cumulative distribution function)."""

    def values(self, q: np.ndarray, nominal: float) -> np.ndarray:
        """Parameter values at probabilities ``q``, for the nominal value ``nominal``."""
        v = np.asarray(self.quantile(np.asarray(q, dtype=float)), dtype=float)
        return v * nominal if self.relative else v

    def describe(self) -> str:
        """A one-line description (stored with a study's results)."""
        return repr(self)


class Uniform(AbstractDistribution):
    """Uniform on ``[low, high]`` (factors of the nominal value where ``relative``).

    ```python
    aj.Uniform(0.95, 1.05, relative=True)    # ±5 % around the system's value
    aj.Uniform(1e-3, 3e-3)                   # a clearance between 1 and 3 mm [m]
    ```
    """

    low: float
    high: float
    relative: bool = eqx.field(default=False, static=True, kw_only=True)

    def __check_init__(self):
        if not (np.isfinite(self.low) and np.isfinite(self.high) and self.low < self.high):
            raise ValueError(f"Uniform needs finite low < high, got low={self.low!r}, "
                             f"high={self.high!r}")

    def quantile(self, q):
        return self.low + q * (self.high - self.low)


class Normal(AbstractDistribution):
    """Gaussian with mean ``mean`` and standard deviation ``std`` (factors of the nominal
    value where ``relative``: ``Normal(1.0, 0.02, relative=True)`` is a 2 % scatter).

    ```python
    aj.Normal(1.0, 0.02, relative=True)
    ```
    """

    mean: float
    std: float
    relative: bool = eqx.field(default=False, static=True, kw_only=True)

    def __check_init__(self):
        if not (np.isfinite(self.mean) and np.isfinite(self.std) and self.std > 0):
            raise ValueError(f"Normal needs a finite mean and std > 0, got mean={self.mean!r}, "
                             f"std={self.std!r}")

    def quantile(self, q):
        inv = np.vectorize(statistics.NormalDist(self.mean, self.std).inv_cdf, otypes=[float])
        return inv(q)
