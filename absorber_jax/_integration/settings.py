"""Integration settings as one object, and the one table of their defaults.

Every entry point that integrates takes ``integrator=Integrator(...)``: the diffrax solver,
the PID step-size controller's tolerances and the step budget.  A field left ``None`` takes
the default of the task at hand, from ``DEFAULTS``, the only place those defaults live:

- ``"simulate"`` (``simulate``): rtol 1e-8, atol 1e-10 on the state in SI units [m, m/s];
- ``"periodic"`` (``steady_state``, ``frequency_response``, ``attractors``,
  ``continuation``, ``band_continuation``): rtol = atol = 1e-9 on the state scaled by the
  orbit's own amplitude and velocity;
- ``"design"`` (``tune``, ``value_and_grad``, ``exact_peak``, ``robust_peak``): rtol = atol
  = 1e-10, tighter because gradients and the located peaks inherit the integration error;
- ``max_steps`` 200 000 for all: the step budget per forcing period (an integration over
  ``n`` periods, a run of ``simulate`` or a period-``n`` map, may take ``n`` times as many).

The solver defaults to the scene's choice: explicit Tsit5, or implicit Kvaerno5 when the
scene is stiff (``choose_solver``).  Rigid impacts (``Restitution``) on a linear structure
under a forcing with exact harmonics are integrated in closed form between their impacts
(the matrix exponential, exact to rounding; ``_integration.flights``) unless a solver is
named.
"""

from __future__ import annotations

import equinox as eqx

from .._core.checks import check_scalar
from .._core.legacy import moved


class Integrator(eqx.Module):
    """The time integration: ``solver``, tolerances and step budget (module docstring).

    - ``solver``: ``None`` or ``"auto"`` (explicit Tsit5, or implicit Kvaerno5 when the
      scene is stiff: ``choose_solver``), a name in ``SOLVERS``, or a diffrax
      solver object.
    - ``rtol``, ``atol``: the PID step-size controller's relative and absolute tolerances.
    - ``max_steps``: the step budget per forcing period.
    - ``dt0``: the first step [s] (``None``: diffrax chooses); used by ``simulate`` only,
      the periodic solvers let diffrax choose.

    ```python
    import absorber_jax as aj
    aj.Integrator(rtol=1e-10, atol=1e-12)            # solver chosen by the scene
    aj.Integrator(solver="kvaerno5", max_steps=50_000)
    ```
    """

    solver: object = eqx.field(static=True, default=None)
    rtol: float | None = eqx.field(static=True, default=None)
    atol: float | None = eqx.field(static=True, default=None)
    max_steps: int | None = eqx.field(static=True, default=None)
    dt0: float | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        if self.rtol is not None:
            check_scalar("Integrator", "rtol", self.rtol, lo=0.0, hi=1.0, lo_open=True,
                         hi_open=True)
        for name in ("atol", "dt0"):
            value = getattr(self, name)
            if value is not None:
                check_scalar("Integrator", name, value, lo=0.0, lo_open=True)
        if self.max_steps is not None and (isinstance(self.max_steps, bool)
                                           or not isinstance(self.max_steps, int)
                                           or self.max_steps < 1):
            raise ValueError(f"Integrator.max_steps must be a positive integer, got "
                             f"{self.max_steps!r}")

    def resolved(self, task: str) -> Integrator:
        """This integrator with every ``None`` tolerance and budget replaced by the
        default of ``task`` (``"simulate"``, ``"periodic"`` or ``"design"``)."""
        base = DEFAULTS[task]
        return Integrator(
            solver=self.solver,
            rtol=base.rtol if self.rtol is None else float(self.rtol),
            atol=base.atol if self.atol is None else float(self.atol),
            max_steps=base.max_steps if self.max_steps is None else int(self.max_steps),
            dt0=self.dt0,
        )


FIELDS = ("solver", "rtol", "atol", "max_steps", "dt0")

DEFAULTS = {
    "simulate": Integrator(rtol=1e-8, atol=1e-10, max_steps=200_000),
    "periodic": Integrator(rtol=1e-9, atol=1e-9, max_steps=200_000),
    "design": Integrator(rtol=1e-10, atol=1e-10, max_steps=200_000),
}


def integrator_from(integrator, task, where, legacy, fields=FIELDS):
    """The resolved ``Integrator`` of an entry point: ``integrator`` (or a default one)
    with the deprecated flat keywords among ``fields`` popped from ``legacy`` and filled in
    (a ``DeprecationWarning`` names the new form); an integrator together with such keywords
    is refused."""

    legacy = {k: legacy.pop(k) for k in fields if k in legacy}
    given = {k: v for k, v in legacy.items() if v is not None}
    if integrator is None:
        integrator = Integrator()
    elif given:
        raise ValueError(f"{where}: give {sorted(given)} on the integrator "
                         f"(aj.Integrator(...)), not as keywords")
    elif not isinstance(integrator, Integrator):
        raise ValueError(f"{where}.integrator must be an aj.Integrator(...), got "
                         f"{type(integrator).__name__}")
    if given:
        moved(where, given, "integrator=aj.Integrator({})")
        fields = {f: getattr(integrator, f) for f in FIELDS}
        fields.update(given)
        integrator = Integrator(**fields)
    return integrator.resolved(task)
