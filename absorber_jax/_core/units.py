"""Units and labels of results: one table (``FIELDS``: field -> long name, unit) that the
result classes' CSV writers, ``to_xarray`` / ``to_dataframe`` and the plots share.

Files and datasets hold SI values (metres, radians, seconds, newtons); a CSV header names
each column's unit (``omega [rad/s]``, ``amplitude x1 [m]``).  Plots may show millimetres and
say so in their labels (``display_scale``).

What a result measures depends on its system: the *observable* (the signal of
``amplitude``, ``rms``, ``harmonic``: ``x1`` for the two-mass systems, a degree of freedom
or a weighted set of them for a structure), the absorber *stroke* (the absorber's motion
relative to its host: ``x2 - x1``), the degrees of freedom (``dof_*``: absolute
displacements) and the state components.  ``signals_of`` reads them off a system into a
``Signals``, which results carry.  Columns:

- ``amplitude <observable> [m]`` (also ``rms``, ``harmonic``): the observable;
- ``amplitude <stroke> [m]`` (also ``rms``), e.g. ``amplitude x2 - x1 [m]``: the relative
  motion, ``absorber_amplitude`` and ``absorber_rms``;
- ``dof amplitude <dof> [m]`` (also ``dof rms``, ``dof harmonic``): the absolute
  displacement of each degree of freedom (``dof amplitude x2 [m]``: the absorber mass's own
  motion, not its stroke).
"""

from __future__ import annotations

import dataclasses
import re

# the unit of the signal the field measures (m, or rad for a rotation)
SIGNAL = "<signal>"

# field -> (long name, unit); ``{observable}``, ``{stroke}``, ``{dof}`` are filled from the
# result's Signals; SIGNAL: the unit of that signal
FIELDS = {
    "omega": ("forcing frequency", "rad/s"),
    "time": ("time", "s"),
    "amplitude": ("amplitude of {observable} (half peak-to-peak)", SIGNAL),
    "rms": ("RMS of {observable} about zero", SIGNAL),
    "harmonic": ("first-harmonic magnitude of {observable} (at the forcing frequency)", SIGNAL),
    "absorber_amplitude": ("amplitude of the absorber stroke {stroke} (relative motion, "
                           "half peak-to-peak)", "m"),
    "absorber_rms": ("RMS of the absorber stroke {stroke} (relative motion)", "m"),
    "impacts": ("contact closures per forcing period", "1"),
    "contact_fraction": ("fraction of the response period with a contact closed (held "
                         "against a wall, for rigid impacts)", "1"),
    "dof_amplitude": ("amplitude of {dof} (absolute displacement, half peak-to-peak)", SIGNAL),
    "dof_rms": ("RMS of {dof} (absolute displacement)", SIGNAL),
    "dof_harmonic": ("first-harmonic magnitude of {dof} (absolute displacement)", SIGNAL),
    "period_multiple": ("response period in forcing periods", "1"),
    "stable": ("stable orbit (Floquet multipliers within the unit circle)", ""),
    "status": ("result code (0 = success)", ""),
    "residual": ("periodicity residual max |x(nT) - x(0)| on the state scaled to order one",
                 "1"),
    "iterations": ("Newton steps, or forcing periods marched", ""),
    "state": ("public state at t = 0 mod nT", SIGNAL),
    "multipliers": ("Floquet multipliers of the period-nT map", "1"),
    "max_multiplier": ("largest Floquet multiplier modulus", "1"),
    "peak": ("largest |{observable}| over the statistics window", SIGNAL),
    "spread": ("spread of the Poincaré samples (scaled state; 0 for a periodic response)",
               "1"),
    "lyapunov": ("largest Lyapunov exponent", "1/s"),
    "section": ("{observable} at t = kT (stroboscopic samples)", SIGNAL),
    "label": ("attractor index (-1: window failed)", ""),
    "coupling_force": ("force of the coupling on the primary (contact force of an impact "
                       "absorber)", "N"),
    "friction_force": ("friction force", "N"),
    "force_ratio": ("|Fa| / |Fnl| (absorber inertia force over friction force)", "1"),
    "regime": ("friction regime (0 jammed, 1 partially gliding, 2 totally gliding)", ""),
    "sliding": ("gross sliding", ""),
    "work": ("work done by the forcing", "J"),
    "dissipated": ("energy dissipated", "J"),
    "num_steps": ("integrator steps", ""),
}

# the column stem of a field in a CSV / data frame (before the signal's name)
_STEMS = {"amplitude": "amplitude", "rms": "rms", "harmonic": "harmonic",
          "absorber_amplitude": "amplitude", "absorber_rms": "rms",
          "dof_amplitude": "dof amplitude", "dof_rms": "dof rms",
          "dof_harmonic": "dof harmonic", "impacts": "impacts per period",
          "contact_fraction": "contact fraction",
          "period_multiple": "period multiple", "stable": "stable", "status": "status",
          "residual": "residual", "iterations": "iterations",
          "max_multiplier": "max |multiplier|", "peak": "peak", "spread": "spread",
          "lyapunov": "lyapunov", "label": "attractor", "omega": "omega", "time": "t"}

# parameter units by field name (after aliases are resolved to a field path)
_PARAMETER_UNITS = {
    "M": "kg", "m": "kg", "m1": "kg", "m2": "kg", "mass": "kg",
    "k": "N/m", "k1": "N/m", "k2": "N/m",
    "c": "N s/m", "c1": "N s/m", "c2": "N s/m",
    "gap": "m", "N": "N", "normal_force": "N", "e": "1",
    "mu": "1", "mu_c": "1", "mu_s": "1", "v_s": "m/s",
    "sigma0": "N/m", "sigma1": "N s/m", "sigma2": "N s/m",
}


@dataclasses.dataclass(frozen=True)
class Signals:
    """What a system's results measure, by name and SI unit (``signals_of``).

    ``observable``: the signal of ``amplitude``, ``rms``, ``harmonic`` (``"x1"``, a
    degree of freedom, or a weighted sum such as ``"floor3 - floor2"``); ``stroke``: the
    absorber's motion relative to its host that ``absorber_amplitude`` measures
    (``"x2 - x1"``); ``dofs``, ``states``, ``parameters``: ``(name, unit)`` pairs of the
    degrees of freedom (absolute displacements), the public state components and the
    named parameters."""

    observable: str = "x1"
    observable_unit: str = "m"
    stroke: str = "x2 - x1"
    dofs: tuple = (("x1", "m"), ("x2", "m"))
    states: tuple = (("x1", "m"), ("v1", "m/s"), ("x2", "m"), ("v2", "m/s"))
    parameters: tuple = ()

    def dof_unit(self, name) -> str:
        return dict(self.dofs).get(name, "m")

    def state_unit(self, name) -> str:
        return dict(self.states).get(name, "")

    def parameter_unit(self, name) -> str:
        """The SI unit of parameter ``name`` (``"omega"``, ``"amplitude"`` too); ``""`` when
        unknown."""
        if name == "omega":
            return "rad/s"
        if name == "amplitude":
            return "N"
        return dict(self.parameters).get(name, "")

    @property
    def state_names(self) -> tuple:
        return tuple(n for n, _ in self.states)


def dof_unit(name: str) -> str:
    """``"rad"`` for a rotational degree of freedom (``th<i>``: a beam's slopes, see
    ``cantilever_beam``), else ``"m"``."""
    return "rad" if re.fullmatch(r"th\d+", str(name)) else "m"


def field_unit(field) -> str:
    """SI unit of a design parameter by its field name (``m``, ``k``, ``gap``, ``N``,
    ``mu``, ``sigma0`` ...); ``""`` when unknown.  Laws and elements refine it through
    their ``field_unit`` methods (a Hertzian stiffness, a friction law's ``eps``)."""
    return _PARAMETER_UNITS.get(field, "")


def common_unit(units):
    """The one unit of ``units``, or ``"a or b"`` where they differ (``"m"`` for none)."""
    units = sorted(set(units))
    return units[0] if len(units) == 1 else " or ".join(units) if units else "m"


def weighted_name(names, weights):
    """``"x3 - x2"``, ``"0.5 x1 + 0.5 x2"``: a readable weighted sum (positive terms
    first)."""
    order = sorted(range(len(names)), key=lambda i: weights[i] < 0)
    text = ""
    for k, (n, w) in enumerate((names[i], weights[i]) for i in order):
        sign = "-" if w < 0 else "+"
        mag = abs(w)
        term = n if mag == 1.0 else f"{mag:g} {n}"
        text += (("-" if sign == "-" else "") + term) if k == 0 else f" {sign} {term}"
    return text


def state_unit(name, dof_units, identity_map):
    """Unit of a public state component by its name (two-mass: ``x1, v1, x2, v2, z<i>``;
    structure: ``q<i>, qd<i>, <element>.u|w|z<i>``)."""
    last = name.split(".")[-1]
    if re.fullmatch(r"qd\d+", last):
        i = int(last[2:]) - 1
        return (dof_units[i] + "/s") if identity_map and i < len(dof_units) else ""
    if re.fullmatch(r"q\d+", last):
        i = int(last[1:]) - 1
        return dof_units[i] if identity_map and i < len(dof_units) else ""
    if re.fullmatch(r"[xuz]\d*", last):   # displacements, strokes, bristle deflections
        return "m"
    if re.fullmatch(r"[vw]\d*", last):
        return "m/s"
    return ""


def _parameter_unit(system, name):
    """The unit of parameter ``name``: its field's unit as the module that holds it gives
    it (``field_unit``: systems, elements and laws each refine the common table)."""
    try:
        path = system.parameter_path(name)
    except Exception:  # noqa: BLE001 - any system: no unit rather than an error
        return ""
    parts = path.split(".")
    owner = system
    for part in parts[:-1]:
        owner = owner[int(part)] if part.isdigit() else getattr(owner, part)
    return owner.field_unit(parts[-1])


def generic_signals(system) -> Signals:
    """The ``Signals`` of a system whose outputs are its degrees of freedom, the first
    observed and the second the absorber (the two-mass absorbers, and the default of
    ``AbstractSystem.signals``)."""
    dof_names = tuple(system.output_names)
    dofs = tuple((n, dof_unit(n)) for n in dof_names)
    observable, obs_unit = (dof_names[0], dofs[0][1]) if dof_names else ("observable", "m")
    stroke = f"{dof_names[1]} - {dof_names[0]}" if len(dof_names) == 2 else "absorber stroke"
    states = tuple((n, state_unit(n, [], False)) for n in system.state_names)
    return Signals(observable=observable, observable_unit=obs_unit, stroke=stroke, dofs=dofs,
                   states=states, parameters=parameter_units(system))


def parameter_units(system) -> tuple:
    """``(name, unit)`` of every named parameter of ``system``."""
    return tuple((n, _parameter_unit(system, n)) for n in system.parameter_names())


def signals_of(system) -> Signals:
    """The ``Signals`` of a system: ``system.signals()`` (each system says what its results
    measure)."""
    return system.signals()


def unit_of(field, signals: Signals | None = None, dof=None) -> str:
    """SI unit of ``field`` (at degree of freedom ``dof`` for ``dof_*`` fields, at the state
    component ``dof`` for ``state``); a field not in ``FIELDS`` is a parameter."""
    signals = Signals() if signals is None else signals
    unit = FIELDS[field][1] if field in FIELDS else signals.parameter_unit(field)
    if unit != SIGNAL:
        return unit
    if field == "state":
        return signals.state_unit(dof)
    if field.startswith("dof_"):
        return signals.dof_unit(dof)
    return signals.observable_unit


def long_name(field, signals: Signals | None = None, dof=None) -> str:
    """What ``field`` is, in words, with the result's signal names filled in."""
    signals = Signals() if signals is None else signals
    if field not in FIELDS:
        return f"parameter {field}"
    text = FIELDS[field][0]
    return text.format(observable=signals.observable, stroke=signals.stroke,
                       dof=dof if dof is not None else "each degree of freedom")


def with_unit(name, unit) -> str:
    """``"name [unit]"`` (``name`` alone without a unit)."""
    return f"{name} [{unit}]" if unit else name


def column(field, signals: Signals | None = None, dof=None) -> str:
    """The CSV / data-frame column header of ``field``: its stem, the signal it measures and
    its SI unit (``"amplitude x1 [m]"``, ``"amplitude x2 - x1 [m]"``,
    ``"dof amplitude x2 [m]"``, ``"omega [rad/s]"``)."""
    signals = Signals() if signals is None else signals
    stem = _STEMS.get(field, field)
    if field in ("amplitude", "rms", "harmonic", "peak"):
        stem = f"{stem} {signals.observable}"
    elif field in ("absorber_amplitude", "absorber_rms"):
        stem = f"{stem} {signals.stroke}"
    elif field.startswith("dof_"):
        stem = f"{stem} {dof}"
    return with_unit(stem, unit_of(field, signals, dof))


def split_column(header: str):
    """``(name, unit)`` of a header ``"name [unit]"`` (unit ``""`` when there is none)."""
    m = re.fullmatch(r"(.*?)\s*\[([^\[\]]*)\]", header.strip())
    return (m.group(1), m.group(2)) if m else (header.strip(), "")


def display_scale(unit):
    """``(factor, unit)`` for plotting values in SI ``unit``: metres and radians shown in
    milli-units (``(1e3, "mm")``), everything else as is."""
    if unit == "m":
        return 1e3, "mm"
    if unit == "rad":
        return 1e3, "mrad"
    return 1.0, unit


def axis_label(field, signals: Signals | None = None, dof=None, unit=None) -> str:
    """An axis label: the field's long name with the signal's name, and ``unit`` (default
    the displayed unit of ``display_scale``) in brackets."""
    if unit is None:
        unit = display_scale(unit_of(field, signals, dof))[1]
    return with_unit(long_name(field, signals, dof), unit)
