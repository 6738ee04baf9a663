"""Time integration of an absorber system with diffrax."""

from __future__ import annotations

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.checks import check_scalar, check_state, check_time_grid, is_traced, require_x64
from .._core.custom_types import States, Times
from .._core.custom_types import Status as StatusArray
from .._core.legacy import no_more
from .._core.status import Status, describe, from_diffrax
from .._core.tables import dataframe, trajectory_columns, trajectory_dataset, write_csv
from .._systems.base import AbstractSystem, is_hybrid
from .._systems.forcing import AbstractForcing
from .._systems.scales import warn_scales
from .flights import in_closed_form
from .settings import integrator_from
from .stickslip import hybrid_solve

# The automatic choice switches to an implicit solver when (largest rate x forcing period)
# exceeds this.  Measured on the Coulomb scene (Table 4, N = 10 N, ω = 50 rad/s,
# rtol 1e-6): eps = 1e-4 m/s (λT = 1.3e4): Tsit5 36k steps / 0.12 s per 2 s, Kvaerno5 38k
# steps / 0.89 s; eps = 1e-5 (λT = 1.3e5): Tsit5 223k steps / 0.75 s per 1 s, Kvaerno5 20k
# steps / 0.55 s; eps = 1e-6: Tsit5 exhausts 400k steps, Kvaerno5 20k steps / 0.64 s.
# Shooting is stricter: a stuck Coulomb absorber at λT = 4e4 (N = 200 N, eps = 1e-3) does not
# converge in 40 Newton steps with Tsit5 (6.9 s) but does in 3 with Kvaerno5 (0.6 s).
STIFF_STEPS_PER_PERIOD = 2.0e4

EXPLICIT_SOLVERS = {
    "tsit5": diffrax.Tsit5,
    "dopri5": diffrax.Dopri5,
    "dopri8": diffrax.Dopri8,
    "bosh3": diffrax.Bosh3,
}
IMPLICIT_SOLVERS = {
    "kvaerno3": diffrax.Kvaerno3,
    "kvaerno5": diffrax.Kvaerno5,
}
# Not offered: diffrax 0.7.2's IMEX KenCarp3/4/5 (with JAX 0.10.2) failed on every scene of
# the work-precision report, and even on y' = -0.1y - 100y split into explicit and implicit
# parts (5888 of 10000 steps rejected).
UNSUPPORTED_SOLVERS = (diffrax.KenCarp3, diffrax.KenCarp4, diffrax.KenCarp5)
SOLVERS = {**EXPLICIT_SOLVERS, **IMPLICIT_SOLVERS}
"""The time integrators accepted by name wherever a solver is chosen (``solver="kvaerno5"``),
mapped to their diffrax classes: the explicit ``"tsit5"`` (the default of non-stiff scenes),
``"dopri5"``, ``"dopri8"``, ``"bosh3"`` and the implicit ``"kvaerno3"``, ``"kvaerno5"`` (for
stiff contacts and friction bristles).  ``None`` or ``"auto"`` picks one
by [`choose_solver`][absorber_jax.choose_solver]; a diffrax solver object is accepted too.

```python
sorted(aj.SOLVERS)    # ['bosh3', 'dopri5', 'dopri8', 'kvaerno3', 'kvaerno5', 'tsit5']
```
"""

REGIME_NAMES = ("jammed", "partially gliding", "totally gliding")
"""The names of the friction regimes, indexed by the ``regime`` code of a friction scene's
[`Trajectory`][absorber_jax.Trajectory]: 0 jammed (the absorber slides less than 2 % of the
forcing period ending at that instant), 1 partially gliding, 2 totally gliding (more than
80 %).

```python
aj.REGIME_NAMES[int(traj.regime[-1])]    # e.g. "totally gliding"
```
"""


# At tight tolerances (the steady-state layer's rtol <= TIGHT_RTOL on the scaled state) an
# implicit solver gains nothing on a fast lightly damped oscillation it must resolve step by
# step (a bristle mode), and costs several times more per step: it is then chosen only where
# the stiff rate exceeds the oscillation's frequency by OSCILLATION_STIFFNESS_RATIO.
# Measured on LuGre σ0 = 1e8 (σ1 = 1e2, N = 2 N, m2 = 1 kg, 50 rad/s; bristle mode 1.4e4
# rad/s, sliding rate 5e5 1/s: a ratio of 35), one period at rtol 1e-9 (scaled): Tsit5 145k
# steps, 1.7 s; Kvaerno5 175k steps (100k rejected), 9.9 s; its monodromy by sensitivity
# equations 2.8 s (Tsit5, steps controlled on the tangents) against 25 s (Kvaerno5).  At
# simulate's looser default tolerances Kvaerno5 takes 8x fewer steps there and stays the
# choice.
TIGHT_RTOL = 1e-7
OSCILLATION_STIFFNESS_RATIO = 1.0e3


def choose_solver(system: AbstractSystem, forcing: AbstractForcing, *,
                  rtol=None) -> str:
    """The automatic solver choice: ``"tsit5"`` unless the scene is stiff (the largest rate of
    its linearised coupling [1/s], ``system.stiffness_rate()``, times the forcing period
    exceeds 2e4), then ``"kvaerno5"`` -- except at tight tolerances (``rtol <= 1e-7``, as the
    steady-state solvers use) where the stiffness comes with a fast oscillation both solvers
    must resolve (a LuGre or Dahl bristle mode, ``system.oscillation_rate()`` [rad/s]) and is
    less than 1000 times faster than it.  Returns the solver's name.

    ```python
    system, forcing = aj.presets.impact("kelvin_voigt")
    aj.choose_solver(system, forcing)    # "tsit5": a soft contact
    ```
    """
    lam, period = system.stiffness_rate(), forcing.period
    osc = system.oscillation_rate()
    if is_traced(lam) or is_traced(period) or is_traced(osc):
        return "tsit5"
    if float(lam) * float(period) <= STIFF_STEPS_PER_PERIOD:
        return "tsit5"
    if rtol is not None and float(rtol) <= TIGHT_RTOL and (
            float(lam) < OSCILLATION_STIFFNESS_RATIO * float(osc)):
        return "tsit5"
    return "kvaerno5"


def left_to_scene(solver) -> bool:
    """Whether ``solver`` leaves the choice to the scene (None or ``"auto"``): rigid impacts
    on a linear structure then fly in closed form."""
    return solver is None or (isinstance(solver, str) and solver == "auto")


def _resolve_solver(solver, system, forcing, rtol=None):
    if left_to_scene(solver):
        solver = choose_solver(system, forcing, rtol=rtol)
    if isinstance(solver, str):
        key = solver.lower()
        if key not in SOLVERS:
            raise ValueError(f"solver must be one of {sorted(SOLVERS)} or 'auto', got {solver!r}")
        return key, SOLVERS[key]()
    if isinstance(solver, UNSUPPORTED_SOLVERS):
        raise ValueError(f"solver {type(solver).__name__} is not supported (diffrax's IMEX "
                         "KenCarp solvers failed on every scene); use 'kvaerno5'")
    if isinstance(solver, diffrax.AbstractSolver):
        return type(solver).__name__.lower(), solver
    raise ValueError(f"solver must be a name, 'auto' or a diffrax solver, got {solver!r}")


def make_terms(system, forcing, energy=False):
    """The diffrax term of ``system`` (with the work and dissipation rates when
    ``energy``)."""

    def full(t, s, args):
        ds = system.vector_field(t, s[: system.num_states], forcing)
        if energy:
            pin, pdiss = system.power(t, s, forcing)
            ds = jnp.concatenate([ds, jnp.stack([pin, pdiss])])
        return ds

    return diffrax.ODETerm(full)


class Trajectory(eqx.Module):
    """A simulated trajectory.

    Attributes: ``ts`` [s]; ``ys`` the public states ``[x1, v1, x2, v2, (z)]`` at ``ts``;
    ``coupling_force`` [N], the force the absorber exerts on the primary (the contact force
    ``Fc`` for impact scenes); for friction scenes ``friction_force`` (``Fnl``),
    ``force_ratio`` (``|Fa|/|Fnl|`` with ``Fa = m2 Ẍ``, paper Figs. 13, 19) and ``regime``
    (0 jammed, 1 partially gliding, 2 totally gliding, judged over the forcing period ending at
    each instant); with ``energy=True``, ``work`` (done by the forcing) and ``dissipated``
    [J]; ``status`` (see [`Status`][absorber_jax.Status]), ``num_steps`` and ``solver``
    (its name; ``"closed-form"`` for rigid impacts integrated by the matrix exponential
    between impacts, where ``num_steps`` counts the nodes evaluated).
    """

    ts: Times
    ys: States
    coupling_force: jax.Array
    status: StatusArray
    num_steps: jax.Array
    system: AbstractSystem
    forcing: AbstractForcing
    friction_force: jax.Array | None = None
    force_ratio: jax.Array | None = None
    sliding: jax.Array | None = None
    regime: jax.Array | None = None
    work: jax.Array | None = None
    dissipated: jax.Array | None = None
    solver: str = eqx.field(static=True, default="")

    @property
    def x1(self):
        """Primary displacement ``x1`` [m] at ``ts`` (two-mass systems: ``ys[..., 0]``)."""
        return self.ys[..., 0]

    @property
    def v1(self):
        """Primary velocity ``v1`` [m/s] at ``ts`` (two-mass systems: ``ys[..., 1]``)."""
        return self.ys[..., 1]

    @property
    def x2(self):
        """Absorber displacement ``x2`` [m] at ``ts`` (two-mass systems: ``ys[..., 2]``)."""
        return self.ys[..., 2]

    @property
    def v2(self):
        """Absorber velocity ``v2`` [m/s] at ``ts`` (two-mass systems: ``ys[..., 3]``)."""
        return self.ys[..., 3]

    @property
    def z(self):
        """The friction law's internal states at ``ts`` (the Dahl or LuGre bristle deflection
        ``z`` [m]; an empty last axis for the other laws)."""
        return self.ys[..., 4:]

    @property
    def ok(self):
        """Whether the integration succeeded (``status == Status.SUCCESS``)."""
        return self.status == Status.SUCCESS

    @property
    def relative(self):
        """Absorber displacement relative to the primary, ``x2 - x1`` [m]."""
        return self.x2 - self.x1

    def dof(self, name):
        """Displacement [m or rad] of the degree of freedom ``name`` (one of
        ``system.output_names``) at ``ts``."""
        names = self.system.output_names
        if name not in names:
            raise ValueError(f"dof must be one of {list(names)}, got {name!r}")
        s = jax.vmap(self.system.to_internal)(self.ys)
        return jax.vmap(self.system.outputs)(s)[:, names.index(name)]

    def observed(self):
        """The system's observable signal (``x1`` for the two-mass systems) at ``ts``."""
        s = jax.vmap(self.system.to_internal)(self.ys)
        return jax.vmap(self.system.observable)(s)

    def mechanical_energy(self):
        """The system's mechanical energy (kinetic plus stored) [J] at ``ts``."""
        to_int = jax.vmap(self.system.to_internal)
        return jax.vmap(self.system.mechanical_energy)(to_int(self.ys))

    def to_csv(self, path):
        """One row per save time, SI values, each header with its unit: ``t [s]``, the
        public state (``x1 [m]``, ``v1 [m/s]`` ...), the degrees of freedom that are not
        state components, the coupling force(s) [N], the friction fields and energies when
        present."""

        write_csv(path, trajectory_columns(self))

    def to_dataframe(self):
        """The rows of ``to_csv`` as a ``pandas.DataFrame`` (needs pandas)."""

        return dataframe(trajectory_columns(self), "Trajectory.to_dataframe")

    def to_xarray(self):
        """An ``xarray.Dataset`` over ``time`` [s]: each public state component, the degrees
        of freedom (over ``dof``), the observable and the forces with ``units`` and
        ``long_name``; ``status`` with its code names (needs xarray)."""

        return trajectory_dataset(self)

    def amplitude(self, signal="x1", last_periods=10):
        """Half peak-to-peak [m] of ``signal`` over the last ``last_periods`` forcing periods
        (host-side helper for plots and reports)."""
        x = np.asarray(getattr(self, signal))
        ts = np.asarray(self.ts)
        T = float(self.forcing.period)
        sel = ts >= ts[-1] - last_periods * T
        return 0.5 * (x[sel].max() - x[sel].min())


def _integrate_states(system, forcing, solver, t0, t1, ts, s0, rtol, atol, dt0, max_steps, throw,
                      energy, closed_form=False):
    """States at ``ts`` (with the work and dissipation columns when ``energy``), status and
    step count: one diffrax solve, or the event-driven segments of a hybrid system."""
    if is_hybrid(system):
        ys, _, status, nsteps, _, _ = hybrid_solve(
            system, forcing, s0, t0, t1, ts, solver=solver, rtol=rtol, atol=atol,
            max_steps=max_steps, scale=jnp.ones_like(s0),
            max_segments=max_steps,  # every segment takes at least one step
            closed_form=closed_form)
        if throw:
            ys = eqx.error_if(ys, status != Status.SUCCESS, "stick–slip integration failed "
                              "(max_steps, or more switches than allowed: chattering)")
        return ys, status, nsteps
    terms = make_terms(system, forcing, energy)
    if energy:
        s0 = jnp.concatenate([s0, jnp.zeros(2, s0.dtype)])
    sol = diffrax.diffeqsolve(
        terms,
        solver,
        t0,
        t1,
        dt0,
        s0,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        max_steps=max_steps,
        throw=throw,
    )
    return sol.ys, from_diffrax(sol.result), sol.stats["num_steps"]


@eqx.filter_jit
def _solve(system, forcing, solver, t0, t1, ts, s0, rtol, atol, dt0, max_steps, throw, energy,
           closed_form):
    ys, status, nsteps = _integrate_states(system, forcing, solver, t0, t1, ts, s0, rtol, atol,
                                           dt0, max_steps, throw, energy, closed_form)
    n = system.num_states
    s = ys[:, :n]
    status = jnp.where(
        (status == Status.SUCCESS) & ~jnp.all(jnp.isfinite(s)), Status.NONFINITE, status
    )
    out = dict(
        ts=ts,
        ys=system.to_public(s),
        status=status,
        num_steps=nsteps,
        system=system,
        forcing=forcing,
        **system.trajectory_fields(ts, s, forcing),
    )
    if energy:
        out.update(work=ys[:, n], dissipated=ys[:, n + 1])
    return out


def simulate(
    system: AbstractSystem,
    forcing: AbstractForcing,
    t1,
    *,
    t0=0.0,
    ts=None,
    y0=None,
    integrator=None,
    throw=True,
    energy=False,
    saves_per_period=40,
    **legacy,
) -> Trajectory:
    """Integrate ``system`` under ``forcing`` from ``t0`` to ``t1`` [s] (float64, diffrax).

    **Arguments**

    - ``system``: any system (``ImpactAbsorber``, ``FrictionAbsorber``,
      ``StructuralSystem``, or one of your own).
    - ``forcing``: any ``AbstractForcing`` (``Harmonic``, ``MultiHarmonic``,
      ``PeriodicForcing``, ``RampedHarmonic``, or one of your own).
    - ``t1``: final time [s]; ``t0``: initial time (default 0).
    - ``ts``: save times (sorted, within ``[t0, t1]``); default a uniform grid with
      ``saves_per_period`` points per forcing period (at least 1001).
    - ``y0``: public initial state (``system.state_names`` gives its layout, e.g.
      ``[x1, v1, x2, v2]`` for the two-mass absorbers, then ``z`` for Dahl and LuGre);
      default rest.
    - ``integrator``: an ``Integrator`` (default: rtol 1e-8, atol 1e-10 on the state in SI
      units, the solver chosen by the scene's stiffness, ``max_steps`` per forcing period:
      the run's budget is that times its number of periods).
    - ``throw``: raise on failure, with what to try (``False``: read ``trajectory.status``
      instead).
    - ``energy``: also integrate the work done by the forcing and the dissipated energy.

    **Returns** a ``Trajectory``.

    ```python
    import absorber_jax as aj
    system, forcing = aj.presets.impact("kelvin_voigt")
    traj = aj.simulate(system, forcing, 2.0)
    traj.amplitude("x1")   # half peak-to-peak of the primary over the last 10 periods
    ```
    """
    require_x64("simulate")
    if not isinstance(system, AbstractSystem):
        raise ValueError(
            f"system must be an ImpactAbsorber, FrictionAbsorber or StructuralSystem, got "
            f"{type(system).__name__}"
        )
    if not isinstance(forcing, AbstractForcing):
        if callable(forcing):
            raise ValueError("forcing must be a forcing object, got a plain function: wrap a "
                             "periodic one as PeriodicForcing(function, omega) with its "
                             "fundamental angular frequency omega [rad/s] (or subclass "
                             "AbstractForcing for a signal that is not periodic)")
        raise ValueError(f"forcing must be a forcing (e.g. Harmonic), got {type(forcing).__name__}")
    integ = integrator_from(integrator, "simulate", "simulate", legacy)
    no_more("simulate", legacy)
    solver, rtol, atol, dt0 = integ.solver, integ.rtol, integ.atol, integ.dt0
    check_scalar("simulate", "t0", t0)
    check_scalar("simulate", "t1", t1, lo=float(t0), lo_open=True)
    check_scalar("simulate", "rtol", rtol, lo=0.0, hi=1.0, lo_open=True, hi_open=True)
    # the budget: max_steps per forcing period, times the run's number of periods
    max_steps = int(integ.max_steps * max(1, math.ceil((t1 - t0) / float(forcing.period))))
    check_state("y0", y0, system.num_states)
    warn_scales(system, forcing, "simulate")
    if energy and is_hybrid(system):
        raise ValueError("simulate.energy=True is not available with an exact stick–slip law "
                         "(friction.exact=True): use the smoothed law for energy bookkeeping")
    if ts is None:
        n = int(
            min(
                max(1001, math.ceil((t1 - t0) / float(forcing.period) * saves_per_period) + 1),
                400_001,
            )
        )
        ts = jnp.linspace(t0, t1, n)
    else:
        check_time_grid("ts", ts, t0=float(t0), t1=float(t1))
        ts = jnp.asarray(ts, dtype=float)
    name, solver_obj = _resolve_solver(solver, system, forcing)
    # rigid impacts on a linear structure under harmonics: flights in closed form, unless
    # a solver was named
    closed_form = (left_to_scene(solver) and is_hybrid(system)
                   and in_closed_form(system, forcing))
    if closed_form:
        name = "closed-form"
    s0 = system.rest_state() if y0 is None else system.to_internal(jnp.asarray(y0, dtype=float))
    f = lambda x: jnp.asarray(x, dtype=float)
    out = _solve(
        system,
        forcing,
        solver_obj,
        f(t0),
        f(t1),
        ts,
        s0,
        f(rtol),
        f(atol),
        None if dt0 is None else f(dt0),
        max_steps,
        False,    # failures come back as a status; ``throw`` is checked here, on the host
        bool(energy),
        closed_form,
    )
    traj = Trajectory(**out, solver=name)
    if throw and not is_traced(traj.status) and int(traj.status) != Status.SUCCESS:
        raise RuntimeError(f"simulate failed: {describe(int(traj.status))} (pass throw=False "
                           "to get the trajectory up to the failure, with its status)")
    return traj
