"""Sets of designs: a grid over named parameters, explicit lists, or samples of uncertain
parameters (Monte Carlo, Latin hypercube).

A design set gives a table: one row per design, one column per named parameter (names as
``aj.parameter_names(system)`` lists them), flattened in a fixed order.  A study computes
and stores the rows in chunks along that order (dimension ``design``); the results are
then presented in the set's own dimensions (a grid's parameters, or ``sample``).
"""

from __future__ import annotations

import abc

import equinox as eqx
import numpy as np

from .._systems.params import get_param
from .distributions import AbstractDistribution


def _span(v):
    v = np.asarray(v)
    return f"{v.size} values {v.min():.6g}..{v.max():.6g}" if v.size > 1 else f"{v[0]:.6g}"


def _columns(owner, columns, kw):
    """The named parameters of ``owner`` from a dict and/or keywords, as float arrays."""
    merged = dict(columns or {}, **kw)
    if not merged:
        raise ValueError(f"{owner} needs at least one named parameter")
    out = {}
    for name, values in merged.items():
        if not isinstance(name, str):
            raise ValueError(f"{owner}: parameter names must be strings, got {name!r}")
        try:
            v = np.atleast_1d(np.asarray(values, dtype=float))
        except (TypeError, ValueError):
            raise ValueError(f"{owner}.{name} must be numbers, got {values!r}") from None
        if v.ndim != 1 or v.size == 0:
            raise ValueError(f"{owner}.{name} must be a non-empty 1-D list of values, "
                             f"got shape {v.shape}")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{owner}.{name} must be finite, got {values!r}")
        out[name] = v
    return out


class AbstractDesigns(eqx.Module):
    """A set of designs: ``names`` (the parameters it sets), ``table(system)`` (one row per
    design, flattened), ``dims``/``axes(system)`` (how results are presented)."""

    @property
    @abc.abstractmethod
    def names(self) -> tuple:
        """The parameters it sets."""

    @abc.abstractmethod
    def table(self, system) -> dict:
        """``{name: (P,) values}``: the ``P`` designs, flattened in the study's order."""

    @abc.abstractmethod
    def axes(self, system) -> dict:
        """``{dim: values}``: the dimensions results are presented in (their product is
        ``P``, in the table's order; values ``None`` for a plain index)."""

    def size(self, system) -> int:
        """The number of designs ``P``."""
        return int(next(iter(self.table(system).values())).shape[0])

    @abc.abstractmethod
    def describe(self) -> str:
        """A one-line description (stored with a study's results)."""


class Grid(AbstractDesigns):
    """Every combination of the values of the named parameters (a full factorial grid), the
    last name varying fastest; results come on one dimension per parameter.

    ```python
    aj.Grid(N=np.linspace(0.5, 6.0, 12))
    aj.Grid({"gap": [1e-3, 2e-3, 3e-3], "c2": [0.1, 0.5]})
    ```
    """

    values: dict

    def __init__(self, axes: dict | None = None, **kw):
        self.values = _columns("Grid", axes, kw)

    @property
    def names(self):
        return tuple(self.values)

    def table(self, system):
        mesh = np.meshgrid(*self.values.values(), indexing="ij")
        return {k: m.ravel() for k, m in zip(self.values, mesh)}

    def axes(self, system):
        return dict(self.values)

    def describe(self):
        return "Grid(" + ", ".join(f"{k}: {_span(v)}" for k, v in self.values.items()) + ")"


class Designs(AbstractDesigns):
    """An explicit list of designs: the ``i``-th value of every named parameter together
    (all lists the same length); results come on dimension ``design``.

    ```python
    aj.Designs(m2=[0.1, 0.2, 0.3], k2=[800.0, 1000.0, 1200.0])
    ```
    """

    values: dict

    def __init__(self, columns: dict | None = None, **kw):
        self.values = _columns("Designs", columns, kw)
        sizes = {k: v.size for k, v in self.values.items()}
        if len(set(sizes.values())) != 1:
            raise ValueError(f"Designs: every parameter needs as many values, got {sizes}")

    @property
    def names(self):
        return tuple(self.values)

    def table(self, system):
        return dict(self.values)

    def axes(self, system):
        return {"design": None}

    def describe(self):
        return "Designs(" + ", ".join(f"{k}: {_span(v)}" for k, v in self.values.items()) + ")"


def _distributions(owner, samples, seed, dists, kw):
    merged = dict(dists or {}, **kw)
    if not merged:
        raise ValueError(f"{owner} needs at least one named parameter")
    for name, d in merged.items():
        if not isinstance(d, AbstractDistribution):
            raise ValueError(f"{owner}.{name} must be a distribution (aj.Uniform, aj.Normal), "
                             f"got {d!r}")
    if not isinstance(samples, int) or isinstance(samples, bool) or samples < 1:
        raise ValueError(f"{owner}.samples must be a positive integer, got {samples!r}")
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"{owner}.seed must be a non-negative integer, got {seed!r}")
    return merged


class AbstractSampled(AbstractDesigns):
    """Designs drawn from distributions of uncertain parameters (``samples`` of them, from
    the generator seeded with ``seed``); results come on dimension ``sample``."""

    distributions: eqx.AbstractVar[dict]
    samples: eqx.AbstractVar[int]
    seed: eqx.AbstractVar[int]

    @abc.abstractmethod
    def probabilities(self) -> np.ndarray:
        """``(samples, parameters)`` probabilities in ``(0, 1)``."""

    @property
    def names(self):
        return tuple(self.distributions)

    def table(self, system):
        q = self.probabilities()
        return {k: d.values(q[:, i], float(get_param(system, k)))
                for i, (k, d) in enumerate(self.distributions.items())}

    def axes(self, system):
        return {"sample": None}

    def describe(self):
        dists = ", ".join(f"{k}: {d.describe()}" for k, d in self.distributions.items())
        return f"{type(self).__name__}({self.samples} samples, seed {self.seed}; {dists})"


class MonteCarlo(AbstractSampled):
    """Independent random samples of the uncertain parameters (plain Monte Carlo).

    ```python
    aj.MonteCarlo(200, k2=aj.Uniform(0.95, 1.05, relative=True),
                  c2=aj.Uniform(0.95, 1.05, relative=True), seed=1)
    ```
    """

    distributions: dict
    samples: int = eqx.field(static=True)
    seed: int = eqx.field(static=True)

    def __init__(self, samples: int, distributions: dict | None = None, *, seed: int = 0,
                 **kw):
        self.distributions = _distributions("MonteCarlo", samples, seed, distributions, kw)
        self.samples, self.seed = samples, seed

    def probabilities(self):
        rng = np.random.default_rng(self.seed)
        return rng.random((self.samples, len(self.distributions)))


class LatinHypercube(AbstractSampled):
    """Latin hypercube samples: each parameter's range of probability cut into ``samples``
    equal strata, one sample in each, the strata paired at random between parameters
    (M. D. McKay, R. J. Beckman, W. J. Conover, *Technometrics* 21 (1979) 239): the
    marginals are covered evenly with few samples.

    ```python
    aj.LatinHypercube(64, gap=aj.Uniform(1e-3, 3e-3), e=aj.Uniform(0.5, 0.9), seed=2)
    ```
    """

    distributions: dict
    samples: int = eqx.field(static=True)
    seed: int = eqx.field(static=True)

    def __init__(self, samples: int, distributions: dict | None = None, *, seed: int = 0,
                 **kw):
        self.distributions = _distributions("LatinHypercube", samples, seed, distributions,
                                            kw)
        self.samples, self.seed = samples, seed

    def probabilities(self):
        rng = np.random.default_rng(self.seed)
        n, d = self.samples, len(self.distributions)
        strata = np.stack([rng.permutation(n) for _ in range(d)], axis=1)
        return (strata + rng.random((n, d))) / n
