r"""The rigid impact law: Newton's coefficient of restitution, integrated exactly by events.

A rigid body meets a wall without penetrating it.  At the instant of contact (the event
``y = ±d``) the relative normal velocity ``w`` of the two bodies is reversed and scaled
by the coefficient of restitution ``e``, and momentum is conserved:

$$w^+ = -e\,w^-, \qquad P = (1+e)\,m_{\rm eff}\,w^-, \qquad
m_{\rm eff} = \Big(\sum_i G_i^2/m_i\Big)^{-1},$$

``P`` the normal impulse [N s] and ``G`` the contact's direction in the bodies' coordinates
(``m_eff = mM/(m+M)`` for two masses; the inverse of ``G M⁻¹ Gᵀ`` for a structure of mass
matrix ``M``).  The kinetic energy lost is ``½ m_eff (1-e²) w⁻²``.  Between impacts the
law exerts no force.  This is the model of the impact-damper literature (S. F. Masri,
T. K. Caughey, *On the stability of the impact damper*, J. Appl. Mech. 33 (1966) 586;
C. N. Bapat, S. Sankar, *Single unit impact damper in free and forced vibration*, J. Sound
Vib. 99 (1985) 85).

**Sticking.**  A body pressed against a wall (its free relative acceleration ``ü`` pointing
into the wall) and bouncing with ``e < 1`` makes an infinite sequence of ever shorter
flights that ends at a finite time (a Zeno sequence: after an impact at speed ``w⁺`` the
remaining flights last ``2|w⁺| / (|ü|(1-e))`` in all).  The systems end it when that time
falls below ``ZENO_FRACTION`` of the forcing period: the body then sticks to the wall (a
plastic end of the sequence, momentum conserved) and moves with it until the force that
holds it there would turn tensile.
"""

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from .._core.checks import as_float, check_scalar
from .contact import AbstractContactLaw

# a Zeno sequence of impacts shorter than this fraction of the forcing period ends in
# sticking at once (see the module docstring)
ZENO_FRACTION = 1e-7


class Restitution(AbstractContactLaw):
    r"""Rigid impacts with coefficient of restitution ``e`` (Newton's law, exact).

    Usable wherever a contact law is: [`ImpactAbsorber`][absorber_jax.ImpactAbsorber],
    [`ImpactDamper`][absorber_jax.ImpactDamper] and [`Contact`][absorber_jax.Contact].  The
    system is then integrated event by event: no penetration, no contact stiffness, no
    step-size collapse; the Floquet multipliers and design gradients carry the saltation
    matrices of the impacts.

    **Arguments**

    - ``e``: coefficient of restitution in ``[0, 1]`` (0: plastic, the bodies stay together
      while pressed; 1: elastic).

    The compliant law with the same restitution:
    [`KelvinVoigt.from_restitution`][absorber_jax.KelvinVoigt.from_restitution]; the restitution
    a compliant law gives: [`restitution_of`][absorber_jax.restitution_of].

    ```python
    sys = ImpactAbsorber(M=1.0, k=1e3, c=0.1, m=0.2, gap=2e-3, contact=Restitution(0.6))
    ```
    """

    exact: ClassVar[bool] = True
    e: object = eqx.field(converter=as_float)

    def __check_init__(self):
        check_scalar("Restitution", "e", self.e, lo=0.0, hi=1.0)

    def impulse(self, w, meff):
        """Normal impulse [N s] of an impact at relative normal velocity ``w`` [m/s] (into
        the wall) between bodies of effective mass ``meff`` [kg]: ``(1 + e) meff w``."""
        return (1.0 + self.e) * meff * w

    def zeno_time(self, w_after, accel):
        """Duration [s] of the rest of a Zeno sequence after an impact leaving the wall at
        speed ``|w_after|`` under a relative acceleration ``|accel|`` into it:
        ``2|w⁺| / (|ü|(1-e))`` (infinite for ``e = 1``)."""
        a = jnp.maximum(jnp.abs(accel), 1e-300)
        return jnp.where(self.e < 1.0, 2.0 * jnp.abs(w_after) / (a * jnp.maximum(1.0 - self.e,
                                                                                  1e-300)),
                         jnp.inf)

    def wall_force(self, x, rate):
        zero = jnp.zeros_like(jnp.asarray(x, dtype=float))
        return zero, zero, zero

    def wall_energy(self, x):
        return jnp.zeros_like(jnp.asarray(x, dtype=float))

    def dissipated_power(self, x, rate):
        return jnp.zeros_like(jnp.asarray(x, dtype=float))

    def stiffness_rate(self, meff, scale):
        return jnp.zeros(())
