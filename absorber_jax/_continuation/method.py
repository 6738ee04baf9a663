"""The continuation method: pseudo-arclength, as an object carrying its options."""

from __future__ import annotations

import math

import equinox as eqx

from .._core.checks import check_scalar


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
    - ``locate``: locate each bifurcation (a few corrector solves each); ``False``: report
      it at the nearer branch point.
    """

    step: float = eqx.field(static=True, default=0.01)
    min_step: float = eqx.field(static=True, default=1e-6)
    max_step: float = eqx.field(static=True, default=0.05)
    max_points: int = eqx.field(static=True, default=400)
    tol: float = eqx.field(static=True, default=1e-6)
    newton_steps: int = eqx.field(static=True, default=12)
    max_angle: float = eqx.field(static=True, default=0.35)
    locate_tol: float = eqx.field(static=True, default=1e-9)
    locate: bool = eqx.field(static=True, default=True)

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
