"""Pseudo-arclength continuation of periodic orbits, with bifurcation detection and location
and branch switching at period doublings.

Unknowns ``z = (x, p)``: the orbit's internal state on its Poincaré section (``t = 0 mod nT``
at first, see Section below) divided by a state scale (``system.state_scale``, rescaled to the
orbit as it grows) and the continuation parameter divided by ``|its start value|`` (by
the bounds' larger magnitude in ``band_continuation``).  The residual is the shooting
residual of the steady-state layer, ``Φ_{nT}(x; p) - x``
(``_integration.flow.period_map``, the same flow, tolerances and derivatives as
``Shooting``); its Jacobian ``[M - I, ∂Φ/∂p]`` comes from one forward-mode pass over
``n + 1`` directions.

- **Predictor**: ``z + h t`` along the unit tangent ``t`` (null vector of the Jacobian,
  oriented to continue the previous one).
- **Corrector**: Newton on ``[Φ - x; t·(z - z_pred)] = 0`` (minimum-norm least-squares
  steps: a floating absorber's orbit family leaves the bordered matrix singular), until the
  scaled residual is below ``tol``, then one more step with the same Jacobian; stopped
  early where the residual has not halved over the last two steps.  The Jacobian of the last
  corrector iterate gives the next tangent and the Floquet multipliers (eigenvalues of
  ``M``) for free; the point's statistics and stability label are the point solve's
  (``_periodic.orbit.finish_orbit``).
- **Section**: the orbit's state is taken on a Poincaré section where the absorbers fly
  free, moved along the branch when a contact comes near it (``_Driver.resection``);
  the states reported are at ``t = 0``.
- **Step control**: the step grows after quick corrections, shrinks after slow ones, and is
  halved when the corrector fails or the tangent turns by more than ``max_angle``.
- **Bifurcations** between two accepted points, by sign changes of test functions: fold
  (the tangent's parameter component), period doubling (``Π(μ_i + 1)``: a real multiplier
  through -1), Neimark–Sacker (a complex pair crossing the unit circle).  Each is located by
  the Illinois variant of regula falsi (M. Dowell, P. Jarratt, *BIT* 11 (1971) 168) on the
  arclength, every evaluation a corrector solve on the hyperplane through the predicted point.
- **Branch switching** at a period doubling: the period-``2n`` branch starts from the
  bifurcating orbit pushed along the eigenvector of the multiplier -1, on the hyperplane
  normal to it, and is followed until it leaves the bounds or rejoins the period-``n``
  branch (at the other end of a flip window).

``band_continuation`` follows half-branches from several start values together, the
corrector solves of each round batched in one vmapped call (a generator per half-branch
yields its corrector requests, ``_follow``).

References: E. L. Allgower & K. Georg, *Introduction to Numerical Continuation Methods*
(SIAM, 2003), ch. 2 and 6; Yu. A. Kuznetsov, *Elements of Applied Bifurcation Theory*
(Springer, 2004), ch. 10 (test functions); R. Seydel, *Practical Bifurcation and Stability
Analysis* (Springer, 2010), ch. 7 (periodic orbits by shooting).
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core import tables
from .._core.checks import check_scalar, check_state, require_x64
from .._core.devices import device_parts, lanes_on_devices, one_blas_thread
from .._core.status import Status, nan_where_failed
from .._core.units import Signals, signals_of
from .._integration.flow import (
    Config,
    accurate_tangents,
    integrate_flow,
    make_config,
    period_map,
    state_scale,
)
from .._integration.settings import FIELDS as INTEGRATOR_FIELDS
from .._integration.settings import integrator_from
from .._periodic.orbit import (
    SAMPLES_PER_PERIOD,
    SteadyResults,
    SteadyState,
    finish_orbit,
    read_through,
)
from .._periodic.shooting import Shooting
from .._periodic.steady import check_system_and_forcing, steady_state
from .._systems.base import AbstractSystem
from .._systems.forcing import AbstractPeriodicForcing
from .._systems.params import replace_params, resolve

FORCING_PARAMETERS = ("omega", "amplitude")
KINDS = ("fold", "period_doubling", "neimark_sacker")
# a bifurcation is located when its bracket has shrunk to locate_tol and the test function
# there is this small against its values at the bracket's first ends (else it jumps there)
JUMP_TOL = 1e-3
# band_continuation's first guesses at a start value: the linear response scaled by these
# (near a resonance the linear response can be far larger than the impacting orbit: on the
# Kelvin–Voigt scene of scripts/benchmark_hard_contacts.py Newton from it fails at 29.4
# and 35.9 rad/s)
START_SCALES = (1.0, 0.3, 0.1)
# band_continuation's starts where no scaled linear response converges: first guesses from
# the CLOSE_RETURNS closest returns of a trajectory marched CLOSE_RETURN_PERIODS periods (the
# first CLOSE_RETURN_SKIP left out as transient)
CLOSE_RETURN_PERIODS, CLOSE_RETURN_SKIP, CLOSE_RETURNS = 240, 40, 3
# band_continuation's fill passes start new branches in the parts of the band no branch
# reached that are wider than this fraction of it
GAP = 1e-4
# a first orbit's Newton (from a far guess) is given up once its residual has grown this
# many times over the least so far: on the hard-contact scenes of
# scripts/benchmark_hard_contacts.py, Newton from the guesses that fail diverges from its
# first steps (the Hertz band's fill passes: residuals from ~1 to 1e2-1e6 in 12 steps, each
# step dearer as the iterate's motion grows, 47 s of its 102 s), while the guesses that
# succeed decrease the residual at every step
PATIENT_GROWTH = 10.0
# a branch's Poincaré section moves (Driver.resection) where the clearance to the nearest
# contact wall there has fallen below RESECTION of the best on the orbit, and not where
# the tangent's parameter component (which orients the tangent in the new section) is below
# RESECTION_TANGENT
RESECTION, RESECTION_TANGENT = 0.5, 1e-3
# ... and keeps the point re-solved there only where its state at t = 0 is the point's to
# this fraction of the orbit's size (at rtol 1e-7 the hard-contact orbits' states at t = 0,
# mapped from two sections, differ by up to ~1e-2 where the absorber is in contact)
RESECTION_SAME = 5e-2
# a sharp turn of the tangent is accepted as a corner once the step is reduced this much
CORNER_REDUCTION = 16.0


class PseudoArclength(eqx.Module):
    """Pseudo-arclength continuation and its options (lengths in the scaled unknowns: the
    orbit state over its scale at the start, the parameter over its start value).

    - ``step``: first arclength step; ``min_step``, ``max_step``: its bounds (the branch
      stops, flagged, when a step below ``min_step`` still fails).
    - ``max_points``: points on the branch at most.
    - ``tol``: corrector tolerance on the scaled shooting residual ``|Φ - x|∞``.
    - ``newton_steps``: corrector iterations per step.
    - ``max_angle``: largest turn of the tangent between two points [rad].
    - ``locate_tol``: bifurcations are located to this arclength (scaled).
    """

    step: float = eqx.field(static=True, default=0.01)
    min_step: float = eqx.field(static=True, default=1e-6)
    max_step: float = eqx.field(static=True, default=0.05)
    max_points: int = eqx.field(static=True, default=400)
    tol: float = eqx.field(static=True, default=1e-6)
    newton_steps: int = eqx.field(static=True, default=12)
    max_angle: float = eqx.field(static=True, default=0.35)
    locate_tol: float = eqx.field(static=True, default=1e-9)

    def __check_init__(self):
        for name in ("step", "min_step", "max_step", "tol", "locate_tol"):
            check_scalar("PseudoArclength", name, getattr(self, name), lo=0.0, lo_open=True)
        if not self.min_step <= self.step <= self.max_step:
            raise ValueError("PseudoArclength: need min_step <= step <= max_step, got "
                             f"{self.min_step:g}, {self.step:g}, {self.max_step:g}")
        check_scalar("PseudoArclength", "max_angle", self.max_angle, lo=0.0, hi=math.pi / 2,
                     lo_open=True)
        for name in ("max_points", "newton_steps"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 2:
                raise ValueError(f"PseudoArclength.{name} must be an integer >= 2, got {v!r}")


class Bifurcation(eqx.Module):
    """A bifurcation found on a [`Branch`][absorber_jax.Branch].

    ``kind``: ``"fold"``, ``"period_doubling"`` or ``"neimark_sacker"``; ``value``: the
    located parameter value; ``amplitude``: the observable's amplitude there; ``state``:
    public orbit state; ``multipliers``: Floquet multipliers there; ``index``: it lies
    between branch points ``index`` and ``index + 1``; ``located``: the location converged
    to ``locate_tol`` onto a zero of the test function (False where the bracket closed on a
    jump of it: a grazing corner, where the multipliers leap across the circle);
    ``evaluations``: corrector solves spent locating it."""

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
    ``termination``: why the branch ended (``"bounds"``, ``"max_points"``, ``"rejoined"``,
    ``"closed"``, ``"step_collapse"`` or ``"start_failed"``); ``steps``: corrector iterations per
    point are ``iterations``.  The measured fields are NaN at failed points; ``signals``: the
    names and SI units of what they measure, as the CSV headers, plot labels and
    ``to_xarray`` attributes give them."""

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

    def summary(self):
        """The branch as a JSON-ready dict: parameter, period, points, how it ended, the range
        covered, stable and failed points, corrector iterations and the bifurcations."""
        st = np.asarray(self.stable)
        return dict(parameter=self.parameter, period_multiple=self.period_multiple,
                    points=len(self), termination=self.termination,
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


# --------------------------------------------------------------------------- the problem


class _Problem(eqx.Module):
    """The shooting residual in the continuation's scaled unknowns ``z = (x, p)``, ``x``
    the orbit's state on the Poincaré section ``section`` samples (of
    ``SAMPLES_PER_PERIOD`` a forcing period) after ``t = 0``."""

    system: AbstractSystem
    forcing: AbstractPeriodicForcing
    s0: jax.Array
    pscale: jax.Array
    cfg: Config
    parameter: str = eqx.field(static=True)
    n: int = eqx.field(static=True)
    section: jax.Array = eqx.field(default_factory=lambda: jnp.asarray(0))

    def at(self, p):
        """(system, forcing) at the scaled parameter ``p``."""
        return _set_value(self.system, self.forcing, self.parameter, p * self.pscale)

    def in_section(self, p):
        """(system, forcing seen from the section) at the scaled parameter ``p``."""
        sysp, forcp = self.at(p)
        phase = 2 * jnp.pi * self.section / SAMPLES_PER_PERIOD
        return sysp, forcp.at_phase(phase)

    def _in_flow(self, z):
        """(system, forcing from the section) at ``z``'s parameter, the flow's state scale
        there and ``z``'s state in it (flow states ``y`` are ``y * sc / s0`` in the
        unknowns)."""
        sysp, forcp = self.in_section(z[-1])
        sc = state_scale(sysp, forcp)
        return sysp, forcp, sc, z[:-1] * self.s0 / sc

    def residual(self, z):
        sysp, forcp, sc, x = self._in_flow(z)
        xn, st = period_map(sysp, forcp, x, self.n, self.cfg)
        return xn * sc / self.s0 - z[:-1], st

    def samples(self, z, periods):
        """The unknowns' states after each ``n`` forcing periods for ``periods`` times from
        ``z`` (at its parameter), and the integrator's status."""
        sysp, forcp, sc, x = self._in_flow(z)
        ts = jnp.arange(1, periods + 1) * (self.n * forcp.period)
        ys, st = integrate_flow((sysp, forcp), x, ts[-1], ts,
                                cfg=self.cfg.over_periods(self.n * periods))
        return ys * sc / self.s0, st


def _set_value(system, forcing, name, value):
    if name == "omega":
        return system, forcing.with_omega(value)
    if name == "amplitude":
        return system, forcing.with_amplitude(value)
    return replace_params(system, {name: value}, check=False), forcing


def _get_value(system, forcing, name):
    if name in FORCING_PARAMETERS:
        return float(getattr(forcing, name))
    from .._systems.params import get_param

    return float(get_param(system, name))


def _evaluate(prob, z):
    def f(z):
        r, st = prob.residual(z)
        return r, (r, st)

    J, (r, st) = jax.jacfwd(f, has_aux=True)(z)
    bad = (st != Status.SUCCESS) | ~jnp.all(jnp.isfinite(r)) | ~jnp.all(jnp.isfinite(J))
    return jnp.where(jnp.isfinite(J), J, 0.0), jnp.where(jnp.isfinite(r), r, 0.0), st, bad


def _tangent(J, t_prev):
    """Unit null vector of ``J`` (``n × (n+1)``) oriented along ``t_prev``."""
    A = jnp.concatenate([J, t_prev[None]], axis=0)
    e = jnp.zeros(A.shape[0]).at[-1].set(1.0)
    t = jnp.linalg.lstsq(A, e)[0]
    t = t / jnp.linalg.norm(t)
    return t * jnp.where(t @ t_prev < 0, -1.0, 1.0)


@eqx.filter_jit
def _corrector(prob, z_pred, t_prev, tol, newton_steps, patient=False):
    """Newton on ``[Φ(z) - x; t_prev·(z - z_pred)] = 0`` from ``z_pred``; returns the point,
    the new tangent, the point's ``SteadyState`` (its iterations included) and its
    ``Section``.

    Every Jacobian is integrated with steps controlled on the tangents too
    (``_integration.flow.accurate_tangents``): forward mode through steps chosen for the
    state alone differentiates the discrete flow, whose Jacobian across a stiff contact is
    off by up to ~1e-3 in the multipliers; the tangent-controlled one costs about the same
    per evaluation (Kelvin–Voigt 2e4 scene at 44 rad/s: 21 vs 22 ms), so the last Newton
    iterate's Jacobian gives the tangent and the multipliers with no further solve, and one
    integrator is compiled instead of two."""
    prob = dataclasses.replace(prob, cfg=accurate_tangents(prob.cfg))

    def newton_step(z, J, r):
        A = jnp.concatenate([J, t_prev[None]], axis=0)
        rhs = -jnp.concatenate([r, (t_prev @ (z - z_pred))[None]])
        return jnp.linalg.lstsq(A, rhs)[0]

    def cond(c):
        return ~c[-1]

    def body(c):
        # ``k`` Newton steps taken before this evaluation; the first pass evaluates the
        # predictor itself (its step is zero: ``J`` and ``r`` start at zero), so the
        # Jacobian's integration is traced and compiled once, not twice
        z, J, r, st, bad, k, res_prev, res_prev2, res_min, done = c
        z = z + newton_step(z, J, r)
        J, r, st, bad = _evaluate(prob, z)
        res = jnp.max(jnp.abs(r))
        # a residual that has not halved over the last two steps is outside Newton's basin:
        # stop there (the step is halved and tried again) rather than spend the budget, which
        # a batch of branches (band_continuation) would wait for.  Over two steps, not one:
        # on strongly unstable orbits the residual often grows at the second step and then
        # falls quadratically (the Kelvin-Voigt scene of scripts/benchmark_hard_contacts.py
        # at 28.47 rad/s, |mu| = 50: 4e-3, 1.8e-4, 3.2e-4, 2.9e-6, 1.3e-8), and a one-step
        # test there halved the arclength step every other point.  A first orbit
        # (``patient``: its guess may be far) is given up only where the residual has grown
        # PATIENT_GROWTH times over the least so far
        stalled = jnp.where(patient, res > PATIENT_GROWTH * res_min,
                            (k >= 2) & (res > 0.5 * res_prev2))
        # at least one Newton step (a predictor within tolerance would otherwise be kept
        # with an error of order tol)
        done = bad | ((k >= 1) & (res <= tol)) | (k >= newton_steps) | stalled
        return z, J, r, st, bad, k + 1, res, res_prev, jnp.minimum(res, res_min), done

    n = z_pred.shape[0] - 1
    inf = jnp.asarray(jnp.inf)
    z, J, r, st, bad, k, _, _, _, _ = jax.lax.while_loop(
        cond, body, (z_pred, jnp.zeros((n, n + 1)), jnp.zeros(n), jnp.asarray(Status.SUCCESS),
                     jnp.asarray(False), jnp.asarray(0), inf, inf, inf, jnp.asarray(False)))
    k = k - 1
    res = jnp.max(jnp.abs(r))
    ok = ~bad & (res <= tol)
    # converged: one more Newton step with the Jacobian at hand, not evaluated again (the
    # residual is nonlinear in the parameter even on a linear structure, and a residual just
    # below tol can mean a state error of tol / (1 - |μ|) on a lightly damped orbit; the
    # step leaves ~tol²).  The tangent and the multipliers are read off that Jacobian, a
    # step of order tol away: a Jacobian of their own would cost one more evaluation per
    # point (3 instead of 2 on most points of a branch).
    z = jnp.where(ok, z + newton_step(z, J, r), z)
    status = jnp.where(st != Status.SUCCESS, st,
                       jnp.where(bad, Status.NONFINITE,
                                 jnp.where(ok, Status.SUCCESS, Status.NO_CONVERGENCE)))
    t = _tangent(J, t_prev)
    mult = jnp.linalg.eigvals(J[:, :n] + jnp.eye(n))
    sysp, forcp = prob.in_section(z[-1])
    sc = state_scale(sysp, forcp)
    ss, sec = finish_orbit(sysp, forcp, z[:-1] * prob.s0 / sc, prob.n, prob.cfg, status, res, k,
                      n_cap=prob.n, multipliers=mult, section=prob.section)
    return z, t, ss, sec


@eqx.filter_jit
def _scale_at(prob, p):
    return state_scale(*prob.at(p))


@eqx.filter_jit
def _jacobian(prob, z):
    return _evaluate(prob, z)[0]


@eqx.filter_jit
def _defect(prob, z):
    """``|Φ(x) - x|∞`` of the period-``prob.n`` map at ``z``."""
    r, st = prob.residual(z)
    return jnp.where(st == Status.SUCCESS, jnp.max(jnp.abs(r)), jnp.inf)


# ----------------------------------------------------------------- test functions


def _pd_test(mult):
    """Product of ``(μ_i + 1)`` (real; changes sign when a real multiplier crosses -1),
    and the located quantity: the real multiplier nearest -1, plus 1."""
    prod = float(np.prod(mult + 1.0).real)
    real = mult[np.abs(mult.imag) <= 1e-7 * np.maximum(1.0, np.abs(mult))]
    near = real[np.argmin(np.abs(real + 1.0))].real + 1.0 if real.size else np.nan
    return np.sign(prod), near


def _complex_upper(mult):
    """Multipliers of the complex pairs (upper half plane), away from +1 and -1."""
    return mult[(mult.imag > 1e-6 * np.maximum(1.0, np.abs(mult)))
                & (np.abs(mult - 1.0) > 1e-3) & (np.abs(mult + 1.0) > 1e-3)]


def _ns_test(mult):
    c = _complex_upper(mult)
    out = int(np.sum(np.abs(c) > 1.0))
    near = (np.abs(c[np.argmin(np.abs(np.abs(c) - 1.0))]) - 1.0) if c.size else np.nan
    return c.size, out, near


def _events(a, b):
    """The bifurcation kinds whose test functions change sign between points ``a`` and
    ``b`` (dicts with the tangent ``t`` and multipliers ``mult``)."""
    kinds = []
    if np.sign(a["t"][-1]) * np.sign(b["t"][-1]) < 0:
        kinds.append("fold")
    if _pd_test(a["mult"])[0] * _pd_test(b["mult"])[0] < 0:
        kinds.append("period_doubling")
    ca, oa, _ = _ns_test(a["mult"])
    cb, ob, _ = _ns_test(b["mult"])
    if ca == cb and ca > 0 and oa != ob:
        kinds.append("neimark_sacker")
    return kinds


def _g(kind, point):
    if kind == "fold":
        return float(point["t"][-1])
    if kind == "period_doubling":
        return float(_pd_test(point["mult"])[1])
    return float(_ns_test(point["mult"])[2])


# ------------------------------------------------------------------------ the driver


class _Driver:
    """Holds the compiled corrector's inputs and the branch being built."""

    def __init__(self, prob, method, bounds):
        self.prob, self.method = prob, method
        self.lo, self.hi = (b / float(prob.pscale) for b in bounds)

    def solve(self, z_pred, t_prev, patient=False):
        """The corrector from ``z_pred`` on the hyperplane normal to ``t_prev``, now
        (``patient``: the whole Newton budget, for a first orbit from a far guess)."""
        return self.point(*_corrector(self.prob, jnp.asarray(z_pred), jnp.asarray(t_prev),
                                      self.method.tol, self.method.newton_steps,
                                      jnp.asarray(patient)))

    def point(self, z, t, ss, sec):
        """A corrector's output as a branch point (numpy): ``xi`` its internal state on the
        driver's section, ``x0`` at ``t = 0``, ``sec`` its ``Section``."""
        ss, sec = jax.tree_util.tree_map(np.asarray, (ss, sec))
        z = np.asarray(z)
        return dict(z=z, t=np.asarray(t), ss=ss, sec=sec, xi=z[:-1] * np.asarray(self.prob.s0),
                    x0=sec.at_zero, mult=np.asarray(ss.multipliers),
                    ok=int(ss.status) == Status.SUCCESS)

    def resection(self, point):
        """Move the branch's Poincaré section to where the orbit at ``point`` flies farthest
        from the contact walls, once the clearance at the current one has fallen below
        ``RESECTION`` of that (a generator of one corrector request, see ``_follow``):
        the point's state there, corrected at its parameter value, gives the unknowns and the
        tangent in the new section (oriented by the parameter's direction, so not near a
        fold: ``|t_p| >= RESECTION_TANGENT``).  Returns the point in the new unknowns, or
        ``point`` where nothing is to be moved or the correction failed."""
        sec, tp = point["sec"], float(point["t"][-1])
        if not (sec.least_clearance <= 0 < sec.best_clearance     # an impacting orbit
                and sec.clearance < RESECTION * sec.best_clearance
                and abs(tp) >= RESECTION_TANGENT):
            return point
        old = self.prob
        self.prob = dataclasses.replace(old, section=jnp.asarray(int(sec.best)))
        z = np.append(sec.best_state / np.asarray(self.prob.s0), point["z"][-1])
        e = np.zeros_like(z)
        e[-1] = np.sign(tp)
        c = yield (self, z, e, False)
        size = np.max(np.abs(point["x0"]))
        if c["ok"] and np.max(np.abs(c["x0"] - point["x0"])) < RESECTION_SAME * size:
            # the same orbit: its statistics and count as the point's
            c["ss"] = dataclasses.replace(c["ss"], iterations=point["ss"].iterations,
                                          residual=point["ss"].residual)
            return self.rescale(c)
        self.prob = old
        return point

    def rescale(self, point):
        """Rescale the state unknowns to the orbit at ``point`` (its state over the state
        scale there, at least 1): steps and tolerances then measure changes relative to
        the orbit's size, as it grows through a resonance.  The compiled corrector is
        reused (the scale is an array input).  Returns ``point`` in the new unknowns."""
        s_old = np.asarray(self.prob.s0)
        sc = np.asarray(_scale_at(self.prob, jnp.asarray(point["z"][-1])))
        s_new = sc * max(1.0, float(np.max(np.abs(point["xi"] / sc))))
        self.prob = eqx.tree_at(lambda q: q.s0, self.prob, jnp.asarray(s_new))
        z = np.append(point["xi"] / s_new, point["z"][-1])
        t = np.append(point["t"][:-1] * s_old / s_new, point["t"][-1])
        return dict(point, z=z, t=t / np.linalg.norm(t))

    def locate(self, kind, a, h):
        """Illinois regula falsi on the arclength ``σ ∈ [0, h]`` from point ``a`` along its
        tangent for a zero of the test function of ``kind`` (a generator of corrector
        requests, see ``_follow``)."""
        lo, hi = 0.0, h
        glo, ghi = _g(kind, a), None
        b = yield (self, a["z"] + h * a["t"], a["t"], False)
        ghi = _g(kind, b)
        best, evals, side = b, 1, 0
        if not (np.isfinite(glo) and np.isfinite(ghi)) or glo * ghi > 0:
            return best, evals, False
        g_start = max(abs(glo), abs(ghi))
        converged = False
        while evals < 60:
            s = hi - ghi * (hi - lo) / (ghi - glo) if ghi != glo else 0.5 * (lo + hi)
            if not lo < s < hi:
                s = 0.5 * (lo + hi)
            p = yield (self, a["z"] + s * a["t"], a["t"], False)
            evals += 1
            if not p["ok"]:
                break
            gp = _g(kind, p)
            best = p
            if not np.isfinite(gp):
                break
            if gp * ghi < 0:
                lo, glo = hi, ghi
                hi, ghi = s, gp
                side = 0
            else:
                hi, ghi = s, gp
                if side == -1:
                    glo *= 0.5
                side = -1
            if gp == 0.0:
                converged = True
                break
            if abs(hi - lo) <= self.method.locate_tol:
                # a bracket shrunk onto a jump of the test function (a grazing corner,
                # where the multipliers leap across the circle) is not a located zero
                converged = min(abs(glo), abs(ghi)) <= JUMP_TOL * g_start
                break
        return best, evals, converged


def continuation(system: AbstractSystem, forcing: AbstractPeriodicForcing,
                 parameter: str = "omega", *, bounds, method: PseudoArclength | None = None,
                 n: int = 1, direction: str = "up", start=None, guess=None, integrator=None,
                 locate=True, progress=False, **legacy) -> Branch:
    """Follow a branch of period-``n`` orbits of ``system`` under ``forcing`` in
    ``parameter`` by pseudo-arclength continuation (see the module docstring), through
    folds, with the bifurcations on it detected and located.

    **Arguments**

    - ``forcing``: any periodic forcing (``Harmonic``, ``MultiHarmonic``,
      ``PeriodicForcing`` ...).
    - ``parameter``: ``"omega"`` (the forcing's fundamental [rad/s], through
      ``forcing.with_omega``), ``"amplitude"`` (F0 [N], through ``forcing.with_amplitude``)
      or any name of ``system.parameter_names()`` (``k1``, ``gap``, ``N``, ``tmd1.k`` ...).
    - ``bounds``: ``(lo, hi)``: the branch ends where the parameter leaves them (the last
      point lands on the bound); the start value must lie inside.
    - ``method``: a ``PseudoArclength`` with the step and corrector options.
    - ``n``: period multiple of the orbits followed.
    - ``direction``: ``"up"`` or ``"down"``: the parameter's direction at the start.
    - ``start``: None (the first orbit is solved at the forcing's and system's current
      parameter value by Newton shooting from ``guess``, default the linear response, and by
      ``steady_state`` with its retries where that fails), or a period-doubling
      ``Bifurcation`` of a branch of this system in this parameter: the period-``2n``
      branch born there is followed (branch switching); ``direction`` is then ignored.
    - ``integrator``: an ``Integrator`` (default: the periodic tolerances, rtol = atol =
      1e-9 on the scaled state; the solver is chosen at the lowest frequency of the bounds
      when continuing in ``omega``).
    - ``locate``: locate each bifurcation (a few corrector solves each); otherwise they are
      reported at the nearer branch point.
    - ``progress``: a tqdm bar over the branch points.

    **Returns** a ``Branch``.

    ```python
    import absorber_jax as aj
    system, forcing = aj.presets.impact("kelvin_voigt", omega=40.0)
    br = aj.continuation(system, forcing, "omega", bounds=(30.0, 70.0))
    br.values, br.amplitude, br.stable, [(b.kind, b.value) for b in br.bifurcations]
    ```
    """
    method, lo, hi = _check_common(system, forcing, parameter, bounds, method, n, "continuation")
    if direction not in ("up", "down"):
        raise ValueError(f"direction must be 'up' or 'down', got {direction!r}")
    if start is not None:
        if not isinstance(start, Bifurcation) or start.kind != "period_doubling":
            raise ValueError("start must be a period-doubling Bifurcation of a Branch, got "
                             f"{start!r}")
        system, forcing = _set_value(system, forcing, parameter, float(start.value))
        n = 2 * start.period_multiple
    value0 = _get_value(system, forcing, parameter)
    if not lo <= value0 <= hi:
        raise ValueError(f"the start value of {parameter!r} ({value0:g}) must lie inside "
                         f"bounds ({lo:g}, {hi:g})")
    check_state("guess", guess, system.num_states)

    integ = integrator_from(integrator, "periodic", "continuation",
                            {k: legacy.pop(k, None) for k in INTEGRATOR_FIELDS})
    if legacy:
        raise TypeError(f"continuation() got an unexpected keyword argument "
                        f"{next(iter(legacy))!r}")
    solver, rtol, atol, max_steps = integ.solver, integ.rtol, integ.atol, integ.max_steps
    cfg = _config(system, forcing, parameter, lo, solver, rtol, atol, max_steps)
    s0 = state_scale(system, forcing)
    pscale = abs(value0) if value0 != 0 else max(abs(lo), abs(hi))
    prob = _Problem(system=system, forcing=forcing, s0=s0, pscale=jnp.asarray(pscale),
                    cfg=cfg, parameter=parameter, n=n)
    drv = _Driver(prob, method, (lo, hi))
    p0 = value0 / pscale

    if start is None:
        shooting = Shooting(n=n, tol=method.tol)
        g = (shooting.initial_state(system, forcing) if guess is None
             else system.to_internal(jnp.asarray(guess, dtype=float)))
        # the first orbit: the branch's own corrector at the start value (Newton shooting
        # from the guess, compiled once for the whole branch); steady_state with its
        # retries (marching, then shooting again) only where that fails: its program costs
        # a compilation of its own (~20 s on the hard-contact scenes of
        # scripts/benchmark_hard_contacts.py)
        e = _axis(prob, direction)
        first = drv.solve(np.append(np.asarray(g) / np.asarray(s0), p0), e, True)
        if not first["ok"]:
            ss = steady_state(system, forcing, method=shooting, guess=guess, integrator=integ)
            x0 = np.asarray(system.to_internal(ss.state)) / np.asarray(s0)
            if int(ss.status) != Status.SUCCESS:
                first = dict(ss=jax.tree_util.tree_map(np.asarray, ss), ok=False)
            else:
                first = drv.solve(np.append(x0, p0), e, True)
        rejoin = None
    else:
        first, rejoin = _switch(drv, system, forcing, start, s0, p0, cfg, parameter, pscale)

    with _bar(method.max_points, parameter, progress) as bar:
        points, bifs, termination = _run(_follow(drv, first, rejoin, locate, bar))
    return _branch(points, bifs, termination, drv, value0, system)


def band_continuation(system: AbstractSystem, forcing: AbstractPeriodicForcing,
                      parameter: str = "omega", *,
                      bounds, starts=8, method: PseudoArclength | None = None, n: int = 1,
                      fill: int = 2, integrator=None, locate=True, progress=False,
                      **legacy) -> tuple:
    """Cover a parameter band with branches of period-``n`` orbits followed from several
    start values at once: every start up and down, each half-branch bounded by the
    neighbouring start values (so every cell between two starts is followed from both
    ends), all half-branches advanced together, their corrector solves batched in one
    vmapped call per step.

    Where the branch through the band snakes through many folds (the hard impact absorber
    of ``scripts/benchmark_hard_contacts.py``: 1200 points from 20 rad/s reach only 29.3
    rad/s) one branch cannot cover the band in reasonable time, and it misses the branches
    and isolas it is not connected to; the starts find those, and the batch runs many small
    orbits for little more than the price of one (that scene: 8 Jacobians in 0.059 s against
    0.031 s for one).

    **Arguments** as ``continuation`` (``bounds``, ``method``, ``n``, ``integrator``,
    ``locate``, ``progress``), and

    - ``starts``: the number of start values (the centres of that many equal cells of the
      bounds) or the start values themselves (inside the bounds).  The first orbit at each
      is Newton shooting from the linear response (scaled by ``START_SCALES`` in turn where
      that fails), then from the closest returns of a trajectory marched from it
      (``CLOSE_RETURNS`` of ``CLOSE_RETURN_PERIODS`` periods: a chaotic motion passes near
      the unstable periodic orbits embedded in it); a start where all fail gives two
      branches that ended ``"start_failed"`` (a fill pass's start, none, where its march
      failed), and its neighbours follow its cells.
    - ``fill``: passes, after the starts' branches end, that start new ones in the parts of
      the band none reached (wider than ``GAP`` of it): as many starts as the batch holds
      (one per start of the band), spread over those parts by width, each followed within
      its part, the first orbit from the closest returns of a marched trajectory at once:
      branches that fold back on both sides of a part leave it uncovered (the Kelvin–Voigt
      scene: the branches from 27.8 and 30.9 rad/s turn at folds at 28.35 and 29.25 rad/s;
      2 passes cover both hard-contact scenes' 20–45 rad/s whole).

    The bifurcations of all the half-branches are located together once the passes end.

    **Returns** a tuple of ``Branch`` es, two per start (down, then up), the fill
    passes' after the starts' (two per fill start that had a first guess).
    """
    method, lo, hi = _check_common(system, forcing, parameter, bounds, method, n,
                                   "band_continuation")
    if isinstance(starts, int) and not isinstance(starts, bool):
        if starts < 1:
            raise ValueError(f"starts must be a positive integer or values, got {starts!r}")
        values = lo + (np.arange(starts) + 0.5) * (hi - lo) / starts
    else:
        try:
            values = np.sort(np.asarray(starts, dtype=float).ravel())
        except (TypeError, ValueError):
            raise ValueError(f"starts must be a positive integer or values, got {starts!r}") \
                from None
        if values.size < 1 or not np.all((values >= lo) & (values <= hi)):
            raise ValueError(f"starts must lie inside bounds ({lo:g}, {hi:g}), got {starts!r}")
    if not isinstance(fill, int) or isinstance(fill, bool) or fill < 0:
        raise ValueError(f"fill must be a non-negative integer, got {fill!r}")
    integ = integrator_from(integrator, "periodic", "band_continuation",
                            {k: legacy.pop(k, None) for k in INTEGRATOR_FIELDS})
    if legacy:
        raise TypeError(f"band_continuation() got an unexpected keyword argument "
                        f"{next(iter(legacy))!r}")
    solver, rtol, atol, max_steps = integ.solver, integ.rtol, integ.atol, integ.max_steps
    cfg = _config(system, forcing, parameter, lo, solver, rtol, atol, max_steps)
    base = _Problem(system=system, forcing=forcing, s0=state_scale(system, forcing),
                    pscale=jnp.asarray(max(abs(lo), abs(hi))), cfg=cfg, parameter=parameter,
                    n=n)
    lanes = 2 * len(values)                 # the batch of the half-branches, for every phase
    out = []
    with _bar(method.max_points * lanes, parameter, progress) as bar:
        out += _band_pass(base, method, values, [(lo, hi)] * len(values), lanes, locate, bar)
        for _ in range(fill):
            values, limits = _fill_starts(_gaps(out, lo, hi), lanes // 2)
            if not values.size:
                break
            bar.total += method.max_points * 2 * values.size
            out += _band_pass(base, method, values, limits, lanes, locate, bar, linear=False)
        # the bifurcations of all the half-branches located together (each a few corrector
        # solves in turn: one after the other on its branch, the Hertz band's main pass
        # took 91 rounds of its batch, 37 bifurcations of 1-19 solves each)
        todo = [(i, j) for i, ((_, bifs, _), _, _) in enumerate(out)
                for j, b in enumerate(bifs) if isinstance(b, tuple)]
        found = _run_batched([_bifurcation(*out[i][0][1][j]) for i, j in todo], base, method,
                             lanes)
        for (i, j), b in zip(todo, found):
            out[i][0][1][j] = b
    return tuple(_branch(*r, drv, v, system) for r, drv, v in out)


def _band_pass(base, method, values, limits, lanes, locate, bar, linear=True):
    """Half-branches from the start ``values`` (start ``i`` followed within ``limits[i]``),
    all together; returns ``[(result, driver, start value)]``, two per start (down, up).
    ``linear``: first guesses from the scaled linear response before the close returns
    (the fill passes go to the close returns at once: their starts lie where the branches
    snake, near a resonance, where Newton from the linear response fails, and the failures
    cost the most: the Hertz band's fill passes spent 30 of 93 s on them); a start with no
    first guess at all (its march failed) is left out."""
    pscale = float(base.pscale)
    starters, guesses = [], []
    for v in values:
        sysv, forcv = _set_value(base.system, base.forcing, base.parameter, float(v))
        prob = dataclasses.replace(base, s0=state_scale(sysv, forcv))
        x0 = np.asarray(sysv.linear_guess(forcv)) / np.asarray(prob.s0)
        starters.append(_Driver(prob, method, (float(v), float(v))))
        guesses.append([np.append(f * x0, v / pscale) for f in START_SCALES])
    up = _axis(base, "up")
    # the first orbit at every start, all starts together: Newton from the scaled linear
    # responses, then, where none converged, from the closest returns of a marched
    # trajectory (orbits near an unstable period-n orbit pass close to it again n periods
    # later: the Kelvin–Voigt scene of scripts/benchmark_hard_contacts.py has no period-1
    # orbit near its linear response at 30.9 rad/s, where the motion is chaotic)
    firsts = [None] * len(values)
    if linear:
        firsts = _run_batched([_first_orbit(d, g, up) for d, g in zip(starters, guesses)],
                              base, method, lanes)
    missing = [i for i, f in enumerate(firsts) if f is None or not f["ok"]]
    if missing:
        seeds = _close_returns([starters[i] for i in missing], [guesses[i][0] for i in missing],
                               lanes=max(lanes // 2, len(missing)))
        seeded = [(i, g) for i, g in zip(missing, seeds) if g]
        again = _run_batched([_first_orbit(starters[i], g, up) for i, g in seeded], base,
                             method, lanes)
        for (i, _), f in zip(seeded, again):
            firsts[i] = f
    keep = [i for i, f in enumerate(firsts) if f is not None]
    values, starters, firsts = values[keep], [starters[i] for i in keep], [firsts[i] for i in keep]
    limits = [limits[i] for i in keep]
    # each start's half-branches are bounded by the nearest starts that have an orbit (every
    # cell between two of them is then followed from both ends; a start without one leaves
    # its cells to its neighbours) and by its limits
    live = np.flatnonzero([f["ok"] for f in firsts])
    drivers, gens = [], []
    for i, (v, d, first, (a, b)) in enumerate(zip(values, starters, firsts, limits)):
        below, above = values[live[live < i]], values[live[live > i]]
        for sign, cell in ((-1.0, (max(a, below[-1]) if below.size else a, v)),
                           (1.0, (v, min(b, above[0]) if above.size else b))):
            drv = _Driver(d.prob, method, cell)
            drivers.append(drv)
            gens.append(_follow(drv, dict(first, t=sign * first["t"]), None, locate, bar,
                                defer=True))
    results = _run_batched(gens, base, method, lanes)
    return [(r, drv, float(v)) for r, drv, v in zip(results, drivers, np.repeat(values, 2))]


def _fill_starts(gaps, count):
    """Start values for a fill pass: ``count`` of them (as many as the compiled batch holds,
    two half-branches each) spread over the ``gaps`` in proportion to their widths, at
    least one in each of the ``count`` widest, each at the centre of an equal part of its
    gap; returns ``(values, limits)``, the limits of each start its gap.

    Several starts in a gap rather than one at its centre: where the branches snake, a
    branch from one start turns at folds inside the gap and leaves parts of it on both
    sides, and Newton from the marched trajectory's close returns fails at some values and
    not at others nearby (the Hertz scene of scripts/benchmark_hard_contacts.py, 8 values
    over 28.30-29.35 rad/s: 4 of 8 first orbits found)."""
    gaps = gaps[:count]
    if not gaps:
        return np.zeros(0), []
    widths = np.array([g1 - g0 for g0, g1 in gaps])
    k = np.ones(len(gaps), int)
    for _ in range(count - len(gaps)):          # the next start to the gap whose parts
        k[np.argmax(widths / k)] += 1           # are widest
    values = [g0 + (m + 0.5) * (g1 - g0) / ki for (g0, g1), ki in zip(gaps, k)
              for m in range(ki)]
    limits = [g for g, ki in zip(gaps, k) for _ in range(ki)]
    order = np.argsort(values)
    return np.asarray(values)[order], [limits[i] for i in order]


def _gaps(out, lo, hi):
    """The parts of ``(lo, hi)`` that no converged point of the half-branches ``out`` (as
    ``_band_pass`` returns them) reached, wider than ``GAP`` of the band, widest
    first."""
    spans = sorted((min(v), max(v)) for v in
                   ([q["z"][-1] * float(drv.prob.pscale) for q in pts if q["ok"]]
                    for (pts, _, _), drv, _ in out) if v)
    gaps, reach = [], lo
    for a, b in spans:
        if a > reach:
            gaps.append((reach, a))
        reach = max(reach, b)
    gaps.append((reach, hi))
    return sorted((g for g in gaps if g[1] - g[0] > GAP * (hi - lo)),
                  key=lambda g: g[0] - g[1])


def _check_common(system, forcing, parameter, bounds, method, n, where):
    """Checks shared by the continuation entry points; returns ``(method, lo, hi)``."""
    require_x64(where)
    check_system_and_forcing(system, forcing, where)
    method = PseudoArclength() if method is None else method
    if not isinstance(method, PseudoArclength):
        raise ValueError(f"method must be a PseudoArclength(...), got {method!r}")
    if not isinstance(parameter, str):
        raise ValueError(f"parameter must be a name, got {parameter!r}")
    if parameter not in FORCING_PARAMETERS:
        resolve(system, parameter)
    if not isinstance(n, int) or not 1 <= n <= 64:
        raise ValueError(f"n must be an integer in [1, 64], got {n!r}")
    try:
        lo, hi = (float(b) for b in bounds)
    except (TypeError, ValueError):
        raise ValueError(f"bounds must be (lo, hi), got {bounds!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ValueError(f"bounds must be finite with lo < hi, got {bounds!r}")
    for b in (lo, hi):                      # both ends must be valid parameter values
        if parameter == "omega":
            check_scalar(where, "bounds (omega)", b, lo=0.0, lo_open=True)
        elif parameter == "amplitude":
            check_scalar(where, "bounds (amplitude)", b, lo=0.0)
        else:
            replace_params(system, {parameter: b}, check=True)
    return method, lo, hi


def _config(system, forcing, parameter, lo, solver, rtol, atol, max_steps):
    # the integrator is chosen at the lowest frequency of the bounds in an omega continuation
    if parameter == "omega":
        forcing = forcing.with_omega(lo)
    return make_config(system, forcing, solver, rtol, atol, max_steps)


def _axis(prob, direction):
    """The parameter's unit direction in the unknowns (the first point's hyperplane)."""
    e = np.zeros(prob.s0.shape[0] + 1)
    e[-1] = 1.0 if direction == "up" else -1.0
    return e


def _bar(total, parameter, progress):
    """A tqdm bar over branch points (a context manager)."""
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=f"continuation in {parameter}", disable=not progress)


def _branch(points, bifs, termination, drv, value0, system):
    steady = jax.tree_util.tree_map(lambda *a: np.stack(a), *[q["ss"] for q in points])
    pscale = float(drv.prob.pscale)
    values = np.array([q["z"][-1] * pscale if "z" in q else value0 for q in points])
    return Branch(parameter=drv.prob.parameter, values=values, steady=nan_where_failed(steady),
                  bifurcations=tuple(bifs), period_multiple=drv.prob.n,
                  termination=termination, dof_names=tuple(system.output_names),
                  signals=signals_of(system))


# ------------------------------------------------------------------- following a branch


def _first_orbit(drv, guesses, e):
    """The first orbit that Newton reaches from one of ``guesses`` (tried in turn; at least
    one) on the hyperplane normal to ``e``, or the last failed one; a generator of corrector
    requests like ``_follow``."""
    for z0 in guesses:
        point = yield (drv, z0, e, True)
        if point["ok"]:
            break
    return point


def _close_returns(drivers, z0s, periods=CLOSE_RETURN_PERIODS, count=CLOSE_RETURNS,
                   lanes=None):
    """First guesses from a trajectory marched from each ``z0`` (one vmapped solve for all
    the drivers): the states after which it came closest to returning ``n`` periods later
    (distances scaled by the spread of the samples; the first ``CLOSE_RETURN_SKIP`` samples
    are transient and left out; one guess per near passage; none where the march failed).

    ``_periodic.marching.march`` keeps the single closest period-1 return of a
    march that never settles, for ``steady_state``'s retry (march from rest, then shoot:
    what ``continuation`` falls back on); this one keeps several, of period ``n``,
    for all the starts of a band in one program, without marching's settling tests and
    Floquet solve (``steady_state`` there would compile a program of its own per call).

    The marches run as ``lanes`` lanes (padded by repeating the first: every call of a band
    compiles one program), split over the local devices (the Hertz band's fill passes: 8
    marches 2.4 s on one CPU device)."""
    prob = drivers[0].prob
    k = len(drivers)
    size = max(k, lanes or k)
    parts = device_parts(size)
    pad = [0] * (size - k)
    s0 = np.stack([np.asarray(d.prob.s0) for d in drivers])
    z = np.stack(z0s)
    with one_blas_thread(parts):
        ys, st = jax.tree_util.tree_map(np.asarray, _march_many(
            prob, s0[list(range(k)) + pad], z[list(range(k)) + pad], periods, parts))
    out = []
    for y, s, z0 in zip(ys[:k, CLOSE_RETURN_SKIP:], st[:k], z0s):
        picks = []
        if s == Status.SUCCESS and np.all(np.isfinite(y)):
            d = np.max(np.abs(np.diff(y, axis=0)) / (np.std(y, axis=0) + 1e-12), axis=1)
            for j in np.argsort(d):
                if all(abs(j - k) > 1 for k in picks):
                    picks.append(j)
                if len(picks) == count:
                    break
        out.append([np.append(y[j], z0[-1]) for j in picks])
    return out


@eqx.filter_jit
def _march_many(prob, s0, z0, periods, ndev=1):
    """``_Problem.samples`` vmapped over state scales and starting points, the lanes
    split over ``ndev`` local devices (``lanes_on_devices``)."""
    def one(prob, s, z):
        return dataclasses.replace(prob, s0=s).samples(z, periods)

    return lanes_on_devices(one, prob, s0, z0, ndev=ndev)


def _follow(drv, first, rejoin, locate, bar, defer=False):
    """Follow the branch from the point ``first`` until it ends; a generator: it yields
    corrector requests ``(driver, z_pred, t_prev, patient)``, is sent the point solved for
    each and returns ``(points, bifurcations, termination)`` (``_run`` serves it one
    request at a time, ``_run_batched`` many branches' requests in one vmapped call).
    ``defer``: the bifurcations to locate are returned as the arguments of
    ``_bifurcation`` (a copy of the driver as it was), for the caller to locate them
    all together (``band_continuation``), instead of one after the other here, the
    branch's other steps waiting."""
    method = drv.method
    points = [(yield from drv.resection(drv.rescale(first))) if first["ok"] else first]
    bifs = []
    termination = "start_failed" if not first["ok"] else None
    h = method.step
    parameter, pscale = drv.prob.parameter, float(drv.prob.pscale)
    bar.update(1)
    while termination is None:
        if len(points) >= method.max_points:
            termination = "max_points"
            break
        a = points[-1]
        b = yield (drv, a["z"] + h * a["t"], a["t"], False)
        turn = float(np.clip(b["t"] @ a["t"], -1.0, 1.0)) if b["ok"] else -1.0
        # a corner (the tangent turning abruptly where a contact starts to graze: the flow's
        # Jacobian varies like the square root of the distance to grazing) is accepted once
        # the step is below step / CORNER_REDUCTION and the corrector still converges
        sharp = (b["ok"] and math.acos(turn) > method.max_angle
                 and h > method.step / CORNER_REDUCTION)
        if not b["ok"] or sharp:
            if h <= method.min_step * (1 + 1e-12):
                termination = "step_collapse"
                break
            h = max(0.5 * h, method.min_step)
            continue
        p_b = b["z"][-1]
        if not drv.lo <= p_b <= drv.hi:
            # land on the bound: a natural-parameter corrector from the interpolated point
            bound = drv.hi if p_b > drv.hi else drv.lo
            w = (bound - a["z"][-1]) / (p_b - a["z"][-1])
            zb = a["z"] + w * (b["z"] - a["z"])
            zb[-1] = bound
            e = np.zeros_like(zb)
            e[-1] = np.sign(p_b - a["z"][-1])
            c = yield (drv, zb, e, False)
            if c["ok"]:
                c["t"] = c["t"] * np.sign(c["t"] @ a["t"] or 1.0)
                b = c
            termination = "bounds"
        for kind in _events(a, b):
            args = (copy.copy(drv), kind, a, b, len(points) - 1, locate,
                    float(np.linalg.norm(b["z"] - a["z"])))
            bifs.append(args if defer and locate else (yield from _bifurcation(*args)))
        points.append(b)
        bar.update(1)
        bar.set_postfix({parameter: f"{p_b * pscale:.6g}", "h": f"{h:.2g}"})
        if rejoin is not None and rejoin(b["x0"], b["z"][-1]):
            termination = "rejoined"
            break
        s_now = np.asarray(drv.prob.s0)
        back = np.append((b["x0"] - points[0]["x0"]) / s_now, b["z"][-1] - points[0]["z"][-1])
        if len(points) > 10 and np.linalg.norm(back) < 0.5 * h:
            termination = "closed"
            break
        points[-1] = drv.rescale(b)
        if termination is None and len(points) < method.max_points:
            points[-1] = yield from drv.resection(points[-1])
        it = int(b["ss"].iterations)
        if it <= 3:
            h = min(1.5 * h, method.max_step)
        elif it >= 6:
            h = max(0.6 * h, method.min_step)
    return points, bifs, termination


def _run(gen):
    """Serve one branch's corrector requests one at a time (the compiled corrector)."""
    try:
        request = next(gen)
        while True:
            request = gen.send(request[0].solve(*request[1:]))
    except StopIteration as stop:
        return stop.value


@eqx.filter_jit
def _corrector_many(prob, s0, section, z_pred, t_prev, patient, tol, newton_steps, ndev=1):
    """``_corrector`` vmapped over the branches' state scales, sections, predictors,
    hyperplanes and patience (the system, forcing and parameter scale shared), the lanes
    split over ``ndev`` local devices (``lanes_on_devices``)."""
    def one(prob, s, j, z, t, pa):
        return _corrector(dataclasses.replace(prob, s0=s, section=j), z, t, tol, newton_steps,
                          pa)

    return lanes_on_devices(one, prob, s0, section, z_pred, t_prev, patient, ndev=ndev)


def _run_batched(gens, prob, method, lanes=None):
    """Serve many branches' corrector requests together: each round, one request from
    each of the first ``lanes`` branches still going (default one lane per branch), solved
    in one vmapped call of ``lanes`` lanes or, once no more than a quarter of that is
    pending, of that many (padded by repeating a request: the ends of branches do not
    recompile; callers that batch several phases give them all the same ``lanes``: one
    compilation per batch size, ~5 s each on the hard-contact scenes).  With several local
    devices a batch of at least two lanes per device is split into equal parts, one per
    device, in one SPMD program (``lanes_on_devices``): the Kelvin–Voigt band of
    scripts/benchmark_hard_contacts.py takes 47.8 s on two CPU devices against 59 s on one.
    One SPMD program traces the corrector's Jacobian integration once, where a program per
    device traces it per device (the first 16-lane call: 6.6 s against 10.8 s)."""
    lanes = len(gens) if lanes is None else lanes
    # the few branches snaking through folds, or locating bifurcations, go on for many more
    # rounds (the Kelvin–Voigt scene of scripts/benchmark_hard_contacts.py spent 39 of 55 s
    # on 60 rounds of 4 branches padded to 16 before the smaller batches): the batch is
    # cut to a quarter while no more than that is pending.  A half size in between cost
    # more compilation than it saved (the Kelvin-Voigt band on 2 CPU devices, one machine:
    # sizes 16/8/4 65.6 s, 16/4 60.9 and 62.1 s, 16/2 65.0 s, 16 alone 77.4 s, the same
    # 606 points; the Hertz band 123.9 s and 123.1 s)
    sizes = [lanes] + ([lanes // 4] if lanes >= 8 else [])
    results = [None] * len(gens)
    pending = {}
    for i, g in enumerate(gens):
        try:
            pending[i] = next(g)
        except StopIteration as stop:       # a branch that asks for nothing (start_failed)
            results[i] = stop.value
    while pending:
        idx = list(pending)[:sizes[0]]          # more requests than lanes: the first ones
        size = min(z for z in sizes if z >= len(idx))
        reqs = [pending[i] for i in idx] + [pending[idx[0]]] * (size - len(idx))
        s0 = np.stack([np.asarray(r[0].prob.s0) for r in reqs])
        sec = np.stack([np.asarray(r[0].prob.section) for r in reqs])
        zp, tp = np.stack([r[1] for r in reqs]), np.stack([r[2] for r in reqs])
        pa = np.asarray([bool(r[3]) for r in reqs])
        parts = device_parts(size)
        with one_blas_thread(parts):
            out = jax.tree_util.tree_map(np.asarray, _corrector_many(
                prob, s0, sec, zp, tp, pa, method.tol, method.newton_steps, parts))
        for j, i in enumerate(idx):
            point = pending[i][0].point(*jax.tree_util.tree_map(lambda a, j=j: a[j], out))
            try:
                pending[i] = gens[i].send(point)
            except StopIteration as stop:
                results[i] = stop.value
                del pending[i]
    return results


def _bifurcation(drv, kind, a, b, index, locate, h):
    if locate:
        p, evals, ok = yield from drv.locate(kind, a, h)
    else:
        p, evals, ok = (a if abs(_g(kind, a)) < abs(_g(kind, b)) else b), 0, False
    ss = p["ss"]
    return Bifurcation(kind=kind, value=float(p["z"][-1] * drv.prob.pscale),
                       amplitude=float(ss.amplitude), state=np.asarray(ss.state),
                       multipliers=np.asarray(ss.multipliers), index=index,
                       period_multiple=drv.prob.n, located=bool(ok), evaluations=evals)


def _switch(drv, system, forcing, bif, s0, p0, cfg, parameter, pscale):
    """The first point of the period-``2n`` branch born at the period doubling ``bif``, and
    the test that it has rejoined the period-``n`` branch."""
    n1 = bif.period_multiple
    prob1 = _Problem(system=system, forcing=forcing, s0=s0, pscale=jnp.asarray(pscale), cfg=cfg,
                     parameter=parameter, n=n1)
    x_star = np.asarray(system.to_internal(jnp.asarray(bif.state))) / np.asarray(s0)
    z_star = np.append(x_star, p0)
    J = np.asarray(_jacobian(prob1, jnp.asarray(z_star)))
    m = J.shape[0]
    mu, vecs = np.linalg.eig(J[:, :m] + np.eye(m))
    v = np.real(vecs[:, np.argmin(np.abs(mu + 1.0))])
    v = v / np.linalg.norm(v)
    tv = np.append(v, 0.0)
    first = None
    for delta in (0.02, 0.05, 0.1, 0.01, 0.005):
        cand = drv.solve(z_star + delta * tv, tv)
        # a genuine period-2n orbit, not the period-n one it branched from
        if cand["ok"] and float(_defect(prob1, jnp.asarray(cand["z"]))) > 1e3 * drv.method.tol:
            first = cand
            break
    if first is None:
        first = dict(ss=jax.tree_util.tree_map(np.asarray, cand["ss"]), ok=False, z=cand["z"],
                     t=cand["t"], mult=cand["mult"])
        first["ss"] = eqx.tree_at(lambda s: s.status, first["ss"],
                                  np.asarray(Status.NO_CONVERGENCE))
    d_first = float(_defect(prob1, jnp.asarray(first["z"]))) if first["ok"] else 0.0

    def rejoined(x0, p):
        z = np.append(x0 / np.asarray(s0), p)
        return float(_defect(prob1, jnp.asarray(z))) < 0.05 * d_first

    return first, rejoined
