"""Scene files: a structure, its elements, the load and the sweep in one TOML or JSON file,
read by ``load_scene`` and the ``absorber-jax scene`` command (user documentation: the Scene
files and the CLI page, docs/guide/scene-files.md).

The same tree in either format (TOML tables = JSON objects, arrays of tables = JSON arrays
of objects).  Every value is checked, and every bad, missing or unknown key raises a
``ValueError`` naming its path (``scene.elements[1].gap``) and what is allowed, before
anything is compiled.  Units: SI (kg, N/m, N s/m, m, rad/s, N).

```toml
title = "3-storey building, three TMDs"         # optional
description = "..."                             # optional, free text (JSON has no comments)

[structure]
type = "shear_building"           # shear_building | cantilever_beam | matrices | modes
masses = [2.0e3, 2.0e3, 1.5e3]
storey_stiffnesses = [4.0e6, 3.5e6, 3.0e6]
rayleigh = [0.2, 5e-4]            # at most one of rayleigh | damping | modal_damping
modal = {n_modes = 3, dofs = ["floor3"]}        # optional: reduce to modes, observed at dofs

[[elements]]                      # zero or more
type = "tmd"                      # tmd | impact | friction | contact | friction_contact
dof = "floor3"
m = 75.0
k = 2.9e4
c = 190.0
name = "roof_tmd"                 # optional (default <type><count>: tmd1, impact1, ...)

[[elements]]
type = "impact"
dof = "floor2"
m = 10.0
gap = 0.002
contact = {law = "kelvin_voigt", stiffness = 1e6, damping = 100.0}

[load]                            # F(t) = amplitude sin(ωt) · weights
dofs = {floor1 = 2.0e3, floor2 = 2.0e3, floor3 = 1.5e3}   # or dof = "floor1" (weight 1)
amplitude = 1.0                   # F0 [N] per unit weight

[observe]                         # optional when the load acts on one degree of freedom
dof = "floor3"                    # or dofs = {floor3 = 1.0, floor2 = -1.0} (a drift)

[sweep]                           # optional (the CLI's --omega can give it instead)
omegas = {start = 10.0, stop = 80.0, num = 64}   # or an increasing list [rad/s]
direction = "parallel"            # parallel | up | down | both
method = "shooting"               # shooting | marching

[simulate]                        # optional: settings of ``absorber-jax scene --simulate``
omega = 45.0                      # [rad/s], default the frequency of the sweep's peak
periods = 30                      # forcing periods simulated from rest

[study]                           # optional: ``absorber-jax study`` (aj.study)
question = "exact_peak"           # frequency_response (over [sweep] omegas) | exact_peak |
band = [10.0, 80.0]               #   robust_peak (over band [rad/s])
store = "roof_tmd_study.zarr"     # optional (default <out>/study.zarr)
chunk = 8                         # optional: designs per chunk

[study.monte_carlo]               # exactly one of grid | designs | monte_carlo | latin_hypercube
samples = 200
seed = 1                          # optional (default 0)
"roof_tmd.k" = {uniform = [0.95, 1.05], relative = true}   # or normal = [mean, std]
"roof_tmd.c" = {normal = [1.0, 0.02], relative = true}

# [study.grid] / [study.designs]: "name" = [values ...] per parameter (a grid: every
# combination; designs: the i-th values together, all lists the same length)
```

**structure** (``type`` and its keys; damping, for all but ``modes``: at most one of
``rayleigh = [alpha, beta]``, ``damping`` (a matrix, ``matrices`` only) and
``modal_damping`` (one ratio, or one per mode); none = undamped):

- ``shear_building``: ``masses`` [kg], ``storey_stiffnesses`` [N/m] (ground floor first);
  degrees of freedom ``floor1 … floorN``.
- ``cantilever_beam``: ``n_elements`` (integer), ``length`` [m], ``EI`` [N m²], ``rho_A``
  [kg/m]; degrees of freedom ``w1, th1, …, wN, thN`` (``wN`` the tip).
- ``matrices``: ``mass``, ``stiffness`` (square matrices as lists of rows), optional
  ``dof_names`` (default ``x1 … xN``).
- ``modes``: ``frequencies`` [rad/s], ``damping_ratios`` (one, or one per mode),
  ``mode_shapes`` (mass-normalised, ``n_dofs`` rows × ``n_modes`` columns), optional
  ``dof_names``.
- any type: ``modal = {n_modes = ..., dofs = [...]}`` (both optional) reduces the structure
  to its lowest ``n_modes`` modes observed at ``dofs`` (``LinearStructure.modal``).

**elements** (each needs ``type`` and ``dof``; ``name`` optional; numbers as in the
constructors of ``_systems.elements``):

- ``tmd``: ``m`` > 0, ``k`` >= 0, ``c`` >= 0.
- ``impact``: ``m`` > 0, ``gap`` >= 0, ``contact`` (a contact law).
- ``friction``: ``m`` > 0, ``k`` >= 0, ``c`` >= 0, ``normal_force`` >= 0, ``friction``
  (a friction law).
- ``contact``: ``gap`` >= 0, ``contact``; optional ``other`` (a degree of freedom; default
  ground), ``sides`` (``"one"`` | ``"two"``), ``direction`` (1 | -1).
- ``friction_contact``: ``normal_force`` >= 0, ``friction``; optional ``other``.

Contact laws ``{law = ..., ...}``: ``kelvin_voigt`` | ``hertz`` | ``hunt_crossley`` with
``stiffness`` > 0, ``damping`` >= 0, optional ``eps`` > 0 [m] and ``adhesive`` (bool, default
false: the wall never pulls).
Friction laws: ``coulomb`` (``mu``, ``eps``), ``stribeck`` (``mu_c``, ``mu_s``, ``v_s``,
``eps``), ``dahl`` (``mu_c``, ``sigma0``, optional ``eps``), ``lugre`` (``mu_c``, ``mu_s``,
``v_s``, ``sigma0``, ``sigma1``, optional ``sigma2``, ``eps``; without ``eps`` the bristle laws
use ``|v|`` exactly).  On a structure Coulomb and Stribeck are smoothed, so their ``eps``
[m/s] is required.

**load**: exactly one of ``dof`` (a name) or ``dofs`` (``{name: weight}``), and
``amplitude`` (F0 >= 0 [N]).  **observe**: exactly one of ``dof`` or ``dofs``.

```python
from absorber_jax._io.scene import load_scene
system, settings = load_scene("examples/building_tmds.toml")
fr = aj.frequency_response(system, settings.omegas, amplitude=settings.amplitude,
                           direction=settings.direction, method=settings.method)
```
"""

from __future__ import annotations

import dataclasses
import json
import math
import os

import numpy as np

SCENE = "scene"

STRUCTURE_TYPES = ("shear_building", "cantilever_beam", "matrices", "modes")
ELEMENT_TYPES = ("tmd", "impact", "friction", "contact", "friction_contact")
CONTACT_LAWS = ("kelvin_voigt", "hertz", "hunt_crossley")
FRICTION_LAWS = ("coulomb", "stribeck", "dahl", "lugre")
DIRECTIONS = ("parallel", "up", "down", "both")
METHODS = ("shooting", "marching")
DEFAULT_PERIODS = 30
STUDY_QUESTIONS = ("frequency_response", "exact_peak", "robust_peak")
DESIGN_KINDS = ("grid", "designs", "monte_carlo", "latin_hypercube")


@dataclasses.dataclass(frozen=True)
class StudySpec:
    """A scene file's ``[study]``: the design set, the question, the store and the chunk
    size (``None``: the defaults of ``aj.study``)."""

    designs: object
    question: object
    store: str | None = None
    chunk: int | None = None


@dataclasses.dataclass(frozen=True)
class SceneSettings:
    """What a scene file says besides the system: the load amplitude ``F0`` [N], the sweep
    (``omegas`` [rad/s] or ``None``, ``direction``, ``method``), the simulation settings
    (``simulate_omega`` [rad/s] or ``None`` = the sweep's peak, ``simulate_periods``),
    ``title``, ``description``, the file read (``source``) and its ``study``
    (a ``StudySpec`` or ``None``)."""

    amplitude: float
    omegas: np.ndarray | None = None
    direction: str = "parallel"
    method: str = "shooting"
    simulate_omega: float | None = None
    simulate_periods: int = DEFAULT_PERIODS
    title: str = ""
    description: str = ""
    source: str = ""
    study: StudySpec | None = None

    def __eq__(self, other):
        if not isinstance(other, SceneSettings):
            return NotImplemented
        sa, sb = self.study, other.study
        if (sa is None) != (sb is None) or (sa is not None and (
                sa.designs.describe(), sa.question.describe(), sa.store, sa.chunk) != (
                sb.designs.describe(), sb.question.describe(), sb.store, sb.chunk)):
            return False
        a = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        b = {f.name: getattr(other, f.name) for f in dataclasses.fields(other)}
        a.pop("study"), b.pop("study")
        oa, ob = a.pop("omegas"), b.pop("omegas")
        a.pop("source"), b.pop("source")
        same_grid = (oa is None and ob is None) or (
            oa is not None and ob is not None and np.array_equal(oa, ob))
        return a == b and same_grid


# --------------------------------------------------------------------------- readers


def toml_loads(text):
    """Parse TOML text with ``tomllib`` (Python 3.11+) or, before 3.11, ``tomli``."""
    try:
        import tomllib
    except ImportError:  # Python 3.10
        try:
            import tomli as tomllib
        except ImportError:
            raise ValueError("reading TOML scene files needs Python 3.11+ or the tomli "
                             "package (pip install tomli); JSON scene files work "
                             "everywhere") from None
    return tomllib.loads(text)


def _read(path):
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".toml", ".json"):
        raise ValueError(f"scene file must end in .toml or .json, got {path!r}")
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as e:
        raise ValueError(f"cannot read scene file {path!r}: {e.strerror or e}") from None
    try:
        if ext == ".toml":
            return toml_loads(raw.decode("utf-8"))
        return json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as e:
        raise ValueError(f"scene file {path!r} is not UTF-8 text: {e}") from None
    except ValueError as e:  # TOMLDecodeError and JSONDecodeError are ValueErrors
        raise ValueError(f"scene file {path!r} is not valid {ext[1:].upper()}: {e}") from None


# --------------------------------------------------------------------------- field checks


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _table(value, path):
    if not isinstance(value, dict):
        raise ValueError(f"{path} must be a table (an object), got {_show(value)}")
    return value


def _show(v):
    s = repr(v)
    return s if len(s) <= 60 else s[:57] + "..."


def _keys(d, path, required=(), optional=()):
    """Every key of ``d`` known, every ``required`` one present."""
    allowed = list(required) + list(optional)
    for k in d:
        if k not in allowed:
            raise ValueError(f"{path}.{k}: unknown key; allowed here: {', '.join(allowed)}")
    for k in required:
        if k not in d:
            raise ValueError(f"{path}.{k} is required (keys here: {', '.join(allowed)})")


class _Absent(Exception):
    """Raised by ``_present`` for an optional key that is missing."""


def _present(d, key, path, required, what=""):
    """``d[key]``; a missing required key is a field-named ValueError, a missing optional one
    raises ``_Absent`` (callers return their default)."""
    if key in d:
        return d[key]
    if required:
        raise ValueError(f"{path}.{key} is required{what}")
    raise _Absent


def _number(d, key, path, *, lo=None, lo_open=False, hi=None, default=None, required=True):
    try:
        v = _present(d, key, path, required)
    except _Absent:
        return default
    where = f"{path}.{key}"
    rng = (("(" if lo_open or lo is None else "[") + ("-inf" if lo is None else f"{lo:g}")
           + ", " + ("inf)" if hi is None else f"{hi:g}]"))
    if not _is_number(v) or not math.isfinite(v):
        raise ValueError(f"{where} must be a finite number in {rng}, got {_show(v)}")
    if (lo is not None and (v <= lo if lo_open else v < lo)) or (hi is not None and v > hi):
        raise ValueError(f"{where} must be in {rng}, got {v!r}")
    return float(v)


def _integer(d, key, path, *, lo=1, default=None, required=True):
    try:
        v = _present(d, key, path, required)
    except _Absent:
        return default
    ok = _is_number(v) and math.isfinite(v) and float(v).is_integer() and v >= lo
    if not ok:
        raise ValueError(f"{path}.{key} must be an integer >= {lo}, got {_show(v)}")
    return int(v)


def _string(d, key, path, *, choices=None, default=None, required=True):
    if key not in d:
        if required:
            extra = f" (one of {', '.join(choices)})" if choices else ""
            raise ValueError(f"{path}.{key} is required{extra}")
        return default
    v = d[key]
    if choices is not None and v not in choices:
        raise ValueError(f"{path}.{key} must be one of {', '.join(choices)}; got {_show(v)}")
    if not isinstance(v, str) or not v:
        raise ValueError(f"{path}.{key} must be a non-empty string, got {_show(v)}")
    return v


def _boolean(d, key, path, *, default):
    if key not in d:
        return default
    if not isinstance(d[key], bool):
        raise ValueError(f"{path}.{key} must be true or false, got {_show(d[key])}")
    return d[key]


def _vector(d, key, path, *, required=True, lo=None, lo_open=False, allow_scalar=False):
    try:
        v = _present(d, key, path, required)
    except _Absent:
        return None
    where = f"{path}.{key}"
    if allow_scalar and _is_number(v):
        v = [v]
        scalar = True
    else:
        scalar = False
    if not isinstance(v, list) or not v:
        what = "a number or a list of numbers" if allow_scalar else "a non-empty list of numbers"
        raise ValueError(f"{where} must be {what}, got {_show(d[key])}")
    for i, x in enumerate(v):
        if not _is_number(x) or not math.isfinite(x):
            raise ValueError(f"{where}[{i}] must be a finite number, got {_show(x)}")
        if lo is not None and (x <= lo if lo_open else x < lo):
            raise ValueError(f"{where}[{i}] must be {'>' if lo_open else '>='} {lo:g}, "
                             f"got {x!r}")
    out = [float(x) for x in v]
    return out[0] if scalar else out


def _matrix(d, key, path, *, required=True):
    try:
        v = _present(d, key, path, required)
    except _Absent:
        return None
    where = f"{path}.{key}"
    if not isinstance(v, list) or not v or not all(isinstance(r, list) for r in v):
        raise ValueError(f"{where} must be a matrix (a non-empty list of rows), got {_show(v)}")
    n = len(v[0])
    for i, row in enumerate(v):
        if len(row) != n or n == 0:
            raise ValueError(f"{where}[{i}] must have {n} entries like row 0, got {len(row)}")
        for j, x in enumerate(row):
            if not _is_number(x) or not math.isfinite(x):
                raise ValueError(f"{where}[{i}][{j}] must be a finite number, got {_show(x)}")
    return [[float(x) for x in row] for row in v]


def _names(d, key, path, *, required=True, known=None):
    try:
        v = _present(d, key, path, required)
    except _Absent:
        return None
    where = f"{path}.{key}"
    if not isinstance(v, list) or not v or not all(isinstance(s, str) and s for s in v):
        raise ValueError(f"{where} must be a non-empty list of names, got {_show(v)}")
    if len(set(v)) != len(v):
        raise ValueError(f"{where} must hold distinct names, got {v!r}")
    if known is not None:
        for i, s in enumerate(v):
            if s not in known:
                raise ValueError(f"{where}[{i}] must be a degree of freedom, one of "
                                 f"{', '.join(known)}; got {s!r}")
    return list(v)


def _dof(d, key, path, known, *, required=True):
    if key not in d:
        if required:
            raise ValueError(f"{path}.{key} is required (a degree of freedom, one of "
                             f"{', '.join(known)})")
        return None
    v = d[key]
    if not isinstance(v, str) or v not in known:
        raise ValueError(f"{path}.{key} must be a degree of freedom, one of "
                         f"{', '.join(known)}; got {_show(v)}")
    return v


def _where(d, path, known):
    """``dof = "name"`` or ``dofs = {name: weight}`` (exactly one): a name or a dict."""
    if ("dof" in d) == ("dofs" in d):
        raise ValueError(f"{path}: give exactly one of dof (a degree of freedom) or dofs "
                         f"({{name = weight}}); degrees of freedom: {', '.join(known)}")
    if "dof" in d:
        return _dof(d, "dof", path, known)
    w = _table(d["dofs"], f"{path}.dofs")
    if not w:
        raise ValueError(f"{path}.dofs must name at least one degree of freedom")
    out = {}
    for k in w:
        if k not in known:
            raise ValueError(f"{path}.dofs.{k}: not a degree of freedom; known: "
                             f"{', '.join(known)}")
        out[k] = _number(w, k, f"{path}.dofs")
    if not any(out.values()):
        raise ValueError(f"{path}.dofs: at least one weight must be nonzero")
    return out


# --------------------------------------------------------------------------- structure

_DAMPING = ("rayleigh", "modal_damping")


def _damping_kwargs(d, path, *, allow_matrix):
    models = [k for k in (("damping",) if allow_matrix else ()) + _DAMPING if k in d]
    if len(models) > 1:
        raise ValueError(f"{path}: give at most one of {', '.join(models)}")
    kw = {}
    if "rayleigh" in d:
        r = _vector(d, "rayleigh", path, lo=0.0)
        if len(r) != 2:
            raise ValueError(f"{path}.rayleigh must be [alpha, beta] (two numbers >= 0), got "
                             f"{_show(d['rayleigh'])}")
        kw["rayleigh"] = tuple(r)
    if "modal_damping" in d:
        kw["modal_damping"] = _vector(d, "modal_damping", path, lo=0.0, allow_scalar=True)
    if "damping" in d:
        kw["damping"] = _matrix(d, "damping", path)
    return kw


def _structure(d, path):
    import absorber_jax as aj

    d = _table(d, path)
    kind = _string(d, "type", path, choices=STRUCTURE_TYPES)
    common = ("type", "modal")
    if kind == "shear_building":
        _keys(d, path, ("masses", "storey_stiffnesses"), common + _DAMPING)
        masses = _vector(d, "masses", path, lo=0.0, lo_open=True)
        storeys = _vector(d, "storey_stiffnesses", path, lo=0.0, lo_open=True)
        if len(storeys) != len(masses):
            raise ValueError(f"{path}.storey_stiffnesses must hold one value per floor "
                             f"({len(masses)} masses), got {len(storeys)}")
        kw = _damping_kwargs(d, path, allow_matrix=False)
        build = lambda: aj.shear_building(masses, storeys, **kw)  # noqa: E731
    elif kind == "cantilever_beam":
        _keys(d, path, ("n_elements", "length", "EI", "rho_A"), common + _DAMPING)
        n = _integer(d, "n_elements", path)
        geo = {k: _number(d, k, path, lo=0.0, lo_open=True) for k in ("length", "EI", "rho_A")}
        kw = _damping_kwargs(d, path, allow_matrix=False)
        build = lambda: aj.cantilever_beam(n, **geo, **kw)  # noqa: E731
    elif kind == "matrices":
        _keys(d, path, ("mass", "stiffness"), common + ("damping", "dof_names") + _DAMPING)
        M = _matrix(d, "mass", path)
        K = _matrix(d, "stiffness", path)
        for key, A in (("mass", M), ("stiffness", K)):
            if len(A) != len(A[0]):
                raise ValueError(f"{path}.{key} must be square, got {len(A)}×{len(A[0])}")
        if len(K) != len(M):
            raise ValueError(f"{path}.stiffness must be {len(M)}×{len(M)} like the mass, got "
                             f"{len(K)}×{len(K[0])}")
        names = _names(d, "dof_names", path, required=False)
        if names is not None and len(names) != len(M):
            raise ValueError(f"{path}.dof_names must hold {len(M)} names, got {len(names)}")
        kw = _damping_kwargs(d, path, allow_matrix=True)
        if "damping" in kw and (len(kw["damping"]) != len(M)
                                or len(kw["damping"][0]) != len(M)):
            raise ValueError(f"{path}.damping must be {len(M)}×{len(M)} like the mass")
        build = lambda: aj.structure_from_matrices(M, K, dof_names=names, **kw)  # noqa: E731
    else:
        _keys(d, path, ("frequencies", "damping_ratios", "mode_shapes"),
              ("type", "modal", "dof_names"))
        w = _vector(d, "frequencies", path, lo=0.0, lo_open=True)
        z = _vector(d, "damping_ratios", path, lo=0.0, allow_scalar=True)
        if isinstance(z, list) and len(z) != len(w):
            raise ValueError(f"{path}.damping_ratios must be one ratio or one per mode "
                             f"({len(w)}), got {len(z)}")
        shapes = _matrix(d, "mode_shapes", path)
        if len(shapes[0]) != len(w):
            raise ValueError(f"{path}.mode_shapes must have one column per mode ({len(w)}), "
                             f"got {len(shapes[0])}")
        names = _names(d, "dof_names", path, required=False)
        if names is not None and len(names) != len(shapes):
            raise ValueError(f"{path}.dof_names must hold one name per row of mode_shapes "
                             f"({len(shapes)}), got {len(names)}")
        build = lambda: aj.structure_from_modes(w, z, shapes, dof_names=names)  # noqa: E731
    try:
        st = build()
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    if "modal" in d:
        mp = f"{path}.modal"
        md = _table(d["modal"], mp)
        _keys(md, mp, (), ("n_modes", "dofs"))
        n_modes = _integer(md, "n_modes", mp, required=False)
        if n_modes is not None and n_modes > st.num_coords:
            raise ValueError(f"{mp}.n_modes must be at most {st.num_coords} (the structure's "
                             f"coordinates), got {n_modes}")
        dofs = _names(md, "dofs", mp, required=False, known=st.dof_names)
        try:
            st = st.modal(n_modes, dofs=dofs)
        except ValueError as e:
            raise ValueError(f"{mp}: {e}") from None
    return st


# --------------------------------------------------------------------------- elements


def _contact_law(d, path):
    import absorber_jax as aj

    d = _table(d, path)
    law = _string(d, "law", path, choices=CONTACT_LAWS)
    _keys(d, path, ("law", "stiffness", "damping"), ("eps", "adhesive"))
    kw = dict(stiffness=_number(d, "stiffness", path, lo=0.0, lo_open=True),
              damping=_number(d, "damping", path, lo=0.0),
              adhesive=_boolean(d, "adhesive", path, default=False))
    if "eps" in d:
        kw["eps"] = _number(d, "eps", path, lo=0.0, lo_open=True)
    cls = {"kelvin_voigt": aj.KelvinVoigt, "hertz": aj.Hertz,
           "hunt_crossley": aj.HuntCrossley}[law]
    return cls(**kw)


def _friction_law(d, path):
    import absorber_jax as aj

    d = _table(d, path)
    law = _string(d, "law", path, choices=FRICTION_LAWS)
    pos = dict(lo=0.0, lo_open=True)
    if law in ("coulomb", "stribeck") and "eps" not in d:
        raise ValueError(f"{path}.eps is required: on a structure {law} friction is smoothed "
                         f"as tanh(v/eps), eps > 0 [m/s] (e.g. 1e-4)")
    if law == "coulomb":
        _keys(d, path, ("law", "mu", "eps"))
        return aj.Coulomb(mu=_number(d, "mu", path, lo=0.0),
                          eps=_number(d, "eps", path, **pos))
    if law == "stribeck":
        _keys(d, path, ("law", "mu_c", "mu_s", "v_s", "eps"))
        mu_c = _number(d, "mu_c", path, lo=0.0)
        return aj.Stribeck(mu_c=mu_c, mu_s=_number(d, "mu_s", path, lo=mu_c),
                           v_s=_number(d, "v_s", path, **pos),
                           eps=_number(d, "eps", path, **pos))
    if law == "dahl":
        _keys(d, path, ("law", "mu_c", "sigma0"), ("eps",))
        kw = dict(mu_c=_number(d, "mu_c", path, lo=0.0), sigma0=_number(d, "sigma0", path, **pos))
        if "eps" in d:
            kw["eps"] = _number(d, "eps", path, **pos)
        return aj.Dahl(**kw)
    _keys(d, path, ("law", "mu_c", "mu_s", "v_s", "sigma0", "sigma1"), ("sigma2", "eps"))
    mu_c = _number(d, "mu_c", path, lo=0.0)
    kw = dict(mu_c=mu_c, mu_s=_number(d, "mu_s", path, lo=mu_c),
              v_s=_number(d, "v_s", path, **pos), sigma0=_number(d, "sigma0", path, **pos),
              sigma1=_number(d, "sigma1", path, lo=0.0))
    if "sigma2" in d:
        kw["sigma2"] = _number(d, "sigma2", path, lo=0.0)
    if "eps" in d:
        kw["eps"] = _number(d, "eps", path, **pos)
    return aj.LuGre(**kw)


# per element type: (required keys, optional keys) besides type, dof and name
_ELEMENT_KEYS = {
    "tmd": (("m", "k", "c"), ()),
    "impact": (("m", "gap", "contact"), ()),
    "friction": (("m", "k", "c", "normal_force", "friction"), ()),
    "contact": (("gap", "contact"), ("other", "sides", "direction")),
    "friction_contact": (("normal_force", "friction"), ("other",)),
}


def _element(d, path, known):
    import absorber_jax as aj

    d = _table(d, path)
    kind = _string(d, "type", path, choices=ELEMENT_TYPES)
    req, opt = _ELEMENT_KEYS[kind]
    _keys(d, path, ("type", "dof") + req, ("name",) + opt)
    dof = _dof(d, "dof", path, known)
    name = _string(d, "name", path, required=False)
    pos, nonneg = dict(lo=0.0, lo_open=True), dict(lo=0.0)
    kw = {"name": name}
    if "m" in req:
        kw["m"] = _number(d, "m", path, **pos)
    for key in ("k", "c", "gap", "normal_force"):
        if key in req:
            kw[key] = _number(d, key, path, **nonneg)
    if "contact" in req:
        kw["contact"] = _contact_law(d["contact"], f"{path}.contact")
    if "friction" in req:
        kw["friction"] = _friction_law(d["friction"], f"{path}.friction")
    if "other" in d:
        kw["other"] = _dof(d, "other", path, known)
        if kw["other"] == dof:
            raise ValueError(f"{path}.other must differ from {path}.dof ({dof!r})")
    if "sides" in d:
        kw["sides"] = _string(d, "sides", path, choices=("one", "two"))
    if "direction" in d:
        v = d["direction"]
        if not _is_number(v) or v not in (1, -1):
            raise ValueError(f"{path}.direction must be 1 or -1, got {_show(v)}")
        kw["direction"] = int(v)
    cls = {"tmd": aj.TunedMassDamper, "impact": aj.ImpactDamper, "friction": aj.FrictionDamper,
           "contact": aj.Contact, "friction_contact": aj.FrictionContact}[kind]
    try:
        return cls(dof, **kw)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


# --------------------------------------------------------------------------- sweep


def _sweep(d, path):
    d = _table(d, path)
    _keys(d, path, ("omegas",), ("direction", "method"))
    om = d["omegas"]
    op = f"{path}.omegas"
    if isinstance(om, dict):
        _keys(om, op, ("start", "stop", "num"))
        start = _number(om, "start", op, lo=0.0, lo_open=True)
        stop = _number(om, "stop", op, lo=start, lo_open=True)
        omegas = np.linspace(start, stop, _integer(om, "num", op, lo=2))
    elif isinstance(om, list):
        omegas = np.asarray(_vector(d, "omegas", path, lo=0.0, lo_open=True))
        if np.any(np.diff(omegas) <= 0):
            raise ValueError(f"{op} must be strictly increasing")
    else:
        raise ValueError(f"{op} must be {{start, stop, num}} or a list of frequencies [rad/s], "
                         f"got {_show(om)}")
    return dict(omegas=omegas,
                direction=_string(d, "direction", path, choices=DIRECTIONS, default="parallel",
                                  required=False),
                method=_string(d, "method", path, choices=METHODS, default="shooting",
                               required=False))


def _simulate(d, path):
    d = _table(d, path)
    _keys(d, path, (), ("omega", "periods"))
    return dict(simulate_omega=_number(d, "omega", path, lo=0.0, lo_open=True, required=False),
                simulate_periods=_integer(d, "periods", path, default=DEFAULT_PERIODS,
                                          required=False))


def _parameter(system, name, where):
    import absorber_jax as aj

    try:
        aj.get_param(system, name)
    except ValueError:
        raise ValueError(f"{where}: unknown parameter {name!r}; known: "
                         f"{aj.parameter_names(system)}") from None


def _distribution(spec, where):
    import absorber_jax as aj

    spec = _table(spec, where)
    _keys(spec, where, (), ("uniform", "normal", "relative"))
    kinds = [k for k in ("uniform", "normal") if k in spec]
    if len(kinds) != 1:
        raise ValueError(f"{where} needs exactly one of uniform = [low, high] | normal = "
                         f"[mean, std], got {_show(spec)}")
    v = _vector(spec, kinds[0], where)
    if len(v) != 2:
        raise ValueError(f"{where}.{kinds[0]} must be two numbers, got "
                         f"{_show(spec[kinds[0]])}")
    a, b = v
    relative = _boolean(spec, "relative", where, default=False)
    cls = aj.Uniform if kinds[0] == "uniform" else aj.Normal
    return cls(a, b, relative=relative)


def _study(d, path, system, amplitude, omegas):
    import absorber_jax as aj

    d = _table(d, path)
    _keys(d, path, ("question",), DESIGN_KINDS + ("band", "store", "chunk"))
    kinds = [k for k in DESIGN_KINDS if k in d]
    if len(kinds) != 1:
        raise ValueError(f"{path} needs exactly one of {' | '.join(DESIGN_KINDS)}, got "
                         f"{kinds or 'none'}")
    kind = kinds[0]
    kp = f"{path}.{kind}"
    t = _table(d[kind], kp)
    if kind in ("grid", "designs"):
        if not t:
            raise ValueError(f"{kp} needs at least one parameter")
        cols = {}
        for name in t:
            _parameter(system, name, f"{kp}.{name}")
            cols[name] = _vector(t, name, kp, allow_scalar=True)
        designs = (aj.Grid if kind == "grid" else aj.Designs)(cols)
    else:
        samples = _integer(t, "samples", kp, lo=1)
        seed = _integer(t, "seed", kp, lo=0, default=0, required=False)
        dists = {}
        for name, spec in t.items():
            if name in ("samples", "seed"):
                continue
            _parameter(system, name, f"{kp}.{name}")
            dists[name] = _distribution(spec, f"{kp}.{name}")
        if not dists:
            raise ValueError(f"{kp} needs at least one parameter")
        designs = (aj.MonteCarlo if kind == "monte_carlo" else aj.LatinHypercube)(
            samples, dists, seed=seed)
    question = _string(d, "question", path, choices=STUDY_QUESTIONS)
    if question == "frequency_response":
        if omegas is None:
            raise ValueError(f"{path}.question = 'frequency_response' needs the frequencies "
                             f"of [sweep] omegas")
        q = aj.questions.FrequencyResponse(omegas, amplitude=amplitude)
    else:
        band = _vector(d, "band", path, lo=0.0, lo_open=True)
        if len(band) != 2 or not band[0] < band[1]:
            raise ValueError(f"{path}.band must be [lo, hi] with 0 < lo < hi [rad/s], got "
                             f"{_show(d['band'])}")
        cls = (aj.questions.ExactPeak if question == "exact_peak"
               else aj.questions.RobustPeak)
        q = cls(tuple(band), amplitude=amplitude)
    return StudySpec(designs=designs, question=q,
                     store=_string(d, "store", path, default=None, required=False),
                     chunk=_integer(d, "chunk", path, lo=1, default=None, required=False))


# --------------------------------------------------------------------------- the scene


def scene_from_dict(data, *, source=""):
    """The ``(StructuralSystem, SceneSettings)`` of a scene tree (the parsed file; see the
    module docstring)."""
    import absorber_jax as aj

    p = SCENE
    d = _table(data, p)
    _keys(d, p, ("structure", "load"),
          ("title", "description", "elements", "observe", "sweep", "simulate", "study"))
    title = _string(d, "title", p, default="", required=False)
    description = d.get("description", "")
    if not isinstance(description, str):
        raise ValueError(f"{p}.description must be a string, got {_show(description)}")
    st = _structure(d["structure"], f"{p}.structure")
    known = list(st.dof_names)
    els = d.get("elements", [])
    if not isinstance(els, list):
        raise ValueError(f"{p}.elements must be a list of tables ([[elements]]), got "
                         f"{_show(els)}")
    elements = [_element(e, f"{p}.elements[{i}]", known) for i, e in enumerate(els)]
    seen = set(known)
    for i, e in enumerate(elements):
        if e.name is not None and e.name in seen:
            raise ValueError(f"{p}.elements[{i}].name must differ from the degrees of freedom "
                             f"and the other elements' names, got {e.name!r}")
        seen.add(e.name)
    lp = f"{p}.load"
    ld = _table(d["load"], lp)
    _keys(ld, lp, ("amplitude",), ("dof", "dofs"))
    load = _where(ld, lp, known)
    amplitude = _number(ld, "amplitude", lp, lo=0.0)
    observe = None
    if "observe" in d:
        op = f"{p}.observe"
        od = _table(d["observe"], op)
        _keys(od, op, (), ("dof", "dofs"))
        observe = _where(od, op, known)
    elif isinstance(load, dict) and sum(1 for v in load.values() if v) != 1:
        raise ValueError(f"{p}.observe is required when the load acts on several degrees of "
                         f"freedom (give [observe] dof = ... or dofs = {{...}})")
    elif isinstance(load, dict):
        observe = next(k for k, v in load.items() if v)
    try:
        system = aj.StructuralSystem(st, elements, load=load, observe=observe)
    except ValueError as e:
        raise ValueError(f"{p}.elements: {e}") from None
    extra = {}
    if "sweep" in d:
        extra.update(_sweep(d["sweep"], f"{p}.sweep"))
    if "simulate" in d:
        extra.update(_simulate(d["simulate"], f"{p}.simulate"))
    if "study" in d:
        extra["study"] = _study(d["study"], f"{p}.study", system, amplitude,
                                extra.get("omegas"))
    settings = SceneSettings(amplitude=amplitude, title=title, description=description,
                             source=source, **extra)
    return system, settings


def load_scene(path):
    """Read a scene file (``.toml`` or ``.json``, keys in the module docstring and on the Scene
    files and the CLI page of the documentation): returns
    ``(system, settings)``, a ``StructuralSystem`` and its ``SceneSettings``.
    Raises ``ValueError`` naming the field for anything bad, missing or unknown."""
    return scene_from_dict(_read(path), source=os.fspath(path))
