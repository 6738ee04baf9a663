r"""Impact (contact) laws of the impact absorber, paper section 2.

A law maps a penetration ``δ ≥ 0`` [m] and its rate ``δ̇`` [m/s] to a compressive force
[N].  The system applies it at both walls of the clearance,
``δ+ = max(0, y - d)`` and ``δ- = max(0, -y - d)`` with ``y = x2 - x1``, smoothed with
``eps`` [m]: ``δ = eps·softplus(x/eps)`` and ``δ̇ = sigmoid(x/eps)·ẏ`` (the exact time
derivative of the smoothed penetration, so the viscous term switches on with contact).
"""

# (no ``from __future__ import annotations`` here: equinox reads ``AbstractVar`` only from
# evaluated annotations; as strings they would become required fields of the base class)

import abc
import math
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from .._core import units
from .._core.checks import as_float, check_scalar, nonnegative, positive
from .smooth import smooth_clip_positive, smooth_gate, smooth_relu


class AbstractContactLaw(eqx.Module):
    """Base class of every contact law: what happens where a clearance closes.

    Two families implement it: the compliant (penalty) laws
    ([`AbstractCompliantLaw`][absorber_jax.AbstractCompliantLaw]: a force grows with the
    penetration, integrated as a smooth vector field) and the rigid impact law
    [`Restitution`][absorber_jax.Restitution] (no penetration: velocities jump at the walls
    by Newton's law, integrated event by event).  ``exact`` tells them apart; the wall
    members below give the force between events (zero for the rigid law).
    """

    # True: the rigid law, integrated by events at the walls
    # (absorber_jax._integration.stickslip)
    exact: eqx.AbstractClassVar[bool]

    @abc.abstractmethod
    def field_unit(self, field: str) -> str:
        """SI unit of the law's parameter field ``field``."""

    @abc.abstractmethod
    def wall_force(self, x, rate):
        """Force [N] at one wall: ``x`` is the signed penetration coordinate
        (``y - d`` on the right wall, ``-y - d`` on the left) and ``rate`` its derivative.

        Returns ``(force, δ, δ̇)``."""

    @abc.abstractmethod
    def wall_energy(self, x):
        """Elastic energy [J] stored at one wall at signed penetration ``x`` [m]."""

    @abc.abstractmethod
    def dissipated_power(self, x, rate):
        """Power [W] dissipated at one wall at signed penetration ``x`` and rate ``rate``."""

    @abc.abstractmethod
    def stiffness_rate(self, meff, scale):
        """A rough largest rate [1/s] the law adds to the linearised dynamics, for the
        automatic explicit/implicit solver choice (``scale``: a typical penetration [m])."""

    # a symmetric clearance: two walls at ±gap around the relative displacement u (the
    # impact absorber of the paper and the ImpactDamper element share these)

    def clearance_penetrations(self, u, gap):
        """``(u - gap, -u - gap)``: the signed penetrations of the right and left walls [m]."""
        return jnp.stack([u - gap, -u - gap])

    def clearance_force(self, u, rate, gap):
        """Net force [N] of the two walls on the relative coordinate ``u`` (rate ``rate``):
        ``f(u - gap, u̇) - f(-u - gap, -u̇)``, the force the absorber exerts on its host."""
        fr, _, _ = self.wall_force(u - gap, rate)
        fl, _, _ = self.wall_force(-u - gap, -rate)
        return fr - fl

    def clearance_energy(self, u, gap):
        """Elastic energy [J] stored in the two walls."""
        return self.wall_energy(u - gap) + self.wall_energy(-u - gap)

    def clearance_dissipation(self, u, rate, gap):
        """Power [W] dissipated in the two walls (``dissipated_power`` of each)."""
        return self.dissipated_power(u - gap, rate) + self.dissipated_power(-u - gap, -rate)


class AbstractCompliantLaw(AbstractContactLaw):
    """Base class of the compliant (penalty) laws:
    ``force(δ, δ̇) = elastic(δ) + viscous(δ, δ̇)``, smoothed at the contact onset over
    ``eps``.

    Subclasses define ``stiffness``, ``damping``, ``eps`` and ``adhesive`` fields and the
    elastic and viscous parts.  With ``adhesive=False`` (the laws' default) the total force
    is clipped at zero (smoothly), so a wall never pulls the masses together at separation;
    the paper's laws pull (its "weakness" list), which its presets reproduce with
    ``adhesive=True``.
    """

    exact: ClassVar[bool] = False
    exponent: ClassVar[float]  # power of δ in the elastic term
    damping_unit: eqx.AbstractClassVar[str]   # of the damping field

    stiffness: eqx.AbstractVar[object]
    damping: eqx.AbstractVar[object]
    eps: eqx.AbstractVar[object]
    adhesive: eqx.AbstractVar[bool]

    def field_unit(self, field: str) -> str:
        """``stiffness`` [N/m^exponent], ``damping`` [``damping_unit``], ``eps`` [m]."""
        if field == "stiffness":
            return "N/m" if float(self.exponent) == 1.0 else f"N/m^{float(self.exponent):g}"
        if field == "damping":
            return self.damping_unit
        return "m" if field == "eps" else units.field_unit(field)

    @abc.abstractmethod
    def elastic_force(self, delta):
        """Conservative part [N] at penetration ``delta`` [m]."""

    @abc.abstractmethod
    def viscous_force(self, delta, delta_dot):
        """Dissipative part [N]."""

    @abc.abstractmethod
    def potential(self, delta):
        """Elastic energy [J] stored at penetration ``delta`` (the exact, nonsmooth one)."""

    def __check_init__(self):
        name = type(self).__name__
        positive(name, "stiffness", self.stiffness)
        nonnegative(name, "damping", self.damping)
        positive(name, "eps", self.eps)

    def force(self, delta, delta_dot):
        """Contact force [N] for penetration ``delta`` [m] and rate ``delta_dot`` [m/s]."""
        f = self.elastic_force(delta) + self.viscous_force(delta, delta_dot)
        if not self.adhesive:
            f = smooth_clip_positive(f, self.stiffness * self.eps**self.exponent)
        return f

    def wall_force(self, x, rate):
        """Smoothed force at one wall: ``δ = eps·softplus(x/eps)``,
        ``δ̇ = sigmoid(x/eps)·rate``.  Returns ``(force, δ, δ̇)``."""
        delta = smooth_relu(x, self.eps)
        delta_dot = smooth_gate(x, self.eps) * rate
        return self.force(delta, delta_dot), delta, delta_dot

    def wall_energy(self, x):
        return self.potential(jnp.maximum(x, 0.0))

    def dissipated_power(self, x, rate):
        """Power [W] dissipated at one wall: ``(force - elastic)·rate``.  With the conservative
        part a function of ``x`` alone, this closes the energy balance of the smoothed ODE
        exactly (up to the ``O(k eps²)`` difference between its potential and
        ``potential``)."""
        f, delta, _ = self.wall_force(x, rate)
        return (f - self.elastic_force(delta)) * rate

    def stiffness_rate(self, meff, scale):
        s = jnp.maximum(scale, self.eps)
        k_lin = self.exponent * self.stiffness * s ** (self.exponent - 1)
        c_lin = self.viscous_force(s, 1.0)
        return jnp.maximum(jnp.sqrt(k_lin / meff), c_lin / meff)


class KelvinVoigt(AbstractCompliantLaw):
    r"""Linear spring–dashpot contact, the paper's *linear* model (section 2.1, Table 1):

    $$f(δ, δ̇) = k_1 δ + c_1 δ̇ .$$

    **Arguments**

    - ``stiffness``: $k_1$ [N/m] (Table 1: 400).
    - ``damping``: $c_1$ [N s/m] (Table 1: 20); default 0 (elastic).
    - ``eps``: smoothing length of the contact onset [m].
    - ``adhesive``: ``False`` (default: the total force is clipped at zero, a wall never
      pulls) or ``True`` (the paper's law as printed, which pulls at separation while
      ``c1 δ̇ < -k1 δ``; the paper's presets use it).

    ``from_restitution`` gives the damping of a target coefficient of restitution.

    Single impact of two free masses (``meff = mM/(m+M)``): contact time ``π/ω_d``,
    ``ω_d = sqrt(k1/meff - (c1/(2 meff))²)``, restitution ``exp(-ζπ/sqrt(1-ζ²))``.

    ```python
    law = KelvinVoigt(stiffness=400.0, damping=20.0)
    law.force(1e-3, 0.1)   # 400*1e-3 + 20*0.1 = 2.4 N
    ```
    """

    exponent: ClassVar[float] = 1.0
    damping_unit: ClassVar[str] = "N s/m"
    stiffness: object = eqx.field(converter=as_float)
    damping: object = eqx.field(converter=as_float, default=0.0)
    eps: object = eqx.field(converter=as_float, default=1e-6)
    adhesive: bool = eqx.field(static=True, default=False)

    def elastic_force(self, delta):
        return self.stiffness * delta

    def viscous_force(self, delta, delta_dot):
        return self.damping * delta_dot

    def potential(self, delta):
        return 0.5 * self.stiffness * delta**2

    @classmethod
    def from_restitution(cls, stiffness, restitution, m, M=math.inf, *, eps=1e-6,
                         adhesive=False):
        r"""The law whose damping gives a single impact of masses ``m`` and ``M`` [kg]
        (``M = inf``: against a fixed wall) the coefficient of restitution ``restitution``
        ``e`` in ``(0, 1]``, exactly for the law as built.

        With ``meff = mM/(m+M)``, ``ω_n = sqrt(k1/meff)`` and ``ζ = c1/(2 meff ω_n)``, the
        penetration during contact is ``δ = (v0/ω_d) e^{-ζω_n t} sin(ω_d t)``.  The adhesive
        law separates at ``δ = 0`` (``ω_d t = π``): ``e = exp(-ζπ/sqrt(1-ζ²))``, inverted in
        closed form, ``ζ = -ln e / sqrt(π² + ln² e)``.  The non-adhesive law separates
        earlier, where the force ``k1 δ + c1 δ̇`` reaches zero, at
        ``θ = ω_d t = π - atan2(2ζ sqrt(1-ζ²), 1-2ζ²)``, with
        ``e = -e^{-ζθ/sqrt(1-ζ²)} (cos θ - ζ sin θ / sqrt(1-ζ²))``, which falls
        monotonically from 1 at ``ζ = 0`` and is inverted by bisection.

        ```python
        law = KelvinVoigt.from_restitution(1e5, 0.6, m=0.2, M=1.0)
        ```
        """
        check_scalar("KelvinVoigt.from_restitution", "restitution", restitution, lo=0.0,
                     hi=1.0, lo_open=True)
        positive("KelvinVoigt.from_restitution", "stiffness", stiffness)
        positive("KelvinVoigt.from_restitution", "m", m)
        positive("KelvinVoigt.from_restitution", "M", M)
        meff = m if math.isinf(M) else m * M / (m + M)
        zeta = _zeta_of_restitution(float(restitution), bool(adhesive))
        damping = 2.0 * zeta * math.sqrt(float(stiffness) * meff)
        return cls(stiffness=stiffness, damping=damping, eps=eps, adhesive=adhesive)


def restitution_of_zeta(zeta, adhesive):
    """The coefficient of restitution of a single Kelvin–Voigt impact of damping ratio
    ``zeta`` in ``[0, 1)`` (``KelvinVoigt.from_restitution``)."""
    r = math.sqrt(1.0 - zeta**2)
    if adhesive:
        return math.exp(-zeta * math.pi / r)
    theta = math.pi - math.atan2(2.0 * zeta * r, 1.0 - 2.0 * zeta**2)
    return -math.exp(-zeta * theta / r) * (math.cos(theta) - zeta * math.sin(theta) / r)


def _zeta_of_restitution(e, adhesive):
    if e >= 1.0:
        return 0.0
    if adhesive:
        ln = math.log(e)
        return -ln / math.sqrt(math.pi**2 + ln**2)
    lo, hi = 0.0, 1.0 - 1e-12
    if restitution_of_zeta(hi, False) > e:
        raise ValueError(f"KelvinVoigt.from_restitution: a restitution of {e} needs an "
                         "overdamped contact; use a larger restitution or adhesive=True")
    for _ in range(200):                       # bisection: e(ζ) is monotonic
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if restitution_of_zeta(mid, False) > e else (lo, mid)
        if hi - lo < 1e-15:
            break
    return 0.5 * (lo + hi)


class _AbstractHertzian(AbstractCompliantLaw):
    """Hertz elastic part ``kHz δ^{3/2}`` and its energy ``(2/5) kHz δ^{5/2}``."""

    exponent: ClassVar[float] = 1.5

    def elastic_force(self, delta):
        return self.stiffness * delta**1.5

    def potential(self, delta):
        return 0.4 * self.stiffness * delta**2.5


class Hertz(_AbstractHertzian):
    r"""Hertz elastic contact with linear viscous damping, the paper's *semi-linear* model
    (section 2.2, Table 2):

    $$f(δ, δ̇) = k_{Hz} δ^{3/2} + c_1 δ̇ .$$

    **Arguments**

    - ``stiffness``: $k_{Hz}$ [N/m^{3/2}] (Table 2: 3260); see
      [`hertz_stiffness`][absorber_jax.hertz_stiffness].
    - ``damping``: $c_1$ [N s/m] (Table 2: 20).
    - ``eps``, ``adhesive``: as in [`KelvinVoigt`][absorber_jax.KelvinVoigt].

    Undamped single impact: contact time ``2.9432 (5 meff/(4 kHz))^{2/5} v0^{-1/5}``
    (Johnson, *Contact Mechanics*, 1985, §11.4).

    ```python
    law = Hertz(stiffness=3260.0, damping=20.0)
    law.force(1e-4, 0.0)   # 3260 * 1e-6 = 3.26e-3 N
    ```
    """

    damping_unit: ClassVar[str] = "N s/m"
    stiffness: object = eqx.field(converter=as_float)
    damping: object = eqx.field(converter=as_float, default=0.0)
    eps: object = eqx.field(converter=as_float, default=1e-6)
    adhesive: bool = eqx.field(static=True, default=False)

    def viscous_force(self, delta, delta_dot):
        return self.damping * delta_dot



class HuntCrossley(_AbstractHertzian):
    r"""Hunt–Crossley contact, the paper's *nonlinear* model (section 2.3, Table 3):

    $$f(δ, δ̇) = k_{Hz} δ^{3/2} + c_1 δ^{3/2} δ̇ .$$

    The damping vanishes with the penetration, so the force starts and ends at zero.
    Hunt & Crossley, *J. Appl. Mech.* 42 (1975) 440; the paper's damping from restitution
    ([`hunt_crossley_damping`][absorber_jax.hunt_crossley_damping]) is Lankarani & Nikravesh's, *J.
    Mech. Des.* 112 (1990).

    **Arguments**

    - ``stiffness``: $k_{Hz}$ [N/m^{3/2}] (Table 3: 3260).
    - ``damping``: $c_1$ [N s/m^{5/2}] (Table 3: 469.5).
    - ``eps``, ``adhesive``: as in [`KelvinVoigt`][absorber_jax.KelvinVoigt].

    ```python
    law = HuntCrossley(stiffness=3260.0, damping=469.5)
    law.force(1e-2, -0.1)  # 1e-3*(3260 - 46.95) = 3.21 N
    ```
    """

    damping_unit: ClassVar[str] = "N s/m^2.5"
    stiffness: object = eqx.field(converter=as_float)
    damping: object = eqx.field(converter=as_float, default=0.0)
    eps: object = eqx.field(converter=as_float, default=1e-6)
    adhesive: bool = eqx.field(static=True, default=False)

    def viscous_force(self, delta, delta_dot):
        return self.damping * delta**1.5 * delta_dot



CONTACT_LAWS = {"kelvin_voigt": KelvinVoigt, "hertz": Hertz, "hunt_crossley": HuntCrossley}
