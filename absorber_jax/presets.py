"""The paper's scenes (Tables 1–5) by name, with our documented defaults for what the
paper omits.

**Assumptions** (the paper gives no value):

- impact scenes: clearance ``gap = 1e-3`` m on each side;
- friction scenes: ``normal_force = 2`` N and a harmonic force of 50 rad/s whose amplitude
  ramps linearly from 0 to 40 N over 20 s (``FRICTION_NORMAL_FORCE``, ``FRICTION_OMEGA``,
  ``FRICTION_F0``, ``FRICTION_RAMP``).  With the absorber stuck the two masses move as one 2 kg body
  (``k1 = 1e4``), so the friction needed to hold it is ``m2 ω² |x1|`` with
  ``|x1| = F0/(k1 - 2 m ω²)``; sticking breaks at ``F0* = μ N (k1 - 2ω²)/ω²``, which is
  2 N for the defaults (N = 2 N, ω = 50 rad/s), so the ramp to 40 N passes 20 times the
  threshold and one run shows the jammed, partially gliding and totally gliding absorber
  (measured: Coulomb jammed until 1.1 s, totally gliding from 7.5 s; LuGre from 14 s).
- The friction scenes are undamped as printed (``c1 = c2 = 0``) and use ``v_s = 1e4`` m/s as
  printed; ``friction("stribeck_physical")`` and ``friction("lugre_physical")`` use
  ``v_s = 1e-2`` m/s, where the Stribeck peak matters.

```python
import absorber_jax as aj
system, forcing = aj.presets.impact("hunt_crossley")
system, forcing = aj.presets.friction("lugre")
```
"""

from __future__ import annotations

from ._laws.contact import Hertz, HuntCrossley, KelvinVoigt
from ._laws.friction import Coulomb, Dahl, LuGre, Stribeck
from ._systems.absorbers import FrictionAbsorber, ImpactAbsorber
from ._systems.forcing import Harmonic, RampedHarmonic

IMPACT_GAP = 1e-3
IMPACT_EPS = 1e-6
FRICTION_NORMAL_FORCE = 2.0
FRICTION_OMEGA = 50.0
FRICTION_F0 = 40.0
FRICTION_RAMP = 20.0
FRICTION_EPS = 1e-4

IMPACT_SCENES = ("kelvin_voigt", "hertz", "hunt_crossley")
FRICTION_SCENES = ("coulomb", "stribeck", "dahl", "lugre", "stribeck_physical", "lugre_physical")

_TABLE = dict(M=1.0, m=0.4, k=1e3, c=0.1)
_F0, _OMEGA = 2.0, 47.4


def contact_law(name: str, *, eps: float = IMPACT_EPS, adhesive: bool = True):
    """The contact law of Table 1 (``kelvin_voigt``), 2 (``hertz``) or 3 (``hunt_crossley``)."""
    if name == "kelvin_voigt":
        return KelvinVoigt(stiffness=400.0, damping=20.0, eps=eps, adhesive=adhesive)
    if name == "hertz":
        return Hertz(stiffness=3260.0, damping=20.0, eps=eps, adhesive=adhesive)
    if name == "hunt_crossley":
        return HuntCrossley(stiffness=3260.0, damping=469.5, eps=eps, adhesive=adhesive)
    raise ValueError(f"impact scene must be one of {IMPACT_SCENES}, got {name!r}")


def impact(name: str = "kelvin_voigt", *, gap: float = IMPACT_GAP, eps: float = IMPACT_EPS,
           adhesive: bool = True, omega: float = _OMEGA, amplitude: float = _F0):
    """``(ImpactAbsorber, Harmonic)`` of the paper's Table 1, 2 or 3.

    ``name``: ``"kelvin_voigt"`` (linear), ``"hertz"`` (semi-linear) or ``"hunt_crossley"``
    (nonlinear).  All: M = 1 kg, m = 0.4 kg, k = 1e3 N/m, c = 0.1 N s/m, F0 = 2 N,
    ω = 47.4 rad/s; ``gap`` is our assumption (1 mm)."""
    law = contact_law(name, eps=eps, adhesive=adhesive)
    return (ImpactAbsorber(gap=gap, contact=law, **_TABLE),
            Harmonic(amplitude=amplitude, omega=omega))


def friction_law(name: str, *, eps: float = FRICTION_EPS):
    """The friction law of Table 4 (``coulomb``, ``stribeck``) or 5 (``dahl``, ``lugre``);
    ``*_physical`` use ``v_s = 1e-2`` m/s."""
    if name == "coulomb":
        return Coulomb(mu=0.5, eps=eps)
    if name in ("stribeck", "stribeck_physical"):
        return Stribeck(mu_c=0.5, mu_s=0.6, v_s=1e4 if name == "stribeck" else 1e-2, eps=eps)
    if name == "dahl":
        return Dahl(mu_c=0.5, sigma0=1e4, eps=eps)
    if name in ("lugre", "lugre_physical"):
        return LuGre(mu_c=0.5, mu_s=0.6, v_s=1e4 if name == "lugre" else 1e-2, sigma0=1e4,
                     sigma1=1e2, sigma2=0.0, eps=eps)
    raise ValueError(f"friction scene must be one of {FRICTION_SCENES}, got {name!r}")


def friction(name: str = "coulomb", *, normal_force: float = FRICTION_NORMAL_FORCE,
             eps: float = FRICTION_EPS, omega: float = FRICTION_OMEGA,
             amplitude: float = FRICTION_F0, ramp_time: float | None = FRICTION_RAMP):
    """``(FrictionAbsorber, forcing)`` of the paper's Table 4 or 5.

    m1 = m2 = 1 kg, k1 = k2 = 1e4 N/m, undamped.  The forcing is a
    [`RampedHarmonic`][absorber_jax.RampedHarmonic] (``ramp_time`` s) or, with ``ramp_time=None``, a
    constant [`Harmonic`][absorber_jax.Harmonic]."""
    law = friction_law(name, eps=eps)
    system = FrictionAbsorber(m1=1.0, k1=1e4, c1=0.0, m2=1.0, k2=1e4, c2=0.0,
                              normal_force=normal_force, friction=law)
    if ramp_time is None:
        forcing = Harmonic(amplitude=amplitude, omega=omega)
    else:
        forcing = RampedHarmonic(amplitude=amplitude, omega=omega, ramp_time=ramp_time)
    return system, forcing


def scene(name: str, **kwargs):
    """Any scene by name (impact or friction)."""
    if name in IMPACT_SCENES:
        return impact(name, **kwargs)
    if name in FRICTION_SCENES:
        return friction(name, **kwargs)
    raise ValueError(f"scene must be one of {IMPACT_SCENES + FRICTION_SCENES}, got {name!r}")
