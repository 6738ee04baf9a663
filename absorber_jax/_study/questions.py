"""What a study asks of each design: the frequency response over a band, the exact peak,
the robust peak, an attractor map.

A question is an ``AbstractQuestion``: it names the dimensions and variables of its answer
(with units) before anything is computed, so that a study's store can be laid out in
advance, and computes the answer for a chunk of designs at once.  Subclass it to ask your
own question (the methods below are all it needs).
"""

from __future__ import annotations

import abc
import warnings

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._core.checks import check_time_grid
from .._core.status import Status
from .._core.units import signals_of
from .._design.objectives import ExactPeak as ExactPeakObjective
from .._design.peak import exact_peak
from .._design.robust import robust_peak
from .._periodic.attractors import attractors
from .._periodic.sweep import frequency_response
from .._systems.forcing import Harmonic, at_frequency, sweep_shape
from .._systems.params import replace_params


class AbstractQuestion(eqx.Module):
    """A question asked of every design of a study.

    - ``coords(system)``: ``{dim: values}`` of the answer's own dimensions (``omega``,
      ``dof`` ...).
    - ``variables(system)``: ``{name: (dims, unit, description, dtype)}`` of its answer
      per design, ``dims`` among ``coords``' (``()`` for one number per design).
    - ``compute(system, params)``: the answer for the designs ``params = {name: (P,)
      values}`` of one chunk: ``{name: array of shape (P, *dims)}``.
    - ``points(system)``: how many solves one design costs (for progress and rates).
    """

    @abc.abstractmethod
    def coords(self, system) -> dict:
        """The answer's own dimensions and their values."""

    @abc.abstractmethod
    def variables(self, system) -> dict:
        """``{name: (dims, unit, description, dtype)}`` of the answer per design."""

    @abc.abstractmethod
    def compute(self, system, params: dict) -> dict:
        """The answer for the designs ``params`` (``{name: (P,) values}``)."""

    @abc.abstractmethod
    def points(self, system) -> int:
        """Solves per design (progress counts these)."""

    @abc.abstractmethod
    def describe(self) -> str:
        """A one-line description (stored with a study's results)."""


def _design_system(system, params, i):
    """``system`` with design ``i`` of ``params`` set (values as arrays: one compiled
    program serves every design)."""
    return replace_params(system, {k: jnp.asarray(float(v[i])) for k, v in params.items()},
                          check=False)


def _quietly(fn, *args, **kw):
    """``fn`` with its per-call failure warnings held back (a study reports failures per
    point in its ``status`` variable, and counts them in its summary)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return fn(*args, **kw)


class FrequencyResponse(AbstractQuestion):
    """The steady-state frequency response over ``omegas`` [rad/s] under ``amplitude``
    (``F0`` [N] of ``F0 sin(ωt)``, or a periodic forcing swept through its fundamental), as
    ``aj.frequency_response`` computes it (``method``, ``integrator`` as there), every design
    of a chunk in one compiled call.

    Answer per design: ``amplitude`` (the observable's, over ``omega``) and
    ``dof_amplitude`` (per degree of freedom) [m], ``absorber_amplitude`` (the stroke)
    [m], ``impacts`` per period, ``stable``, ``status`` (0 converged), ``spectral_radius``
    (the largest Floquet multiplier's modulus), and the sampled ``peak`` [m] with its
    ``peak_omega`` [rad/s] (the largest converged amplitude on the grid).

    ```python
    aj.questions.FrequencyResponse(np.linspace(20, 45, 64), amplitude=3.0)
    ```
    """

    omegas: np.ndarray
    amplitude: object
    method: object = None
    integrator: object = None

    def __init__(self, omegas, *, amplitude, method=None, integrator=None):
        check_time_grid("omegas", omegas, strictly=True)
        self.omegas = np.asarray(omegas, dtype=float)
        if self.omegas[0] <= 0:
            raise ValueError(f"FrequencyResponse.omegas must be > 0 [rad/s], got "
                             f"{self.omegas[0]:g}")
        self.amplitude = sweep_shape(amplitude, "FrequencyResponse")
        if isinstance(self.amplitude, Harmonic):
            self.amplitude = float(self.amplitude.amplitude)
        self.method, self.integrator = method, integrator

    def coords(self, system):
        return {"omega": self.omegas, "dof": np.asarray(system.output_names)}

    def variables(self, system):
        sig = signals_of(system)
        u = sig.observable_unit
        return {
            "amplitude": (("omega",), u, f"amplitude of {sig.observable}", "f8"),
            "dof_amplitude": (("dof", "omega"), "m", "amplitude per degree of freedom", "f8"),
            "absorber_amplitude": (("omega",), "m", f"amplitude of {sig.stroke}", "f8"),
            "impacts": (("omega",), "1/period", "impacts per forcing period", "f8"),
            "stable": (("omega",), "", "stable (Floquet)", "bool"),
            "status": (("omega",), "", "0 converged; else aj.describe(status)", "i4"),
            "spectral_radius": (("omega",), "", "largest Floquet multiplier modulus", "f8"),
            "peak": ((), u, f"largest converged amplitude of {sig.observable} on the grid",
                     "f8"),
            "peak_omega": ((), "rad/s", "frequency of the peak", "f8"),
        }

    def points(self, system):
        return int(self.omegas.size)

    def describe(self):
        return (f"FrequencyResponse({_grid(self.omegas)}, amplitude {_force(self.amplitude)}, "
                f"method {self.method!r}, integrator {self.integrator!r})")

    def compute(self, system, params):
        fr = _quietly(frequency_response, system, self.omegas, amplitude=self.amplitude,
                      method=self.method, integrator=self.integrator, params=params)
        amp = np.asarray(fr.amplitude)
        ok = np.asarray(fr.status) == Status.SUCCESS
        masked = np.where(ok, amp, -np.inf)
        j = np.argmax(masked, axis=1)
        anyok = ok.any(axis=1)
        mu = np.abs(np.asarray(fr.steady.multipliers))
        return {
            "amplitude": amp,
            "dof_amplitude": np.moveaxis(np.asarray(fr.steady.dof_amplitude), -1, 1),
            "absorber_amplitude": np.asarray(fr.absorber_amplitude),
            "impacts": np.asarray(fr.impacts),
            "stable": np.asarray(fr.stable, dtype=bool),
            "status": np.asarray(fr.status, dtype=np.int32),
            "spectral_radius": np.where(ok, np.max(mu, axis=-1), np.nan),
            "peak": np.where(anyok, np.take_along_axis(amp, j[:, None], 1)[:, 0], np.nan),
            "peak_omega": np.where(anyok, self.omegas[j], np.nan),
        }


class ExactPeak(AbstractQuestion):
    """The largest steady-state amplitude over ``band = (lo, hi)`` [rad/s], located exactly
    (``aj.exact_peak``, its ``objective`` an ``aj.objectives.ExactPeak``), one design after
    the other on one compiled program.

    Answer per design: ``peak`` [m], ``peak_omega`` [rad/s], ``located`` (the zero of
    ``dA/dω`` found, not a band edge or grid point) and ``status``.

    ```python
    aj.questions.ExactPeak((80.0, 120.0), amplitude=1.0)
    ```
    """

    band: tuple
    amplitude: object
    objective: object = None
    method: object = None
    integrator: object = None

    def __init__(self, band, *, amplitude, objective=None, method=None, integrator=None):
        self.band = _band("ExactPeak", band)
        self.amplitude = sweep_shape(amplitude, "ExactPeak")
        if objective is not None and not isinstance(objective, ExactPeakObjective):
            raise ValueError(f"ExactPeak.objective must be an aj.objectives.ExactPeak(...), "
                             f"got {type(objective).__name__}")
        self.objective, self.method, self.integrator = objective, method, integrator

    def coords(self, system):
        return {}

    def variables(self, system):
        return _peak_variables(system, "peak", located=True)

    def points(self, system):
        return 1        # one peak search per design

    def describe(self):
        return (f"ExactPeak(band {self.band[0]:g}..{self.band[1]:g} rad/s, amplitude "
                f"{_force(self.amplitude)}, objective {self.objective!r})")

    def compute(self, system, params):
        out = {k: [] for k in ("peak", "peak_omega", "located", "status")}
        for i in range(_count(params)):
            pk = _quietly(exact_peak, _design_system(system, params, i), self.band,
                          amplitude=self.amplitude, objective=self.objective,
                          method=self.method, integrator=self.integrator)
            ok = bool(pk.ok.any())
            out["peak"].append(pk.value)
            out["peak_omega"].append(pk.omega)
            out["located"].append(ok and bool(pk.located[pk.index]))
            out["status"].append(int(pk.status[pk.index]) if ok else int(np.max(pk.status)))
        return {k: np.asarray(v) for k, v in out.items()}


class RobustPeak(AbstractQuestion):
    """The largest amplitude over ``band`` among every stable coexisting response found
    (``aj.robust_peak``, its options as there), one design after the other.

    Answer per design: ``peak`` [m], ``peak_omega`` [rad/s], ``status``."""

    band: tuple
    amplitude: object
    options: dict

    def __init__(self, band, *, amplitude, **options):
        self.band = _band("RobustPeak", band)
        self.amplitude = sweep_shape(amplitude, "RobustPeak")
        self.options = dict(options)

    def coords(self, system):
        return {}

    def variables(self, system):
        return _peak_variables(system, "robust peak", located=False)

    def points(self, system):
        return 1        # one peak search per design

    def describe(self):
        return (f"RobustPeak(band {self.band[0]:g}..{self.band[1]:g} rad/s, amplitude "
                f"{_force(self.amplitude)}, options {self.options!r})")

    def compute(self, system, params):
        out = {k: [] for k in ("peak", "peak_omega", "status")}
        for i in range(_count(params)):
            rp = _quietly(robust_peak, _design_system(system, params, i), self.band,
                          amplitude=self.amplitude, **self.options)
            value = float(rp.value)
            out["peak"].append(value)
            out["peak_omega"].append(float(rp.omega))
            out["status"].append(0 if np.isfinite(value) else int(Status.NO_CONVERGENCE))
        return {k: np.asarray(v) for k, v in out.items()}


class Attractors(AbstractQuestion):
    """The attractor map at each of ``omegas`` [rad/s] (``aj.attractors``: ``samples``
    initial conditions marched, their end states grouped): how many distinct attractors
    coexist, and the largest and smallest stable periodic amplitudes among them.

    Answer per design and frequency: ``attractors`` (count), ``periodic`` (how many are
    periodic), ``largest`` and ``smallest`` amplitude [m] among the periodic ones."""

    omegas: np.ndarray
    amplitude: float
    samples: int = eqx.field(static=True)
    options: dict

    def __init__(self, omegas, *, amplitude, samples=16, **options):
        check_time_grid("omegas", omegas, strictly=True)
        self.omegas = np.asarray(omegas, dtype=float)
        self.amplitude = float(amplitude)
        if not isinstance(samples, int) or samples < 1:
            raise ValueError(f"Attractors.samples must be a positive integer, got "
                             f"{samples!r}")
        self.samples, self.options = samples, dict(options)

    def coords(self, system):
        return {"omega": self.omegas}

    def variables(self, system):
        u = signals_of(system).observable_unit
        return {
            "attractors": (("omega",), "", "distinct attractors found", "i4"),
            "periodic": (("omega",), "", "periodic attractors among them", "i4"),
            "largest": (("omega",), u, "largest periodic amplitude", "f8"),
            "smallest": (("omega",), u, "smallest periodic amplitude", "f8"),
        }

    def points(self, system):
        return int(self.omegas.size)

    def describe(self):
        return (f"Attractors({_grid(self.omegas)}, amplitude {self.amplitude:g} N, "
                f"{self.samples} samples, options {self.options!r})")

    def compute(self, system, params):
        P, F = _count(params), self.omegas.size
        out = {"attractors": np.zeros((P, F), np.int32), "periodic": np.zeros((P, F), np.int32),
               "largest": np.full((P, F), np.nan), "smallest": np.full((P, F), np.nan)}
        for i in range(P):
            sysi = _design_system(system, params, i)
            for j, w in enumerate(self.omegas):
                amap = _quietly(attractors, sysi, at_frequency(self.amplitude, float(w)),
                                samples=self.samples, **self.options)
                per = [a.amplitude for a in amap.attractors if a.periodic]
                out["attractors"][i, j] = len(amap.attractors)
                out["periodic"][i, j] = len(per)
                if per:
                    out["largest"][i, j], out["smallest"][i, j] = max(per), min(per)
        return out


def _peak_variables(system, what, *, located):
    """The answer of a peak question: ``peak`` [the observable's unit], ``peak_omega``
    [rad/s], (``located``,) ``status``."""
    sig = signals_of(system)
    out = {"peak": ((), sig.observable_unit, f"{what} amplitude of {sig.observable}", "f8"),
           "peak_omega": ((), "rad/s", f"frequency of the {what}", "f8")}
    if located:
        out["located"] = ((), "", "peak located (dA/dω = 0)", "bool")
    out["status"] = ((), "", "0 converged; else aj.describe(status)", "i4")
    return out


def _grid(omegas):
    return f"{omegas.size} frequencies {omegas[0]:g}..{omegas[-1]:g} rad/s"


def _force(amplitude):
    return f"{amplitude:g} N" if isinstance(amplitude, (int, float)) else repr(amplitude)


def _band(owner, band):
    try:
        lo, hi = (float(b) for b in band)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}.band must be (lo, hi) [rad/s], got {band!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo < hi):
        raise ValueError(f"{owner}.band must satisfy 0 < lo < hi [rad/s], got {band!r}")
    return (lo, hi)


def _count(params):
    return int(next(iter(params.values())).shape[0])

