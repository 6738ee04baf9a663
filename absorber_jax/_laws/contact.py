r"""Impact (contact) laws of the impact absorber, paper section 2.

A law maps a penetration ``δ ≥ 0`` [m] and its rate ``δ̇`` [m/s] to a compressive force
[N].  The system applies it at both walls of the clearance,
``δ+ = max(0, y - d)`` and ``δ- = max(0, -y - d)`` with ``y = x2 - x1``, smoothed with
``eps`` [m]: ``δ = eps·softplus(x/eps)`` and ``δ̇ = sigmoid(x/eps)·ẏ`` (the exact time
derivative of the smoothed penetration, so the viscous term switches on with contact).
"""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from .._core.checks import as_float, nonnegative, positive
from .smooth import smooth_clip_positive, smooth_gate, smooth_relu


class AbstractContactLaw(eqx.Module):
    """Base class of the impact laws: ``force(δ, δ̇) = elastic(δ) + viscous(δ, δ̇)``.

    Subclasses define ``stiffness``, ``damping``, ``eps`` and ``adhesive`` fields and the
    elastic and viscous parts.  With ``adhesive=False`` the total force is clipped at zero
    (smoothly), so the law never pulls the masses together at separation; the paper's
    laws pull (its "weakness" list), which is the default here to reproduce it.
    """

    exponent: ClassVar[float]  # power of δ in the elastic term

    stiffness: eqx.AbstractVar[object]
    damping: eqx.AbstractVar[object]
    eps: eqx.AbstractVar[object]
    adhesive: eqx.AbstractVar[bool]

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
        """Smoothed force at one wall: ``x`` is the signed penetration coordinate
        (``y - d`` on the right wall, ``-y - d`` on the left) and ``rate`` its derivative.

        Returns ``(force, δ, δ̇)``."""
        delta = smooth_relu(x, self.eps)
        delta_dot = smooth_gate(x, self.eps) * rate
        return self.force(delta, delta_dot), delta, delta_dot

    def dissipated_power(self, x, rate):
        """Power [W] dissipated at one wall: ``(force - elastic)·rate``.  With the conservative
        part a function of ``x`` alone, this closes the energy balance of the smoothed ODE
        exactly (up to the ``O(k eps²)`` difference between its potential and
        :meth:`potential`)."""
        f, delta, _ = self.wall_force(x, rate)
        return (f - self.elastic_force(delta)) * rate

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
        return (self.potential(jnp.maximum(u - gap, 0.0))
                + self.potential(jnp.maximum(-u - gap, 0.0)))

    def clearance_dissipation(self, u, rate, gap):
        """Power [W] dissipated in the two walls (:meth:`dissipated_power` of each)."""
        return self.dissipated_power(u - gap, rate) + self.dissipated_power(-u - gap, -rate)

    def stiffness_rate(self, meff, scale):
        """A rough largest rate [1/s] the law adds to the linearised dynamics, for the
        automatic explicit/implicit solver choice (``scale``: a typical penetration [m])."""
        s = jnp.maximum(scale, self.eps)
        k_lin = self.exponent * self.stiffness * s ** (self.exponent - 1)
        c_lin = self.viscous_force(s, 1.0)
        return jnp.maximum(jnp.sqrt(k_lin / meff), c_lin / meff)


class KelvinVoigt(AbstractContactLaw):
    r"""Linear spring–dashpot contact, the paper's *linear* model (section 2.1, Table 1):

    $$f(δ, δ̇) = k_1 δ + c_1 δ̇ .$$

    **Arguments**

    - ``stiffness``: $k_1$ [N/m] (Table 1: 400).
    - ``damping``: $c_1$ [N s/m] (Table 1: 20).
    - ``eps``: smoothing length of the contact onset [m].
    - ``adhesive``: ``True`` (the paper's law, pulls at separation) or ``False`` (force
      clipped at zero).

    Single impact of two free masses (``meff = mM/(m+M)``): contact time ``π/ω_d``,
    ``ω_d = sqrt(k1/meff - (c1/(2 meff))²)``, restitution ``exp(-ζπ/sqrt(1-ζ²))``.

    ```python
    law = KelvinVoigt(stiffness=400.0, damping=20.0)
    law.force(1e-3, 0.1)   # 400*1e-3 + 20*0.1 = 2.4 N
    ```
    """

    exponent: ClassVar[float] = 1.0
    stiffness: object = eqx.field(converter=as_float)
    damping: object = eqx.field(converter=as_float)
    eps: object = eqx.field(converter=as_float, default=1e-6)
    adhesive: bool = eqx.field(static=True, default=True)

    def elastic_force(self, delta):
        return self.stiffness * delta

    def viscous_force(self, delta, delta_dot):
        return self.damping * delta_dot

    def potential(self, delta):
        return 0.5 * self.stiffness * delta**2


class _AbstractHertzian(AbstractContactLaw):
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

    - ``stiffness``: $k_{Hz}$ [N/m^{3/2}] (Table 2: 3260); see :func:`hertz_stiffness`.
    - ``damping``: $c_1$ [N s/m] (Table 2: 20).
    - ``eps``, ``adhesive``: as in :class:`KelvinVoigt`.

    Undamped single impact: contact time ``2.9432 (5 meff/(4 kHz))^{2/5} v0^{-1/5}``
    (Johnson, *Contact Mechanics*, 1985, §11.4).

    ```python
    law = Hertz(stiffness=3260.0, damping=20.0)
    law.force(1e-4, 0.0)   # 3260 * 1e-6 = 3.26e-3 N
    ```
    """

    stiffness: object = eqx.field(converter=as_float)
    damping: object = eqx.field(converter=as_float)
    eps: object = eqx.field(converter=as_float, default=1e-6)
    adhesive: bool = eqx.field(static=True, default=True)

    def viscous_force(self, delta, delta_dot):
        return self.damping * delta_dot



class HuntCrossley(_AbstractHertzian):
    r"""Hunt–Crossley contact, the paper's *nonlinear* model (section 2.3, Table 3):

    $$f(δ, δ̇) = k_{Hz} δ^{3/2} + c_1 δ^{3/2} δ̇ .$$

    The damping vanishes with the penetration, so the force starts and ends at zero.
    Hunt & Crossley, *J. Appl. Mech.* 42 (1975) 440; the paper's damping from restitution
    (:func:`hunt_crossley_damping`) is Lankarani & Nikravesh's, *J. Mech. Des.* 112 (1990).

    **Arguments**

    - ``stiffness``: $k_{Hz}$ [N/m^{3/2}] (Table 3: 3260).
    - ``damping``: $c_1$ [N s/m^{5/2}] (Table 3: 469.5).
    - ``eps``, ``adhesive``: as in :class:`KelvinVoigt`.

    ```python
    law = HuntCrossley(stiffness=3260.0, damping=469.5)
    law.force(1e-2, -0.1)  # 1e-3*(3260 - 46.95) = 3.21 N
    ```
    """

    stiffness: object = eqx.field(converter=as_float)
    damping: object = eqx.field(converter=as_float)
    eps: object = eqx.field(converter=as_float, default=1e-6)
    adhesive: bool = eqx.field(static=True, default=True)

    def viscous_force(self, delta, delta_dot):
        return self.damping * delta**1.5 * delta_dot


CONTACT_LAWS = {"kelvin_voigt": KelvinVoigt, "hertz": Hertz, "hunt_crossley": HuntCrossley}
