"""Results as tables and labelled datasets: the columns of their CSV files and data frames
(headers with SI units, ``units``) and their ``xarray.Dataset``s, built from the one
table of units and labels (``units.FIELDS``).

The result classes (``FrequencyResponse``, ``Branch``, ``SteadyState``, ``Trajectory``,
``AttractorMap``) call these from their ``to_csv``, ``to_dataframe`` and ``to_xarray``;
this module reads their fields by name and imports none of them.  ``pandas`` and ``xarray``
are optional: imported when a data frame or dataset is asked for.

Values are SI (metres, radians, seconds, newtons); the measured fields are NaN at failed
points (``status != 0``).
"""

from __future__ import annotations

import csv
import importlib

import numpy as np

from .status import Status, describe, flag_attributes, name
from .units import Signals, column, long_name, signals_of, unit_of, with_unit

# the scalar fields of a steady-state result, in column order, then the per-degree-of-freedom
# ones
SCALARS = ("amplitude", "rms", "harmonic", "absorber_amplitude", "absorber_rms", "impacts",
           "contact_fraction")
PER_DOF = ("dof_amplitude", "dof_rms", "dof_harmonic")
INTEGER = ("period_multiple", "stable", "status", "iterations")


def require(module, what):
    """Import the optional ``module`` (``"xarray"``, ``"pandas"``) for ``what``, or raise an
    ImportError saying how to install it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise ImportError(f"{what} needs {module}, an optional dependency: "
                          f"pip install {module}  (or pip install 'absorber_jax[io]')") from None


# ----------------------------------------------------------------------- tables (CSV, pandas)


def write_csv(path, columns):
    """Write ``columns`` (``[(header, 1-D values)]``, one row per index) as CSV: the
    headers, then the values (floats in full precision, ``nan`` where missing)."""
    headers = [h for h, _ in columns]
    cells = [_cells(v) for _, v in columns]
    rows = len(cells[0]) if cells else 0
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(headers)
        for i in range(rows):
            w.writerow([c[i] for c in cells])


def _cells(values):
    a = np.asarray(values)
    if a.dtype == bool or np.issubdtype(a.dtype, np.integer):
        return [int(v) for v in a]
    if np.issubdtype(a.dtype, np.floating):
        return [float(v) for v in a]
    return [str(v) for v in a]


def dataframe(columns, what="to_dataframe"):
    """A ``pandas.DataFrame`` of ``columns`` (headers with units, as in the CSV files)."""
    pd = require("pandas", what)
    return pd.DataFrame({h: np.asarray(v) for h, v in columns})


def _status_text(status):
    return np.array([describe(c, hint=False) for c in np.ravel(status)], dtype=object)


def steady_columns(steady, signals, dof_names, rows):
    """Columns of a batched steady-state result flattened to ``rows`` points: the
    observable's and the stroke's statistics, impacts, period multiple, stability, status,
    residual, iterations, largest |multiplier|, each degree of freedom's statistics, the
    status text."""
    cols = [(column(f, signals), np.asarray(getattr(steady, f), float).reshape(rows))
            for f in SCALARS]
    for f in ("period_multiple", "stable", "status", "residual", "iterations"):
        a = np.asarray(getattr(steady, f)).reshape(rows)
        cols.append((column(f, signals), a.astype(int) if f in INTEGER else a.astype(float)))
    mult = np.abs(np.asarray(steady.multipliers)).reshape(rows, -1)
    cols.append((column("max_multiplier", signals),
                 mult.max(axis=1) if mult.shape[1] else np.full(rows, np.nan)))
    for f in PER_DOF:
        a = np.asarray(getattr(steady, f), float).reshape(rows, -1)
        cols += [(column(f, signals, d), a[:, j]) for j, d in enumerate(dof_names)]
    cols.append(("status text", _status_text(np.asarray(steady.status))))
    return cols


def frequency_response_columns(frf):
    """One row per (design, frequency): the sweep direction, the design parameters, ``omega``
    and ``steady_columns``."""
    sig = frf.signals
    status = np.atleast_2d(np.asarray(frf.status))
    P, F = status.shape
    om = np.broadcast_to(np.asarray(frf.omegas, float)[None, :], (P, F)).reshape(-1)
    cols = [("direction", np.full(P * F, frf.direction, dtype=object))]
    for k, v in frf.params.items():
        vals = np.broadcast_to(np.asarray(v, float)[:, None], (P, F)).reshape(-1)
        cols.append((with_unit(k, sig.parameter_unit(k)), vals))
    cols.append((column("omega", sig), om))
    return cols + steady_columns(frf.steady, sig, frf.dof_names, P * F)


def branch_columns(br):
    """One row per branch point: its index, the parameter and ``steady_columns``."""
    sig = br.signals
    n = len(br)
    return ([("point", np.arange(n)),
             (with_unit(br.parameter, sig.parameter_unit(br.parameter)),
              np.asarray(br.values, float))]
            + steady_columns(br.steady, sig, br.dof_names, n))


def _forces(tr, system):
    """The coupling force column(s) of a trajectory: one, or one per element."""
    f = np.asarray(tr.coupling_force, float)
    if f.ndim == 1:
        return [(with_unit("coupling force", "N"), f)]
    f = f.reshape(f.shape[0], -1)
    names = list(system.force_names)
    if len(names) != f.shape[1]:
        names = [str(j) for j in range(f.shape[1])]
    return [(with_unit(f"force {nm}", "N"), f[:, j]) for j, nm in enumerate(names)]


def _outputs(tr):
    """``(names, values (T, dofs))`` of a trajectory's degrees of freedom."""
    import jax

    s = jax.vmap(tr.system.to_internal)(tr.ys)
    return tuple(tr.system.output_names), np.asarray(jax.vmap(tr.system.outputs)(s))


def trajectory_columns(tr):
    """One row per save time: ``t [s]``, the public state, the degrees of freedom that are
    not state components (a structure's floors), the coupling force(s) and the friction
    quantities and energies when present."""
    sys_ = tr.system
    sig = signals_of(sys_)
    ys = np.asarray(tr.ys, float)
    cols = [(with_unit("t", "s"), np.asarray(tr.ts, float))]
    cols += [(with_unit(n, sig.state_unit(n)), ys[:, j]) for j, n in enumerate(sys_.state_names)]
    names, out = _outputs(tr)
    cols += [(with_unit(n, sig.dof_unit(n)), out[:, j]) for j, n in enumerate(names)
             if n not in sys_.state_names]
    cols += _forces(tr, sys_)
    extra = (("friction_force", "friction force"), ("force_ratio", "force ratio |Fa|/|Fnl|"),
             ("regime", "regime"), ("work", "work"), ("dissipated", "dissipated"))
    for f, stem in extra:
        v = getattr(tr, f)
        if v is not None:
            a = np.asarray(v)
            cols.append((with_unit(stem, unit_of(f)),
                         a.astype(int) if f == "regime" else a.astype(float)))
    return cols


def attractor_columns(am):
    """One row per initial state: ``omega``, the sample index, the initial state, the
    attractor it settled on (index, periodic, period multiple), the window statistics, the
    marching status."""
    sig = am.signals
    K = am.label.shape[0]
    y0 = np.asarray(am.initial_states, float)
    names = sig.state_names if len(sig.state_names) == y0.shape[1] else tuple(
        f"s{j}" for j in range(y0.shape[1]))
    cols = [(column("omega", sig), np.full(K, float(am.omega))), ("sample", np.arange(K))]
    cols += [(with_unit(f"y0 {n}", sig.state_unit(n)), y0[:, j]) for j, n in enumerate(names)]
    label = np.asarray(am.label, int)
    periodic = np.array([int(am.attractors[i].periodic) if i >= 0 else -1 for i in label])
    cols += [("attractor", label), ("periodic", periodic),
             ("period multiple", np.array([am.attractors[i].period_multiple if i >= 0 else -1
                                           for i in label]))]
    for f in ("amplitude", "rms", "peak"):
        cols.append((column(f, sig), np.asarray(getattr(am, f), float)))
    cols += [(with_unit("spread", "1"), np.asarray(am.spread, float)),
             (column("impacts", sig), np.asarray(am.impacts, float)),
             (with_unit("lyapunov", "1/s"), np.asarray(am.lyapunov, float)),
             ("marching status", np.asarray(am.steady.status, int)),
             ("status text", _status_text(np.asarray(am.steady.status)))]
    return cols


# ----------------------------------------------------------------------------- xarray


def _attrs(field, signals, dof=None, **extra):
    out = {"long_name": long_name(field, signals, dof), "units": unit_of(field, signals, dof)}
    if field == "status":
        out.update(flag_attributes())
    out.update(extra)
    return {k: v for k, v in out.items() if not (k == "units" and v == "")}


def _names_or_index(names, size, stem):
    names = tuple(names)
    return names if len(names) == size else tuple(f"{stem}{j}" for j in range(size))


def _per_component_units(units):
    """One ``units`` attribute for a variable over components of ``units``: the common unit,
    or ``"m or rad"``-style when they differ (the per-component units are a coordinate)."""
    distinct = sorted(set(u for u in units if u))
    return distinct[0] if len(distinct) == 1 else " or ".join(distinct)


def steady_variables(steady, signals, dof_names, dims):
    """``{name: (dims, values, attrs)}`` of a steady-state result over ``dims`` (the
    status's axes), and the coordinates of its component axes (``dof``, ``state``,
    ``multiplier``)."""
    status = np.asarray(steady.status)
    data = {f: (dims, np.asarray(getattr(steady, f), float), _attrs(f, signals))
            for f in SCALARS}
    for f in ("period_multiple", "stable", "status", "iterations"):
        data[f] = (dims, np.asarray(getattr(steady, f)).astype(int), _attrs(f, signals))
    data["residual"] = (dims, np.asarray(steady.residual, float), _attrs("residual", signals))
    data["status_name"] = (dims, np.vectorize(name, otypes=[object])(status)
                           if status.size else status.astype(object),
                           {"long_name": "result code name (see status)"})
    coords = {}
    dofs = np.asarray(steady.dof_amplitude)
    if dofs.ndim > status.ndim:
        dn = _names_or_index(dof_names, dofs.shape[-1], "dof")
        units = [signals.dof_unit(d) for d in dn]
        coords["dof"] = ("dof", list(dn), {"long_name": "degree of freedom"})
        coords["dof_unit"] = ("dof", units, {"long_name": "SI unit of each degree of freedom"})
        for f in PER_DOF:
            data[f] = (dims + ("dof",), np.asarray(getattr(steady, f), float),
                       _attrs(f, signals, units=_per_component_units(units)))
    state = np.asarray(steady.state, float)
    sn = _names_or_index(signals.state_names, state.shape[-1], "s")
    s_units = [signals.state_unit(n) for n in sn]
    coords["component"] = ("component", list(sn), {"long_name": "public state component"})
    coords["component_unit"] = ("component", s_units,
                                {"long_name": "SI unit of each state component"})
    data["state"] = (dims + ("component",), state,
                     _attrs("state", signals, units=_per_component_units(s_units)))
    mult = np.asarray(steady.multipliers)
    data["multipliers"] = (dims + ("multiplier",), mult, _attrs("multipliers", signals))
    data["max_multiplier"] = (dims, np.abs(mult).max(axis=-1) if mult.shape[-1] else
                              np.full(status.shape, np.nan), _attrs("max_multiplier", signals))
    return data, coords


def _dataset_attrs(signals, **extra):
    return {"observable": signals.observable, "observable_units": signals.observable_unit,
            "stroke": signals.stroke,
            "conventions": "SI units; measured fields are NaN where status != 0",
            **extra}


def frequency_response_dataset(frf):
    """``xarray.Dataset`` of a ``FrequencyResponse`` over ``omega`` (and ``design``
    when it holds several designs, with each design parameter as a coordinate)."""
    xr = require("xarray", "FrequencyResponse.to_xarray")
    sig = frf.signals
    designs = np.ndim(frf.status) == 2
    dims = ("design", "omega") if designs else ("omega",)
    data, coords = steady_variables(frf.steady, sig, frf.dof_names, dims)
    coords["omega"] = ("omega", np.asarray(frf.omegas, float), _attrs("omega", sig))
    if designs:
        coords["design"] = ("design", np.arange(np.shape(frf.status)[0]),
                            {"long_name": "design index"})
        for k, v in frf.params.items():
            coords[k] = ("design", np.asarray(v, float),
                         {"long_name": f"design parameter {k}", "units": sig.parameter_unit(k)})
    return xr.Dataset(data, coords=coords,
                      attrs=_dataset_attrs(sig, direction=frf.direction))


def branch_dataset(br):
    """``xarray.Dataset`` of a continuation ``Branch`` over its ``point``s (the
    parameter a coordinate along them: it turns back at folds), with its bifurcations over
    ``bifurcation``."""
    xr = require("xarray", "Branch.to_xarray")
    sig = br.signals
    data, coords = steady_variables(br.steady, sig, br.dof_names, ("point",))
    coords["point"] = ("point", np.arange(len(br)), {"long_name": "branch point index"})
    punit = sig.parameter_unit(br.parameter)
    coords[br.parameter] = ("point", np.asarray(br.values, float),
                            {"long_name": f"continuation parameter {br.parameter}",
                             **({"units": punit} if punit else {})})
    bifs = br.bifurcations
    b = ("bifurcation",)
    data["bifurcation_kind"] = (b, np.array([x.kind for x in bifs], dtype=object),
                                {"long_name": "bifurcation kind"})
    data["bifurcation_value"] = (b, np.array([float(x.value) for x in bifs]),
                                 {"long_name": f"located {br.parameter}",
                                  **({"units": punit} if punit else {})})
    data["bifurcation_amplitude"] = (b, np.array([float(x.amplitude) for x in bifs]),
                                     _attrs("amplitude", sig))
    data["bifurcation_index"] = (b, np.array([x.index for x in bifs], dtype=int),
                                 {"long_name": "lies between points index and index + 1"})
    data["bifurcation_located"] = (b, np.array([bool(x.located) for x in bifs], dtype=bool),
                                   {"long_name": "located onto a zero of the test function"})
    return xr.Dataset(data, coords=coords, attrs=_dataset_attrs(
        sig, parameter=br.parameter, period_multiple=int(br.period_multiple),
        termination=br.termination))


def steady_dataset(ss, system=None):
    """``xarray.Dataset`` of a ``SteadyState`` (one orbit, or a batch over
    ``point``); names and units from ``system`` when given, else generic."""
    xr = require("xarray", "SteadyState.to_xarray")
    sig = signals_of(system) if system is not None else Signals(
        dofs=(), states=(), observable="observable", stroke="absorber stroke")
    dof_names = tuple(system.output_names) if system is not None else ()
    status = np.asarray(ss.status)
    dims = tuple(["point"] if status.ndim == 1 else [f"axis{i}" for i in range(status.ndim)])
    data, coords = steady_variables(ss, sig, dof_names, dims)
    return xr.Dataset(data, coords=coords, attrs=_dataset_attrs(sig))


def trajectory_dataset(tr):
    """``xarray.Dataset`` of a ``Trajectory`` over ``time`` [s]: one variable per
    public state component (with its unit), the degrees of freedom over ``dof``, the
    observable, the coupling force(s) and whatever friction and energy fields it holds."""
    xr = require("xarray", "Trajectory.to_xarray")
    sys_ = tr.system
    sig = signals_of(sys_)
    t = ("time",)
    ys = np.asarray(tr.ys, float)
    data = {}
    for j, n in enumerate(sys_.state_names):
        data[n] = (t, ys[:, j], {"long_name": f"state component {n}",
                                 **({"units": sig.state_unit(n)} if sig.state_unit(n) else {})})
    names, out = _outputs(tr)
    units = [sig.dof_unit(n) for n in names]
    data["dof_displacement"] = (t + ("dof",), out, {
        "long_name": "absolute displacement of each degree of freedom",
        "units": _per_component_units(units)})
    data["observable"] = (t, np.asarray(tr.observed(), float),
                          {"long_name": f"observable {sig.observable}",
                           "units": sig.observable_unit})
    f = np.asarray(tr.coupling_force, float)
    if f.ndim == 1:
        data["coupling_force"] = (t, f, _attrs("coupling_force", sig))
    else:
        f = f.reshape(f.shape[0], -1)
        data["coupling_force"] = (t + ("element",), f, {"long_name": "force of each element",
                                                        "units": "N"})
    for field in ("friction_force", "force_ratio", "regime", "sliding", "work", "dissipated"):
        v = getattr(tr, field)
        if v is not None:
            a = np.asarray(v)
            a = a.astype(int) if field in ("regime", "sliding") else a.astype(float)
            data[field] = (t, a, _attrs(field, sig))
    coords = {"time": ("time", np.asarray(tr.ts, float), _attrs("time", sig)),
              "dof": ("dof", list(names), {"long_name": "degree of freedom"}),
              "dof_unit": ("dof", units, {"long_name": "SI unit of each degree of freedom"})}
    if f.ndim == 2:
        en = list(getattr(sys_, "element_names", ()))
        coords["element"] = ("element", en if len(en) == f.shape[1] else list(range(f.shape[1])),
                             {"long_name": "element"})
    status = int(np.asarray(tr.status))
    data["status"] = ((), status, _attrs("status", sig))
    data["num_steps"] = ((), int(np.asarray(tr.num_steps)), _attrs("num_steps", sig))
    return xr.Dataset(data, coords=coords, attrs=_dataset_attrs(
        sig, solver=tr.solver, status_name=name(status),
        status_text=describe(status)))


def attractor_dataset(am):
    """``xarray.Dataset`` of an ``AttractorMap`` over its initial states (``sample``):
    the initial states, window statistics, stroboscopic samples (``sample``, ``period``),
    the attractor label, the marching result; the distinct attractors over ``attractor``."""
    xr = require("xarray", "AttractorMap.to_xarray")
    sig = am.signals
    s = ("sample",)
    y0 = np.asarray(am.initial_states, float)
    sn = _names_or_index(sig.state_names, y0.shape[1], "s")
    s_units = [sig.state_unit(n) for n in sn]
    data = {
        "initial_state": (s + ("component",), y0, {"long_name": "public initial state",
                                               "units": _per_component_units(s_units)}),
        "label": (s, np.asarray(am.label, int), _attrs("label", sig)),
        "section": (s + ("period",), np.asarray(am.section, float), _attrs("section", sig)),
    }
    for f in ("amplitude", "rms", "peak", "spread", "impacts", "lyapunov"):
        data[f] = (s, np.asarray(getattr(am, f), float),
                   _attrs(f, sig, long_name=long_name(f, sig) + " (statistics window)"))
    st = np.asarray(am.steady.status, int)
    data["status"] = (s, st, _attrs("status", sig, long_name="marching result code"))
    data["status_name"] = (s, np.array([name(c) for c in st], dtype=object),
                           {"long_name": "marching result code name"})
    data["period_multiple"] = (s, np.asarray(am.steady.period_multiple, int),
                               _attrs("period_multiple", sig))
    data["stable"] = (s, np.asarray(am.steady.stable, int), _attrs("stable", sig))
    a = ("attractor",)
    found = am.attractors
    data["attractor_kind"] = (a, np.array([x.kind for x in found], dtype=object),
                              {"long_name": "periodic, quasi-periodic, chaotic or not periodic"})
    data["attractor_period_multiple"] = (a, np.array([x.period_multiple for x in found], int),
                                         _attrs("period_multiple", sig))
    data["attractor_share"] = (a, np.array([float(x.share) for x in found]),
                               {"long_name": "fraction of the initial states", "units": "1"})
    data["attractor_amplitude"] = (a, np.array([float(x.amplitude) for x in found]),
                                   _attrs("amplitude", sig))
    data["attractor_peak"] = (a, np.array([float(x.peak) for x in found]), _attrs("peak", sig))
    data["attractor_stable"] = (a, np.array([bool(x.stable) for x in found]),
                                _attrs("stable", sig))
    coords = {"sample": ("sample", np.arange(y0.shape[0]), {"long_name": "initial state index"}),
              "component": ("component", list(sn), {"long_name": "public state component"}),
              "component_unit": ("component", s_units,
                                 {"long_name": "SI unit of each state component"}),
              "period": ("period", np.arange(np.shape(am.section)[1]),
                         {"long_name": "forcing period of the statistics window"}),
              "attractor": ("attractor", np.arange(len(found)), {"long_name": "attractor index"}),
              "omega": ((), float(am.omega), _attrs("omega", sig))}
    return xr.Dataset(data, coords=coords, attrs=_dataset_attrs(
        sig, forcing_amplitude=float(am.amplitude_F0), forcing_amplitude_units="N"))


def failure_list(status):
    """``[(index tuple, description with what to try)]`` of the entries of ``status`` that
    are not ``SUCCESS``."""
    status = np.asarray(status)
    idx = np.argwhere(status != Status.SUCCESS)
    return [(tuple(int(j) for j in i), describe(status[tuple(i)])) for i in idx]
