"""Results of a continuation: a branch of periodic orbits and its bifurcations."""

from __future__ import annotations

import dataclasses
import json

import equinox as eqx
import numpy as np

from .._core import tables
from .._core.units import Signals
from .._periodic.orbit import (
    SteadyResults,
    SteadyState,
    read_through,
)
from .constants import KINDS, REACHED


class Bifurcation(eqx.Module):
    """A bifurcation found on a [`Branch`][absorber_jax.Branch].

    ``kind``: ``"fold"``, ``"period_doubling"``, ``"neimark_sacker"`` or ``"grazing"`` (an
    orbit touching a rigid wall at zero relative velocity, where an impact is born or dies;
    located by the closest approach of the orbit's flights to the walls); ``value``: the
    located parameter value; ``amplitude``: the observable's amplitude there; ``state``:
    public orbit state; ``multipliers``: Floquet multipliers there; ``index``: it lies
    between branch points ``index`` and ``index + 1``; ``located``: the location converged
    to ``locate_tol`` onto a zero of the test function (False where the bracket closed on a
    jump of it: a grazing corner, where the multipliers leap across the circle);
    ``evaluations``: corrector solves spent locating it (0 where ``band_continuation``
    took the location from another sighting of it: the other half-branch of its cell, or
    its own half-branch passing it again round a loop)."""

    kind: str = eqx.field(static=True)
    value: float
    amplitude: float
    state: np.ndarray
    multipliers: np.ndarray
    index: int = eqx.field(static=True)
    period_multiple: int = eqx.field(static=True)
    located: bool = eqx.field(static=True)
    evaluations: int = eqx.field(static=True)

    def summary(self):
        """The bifurcation as a JSON-ready dict (multipliers as ``[real, imag]`` pairs)."""
        return dict(kind=self.kind, value=float(self.value), amplitude=float(self.amplitude),
                    index=self.index, period_multiple=self.period_multiple,
                    located=self.located, evaluations=self.evaluations,
                    multipliers=[[float(m.real), float(m.imag)] for m in self.multipliers])


class Branch(SteadyResults, eqx.Module):
    """A branch of period-``n`` orbits from [`continuation`][absorber_jax.continuation].

    ``values``: the parameter along the branch (in the order followed: it turns back at
    folds); ``steady``: the point solve's [`SteadyState`][absorber_jax.SteadyState], batched (its
    fields read through: ``amplitude``, ``dof_amplitude``, ``stable``, ``multipliers``, ``status``
    ...); ``bifurcations``: the [`Bifurcation`][absorber_jax.Bifurcation]s found, in branch order;
    ``termination``: why the branch ended (``"bounds"``, ``"rejoined"``, ``"closed"``: it
    went where it was asked to, ``reached`` is True; ``"closed"``: back at its first point,
    back on a part of itself it had followed already (going the same way, with as many
    impacts), or through two grazings in a row that it had passed before, one after the
    other, so that going on would retrace it; ``"max_points"``, ``"step_collapse"``,
    ``"grazing"``: a grazing it located but could not continue through, or
    ``"start_failed"``: it did not, and ``ending()`` says why and what to try);
    corrector iterations per point are ``iterations``.  The measured fields are NaN at
    failed points; ``signals``: the names and SI units of what they measure, as the CSV
    headers, plot labels and ``to_xarray`` attributes give them."""

    parameter: str = eqx.field(static=True)
    values: np.ndarray
    steady: SteadyState
    bifurcations: tuple
    period_multiple: int = eqx.field(static=True)
    termination: str = eqx.field(static=True)
    dof_names: tuple = eqx.field(static=True, default=())
    signals: Signals = eqx.field(static=True, default=Signals())

    def __len__(self):
        return int(np.asarray(self.values).shape[0])

    def of_kind(self, kind):
        """The bifurcations of one kind."""
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
        return [b for b in self.bifurcations if b.kind == kind]

    @property
    def reached(self) -> bool:
        """Whether the branch went where it was asked to (a bound, back onto the branch it
        was switched from, or round a closed branch)."""
        return self.termination in REACHED

    def ending(self) -> str:
        """How the branch ended, in words, with what to try where it stopped short."""
        v = np.asarray(self.values)
        last = f"{self.parameter} = {v[-1]:.6g}" if v.size else "its start"
        if self.reached:
            return f"the branch ended at {last} ({self.termination})"
        why = {
            "max_points": "it used its whole point budget; try: raise "
                          "PseudoArclength(max_points=...), or a larger step",
            "step_collapse": "the corrector failed down to the smallest step (a sharp "
                             "corner or a branch point); try: a smaller "
                             "PseudoArclength(min_step=...), a tighter integrator rtol, or "
                             "band_continuation, which starts branches beyond it",
            "grazing": "it grazes a rigid wall there and the orbit with the impact born "
                       "there was not found (the period map is singular at grazing); try: "
                       "start a continuation just beyond the grazing value, "
                       "band_continuation, or aj.attractors there",
            "start_failed": "no first orbit was found; try: another guess (guess=...), a "
                            "start value where the response is simpler, or "
                            "band_continuation",
        }[self.termination]
        return f"the branch stopped short at {last}: {why}"

    def summary(self):
        """The branch as a JSON-ready dict: parameter, period, points, how it ended, the range
        covered, stable and failed points, corrector iterations and the bifurcations."""
        st = np.asarray(self.stable)
        return dict(parameter=self.parameter, period_multiple=self.period_multiple,
                    points=len(self), termination=self.termination, reached=self.reached,
                    ending=self.ending(),
                    range=[float(np.min(self.values)), float(np.max(self.values))],
                    stable_points=int(st.sum()), failed_points=int((~self.ok).sum()),
                    corrector_iterations_median=float(np.median(self.iterations)),
                    bifurcations=[b.summary() for b in self.bifurcations])

    def failures(self):
        """``[(index, what failed and what to try)]`` of the points that failed."""
        return tables.failure_list(self.status)

    def to_csv(self, path):
        """One row per branch point, SI values, each header with its unit: the point index,
        the parameter (``omega [rad/s]``), the observable's and the absorber stroke's
        statistics, impacts, period multiple, stability, status, residual, iterations, the
        largest |multiplier|, each degree of freedom's absolute statistics, the status
        text (columns as in ``FrequencyResponse.to_csv``)."""
        tables.write_csv(path, tables.branch_columns(self))

    def to_dataframe(self):
        """The rows of ``to_csv`` as a ``pandas.DataFrame`` (needs pandas)."""
        return tables.dataframe(tables.branch_columns(self), "Branch.to_dataframe")

    def to_xarray(self):
        """An ``xarray.Dataset`` over the branch's ``point`` s (the parameter a coordinate
        along them), every field with ``units`` and ``long_name``, ``status`` with its code
        names, the bifurcations over ``bifurcation`` (needs xarray)."""
        return tables.branch_dataset(self)

    def to_json(self, path):
        """Write ``summary()`` to the JSON file ``path``."""
        with open(path, "w") as fh:
            json.dump(self.summary(), fh, indent=2)


read_through(Branch, [f.name for f in dataclasses.fields(SteadyState)
                      if f.name not in ("state", "multipliers", "period_multiple")],
             "branch point")
