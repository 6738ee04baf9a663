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
falls below ``ZENO_FRACTION`` of the forcing period, or where the next bounce would rise
less than ``ZENO_HEIGHT`` of the motion's length scale, at least the gap (below what the
flights' rounding resolves): the body then sticks to the wall (a plastic end of the
sequence, momentum conserved) and moves with it until the force that holds it there would
turn tensile.
"""

import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .._core import units
from .._core.checks import as_float, check_scalar, positive
from .contact import AbstractCompliantLaw, AbstractContactLaw

# a Zeno sequence of impacts shorter than this fraction of the forcing period ends in
# sticking at once (see the module docstring)
ZENO_FRACTION = 1e-7
# ... as does one whose next bounce would rise less than this fraction of the motion's
# length scale (at least the gap) off the wall (``w⁺²/(2|ü|)``): the flights' rounding of
# the relative position (~1e-14 of the motion's size) gives the bounces back about as much
# energy as the impacts take once they are that low (e = 0.947 under 0.8 m/s²: bounces
# stalled at 4e-9 m/s, 3125 impacts in one period, where the rest of the sequence would
# last 60 times ZENO_FRACTION of it)
ZENO_HEIGHT = 1e-12
# the integrator takes at least this many steps per forcing period with rigid walls (an
# impact is located from a sign change at the ends of a step: a graze shorter than a step
# is missed, so the steps bound how deep a missed excursion can be)
RIGID_STEPS_PER_PERIOD = 256


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

    def field_unit(self, field: str) -> str:
        """SI unit of the law's parameter field ``field`` (``e``: 1)."""
        return units.field_unit(field)

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

    def settles(self, w_after, accel, period, length):
        """Whether a Zeno sequence ends in sticking after an impact leaving the wall at
        speed ``|w_after|`` [m/s] under a relative acceleration ``|accel|`` [m/s²] into it:
        the rest of the sequence (``zeno_time``) lasts no more than ``ZENO_FRACTION`` of
        the forcing ``period`` [s], or the next bounce rises no more than ``ZENO_HEIGHT``
        times ``length`` [m] (the motion's length scale, at least the gap) off the wall."""
        a = jnp.maximum(jnp.abs(accel), 1e-300)
        low = w_after * w_after / (2.0 * a) <= ZENO_HEIGHT * length
        return (self.zeno_time(w_after, accel) <= ZENO_FRACTION * period) | low

    def wall_force(self, x, rate):
        zero = jnp.zeros_like(jnp.asarray(x, dtype=float))
        return zero, zero, zero

    def wall_energy(self, x):
        return jnp.zeros_like(jnp.asarray(x, dtype=float))

    def dissipated_power(self, x, rate):
        return jnp.zeros_like(jnp.asarray(x, dtype=float))

    def stiffness_rate(self, meff, scale):
        return jnp.zeros(())


def restitution_of(law, m, M=math.inf, impact_velocity=1.0, *, steps=20_000):
    """The coefficient of restitution a compliant ``law`` gives a single impact of masses
    ``m`` and ``M`` [kg] (``M = inf``: against a fixed wall) at relative speed
    ``impact_velocity`` [m/s] (it depends on the speed unless the law is linear).

    The contact ``meff δ̈ = -f(δ, δ̇)`` from ``δ = 0``, ``δ̇ = v0`` is integrated by
    fourth-order Runge–Kutta in ``steps`` steps of the undamped contact's time scale, to
    separation: ``δ`` back to zero, or, for a non-adhesive law, the force back to zero
    while the bodies part (the located instant interpolated linearly);
    ``e = -δ̇_separation / v0``.  The converse, the law for a restitution:
    [`KelvinVoigt.from_restitution`][absorber_jax.KelvinVoigt.from_restitution] (exact).

    ```python
    restitution_of(KelvinVoigt.from_restitution(1e5, 0.6, m=0.2, M=1.0), 0.2, 1.0)  # 0.6
    ```
    """
    if not isinstance(law, AbstractCompliantLaw):
        raise ValueError(f"restitution_of.law must be a compliant contact law (KelvinVoigt, "
                         f"Hertz, HuntCrossley), got {type(law).__name__}")
    positive("restitution_of", "m", m)
    positive("restitution_of", "M", M)
    positive("restitution_of", "impact_velocity", impact_velocity)
    meff = m if math.isinf(M) else m * M / (m + M)
    v0 = float(impact_velocity)
    p = float(law.exponent)
    k = float(law.stiffness)
    # the undamped contact's largest penetration, and a time scale of the whole contact
    depth = ((p + 1) * meff * v0**2 / (2 * k)) ** (1 / (p + 1))
    dt = 4.0 * depth / v0 / steps

    def accel(y):
        return -law.force(jnp.maximum(y[0], 0.0), y[1]) / meff

    def rhs(y):
        return jnp.stack([y[1], accel(y)])

    def parted(y):
        gone = y[0] <= 0.0
        if not law.adhesive:
            gone = gone | ((law.force(jnp.maximum(y[0], 0.0), y[1]) <= 0.0) & (y[1] < 0.0))
        return gone

    def body(c):
        y, _, i = c
        k1 = rhs(y)
        k2 = rhs(y + 0.5 * dt * k1)
        k3 = rhs(y + 0.5 * dt * k2)
        k4 = rhs(y + dt * k3)
        return y + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4), y, i + 1

    def cond(c):
        y, _, i = c
        return (~parted(y) | (i < 2)) & (i < 100 * steps)

    y0 = jnp.array([0.0, v0])
    y, prev, _ = jax.jit(lambda y0: jax.lax.while_loop(cond, body, (y0, y0, 0)))(y0)
    # the separation between the last two steps, by linear interpolation of the criterion
    if law.adhesive:
        ga, gb = float(prev[0]), float(y[0])
    else:
        fa = float(law.force(max(float(prev[0]), 0.0), float(prev[1])))
        fb = float(law.force(max(float(y[0]), 0.0), float(y[1])))
        ga, gb = (float(prev[0]), float(y[0])) if float(y[0]) <= 0.0 else (fa, fb)
    s = ga / (ga - gb) if ga != gb else 1.0
    v_sep = float(prev[1]) + s * (float(y[1]) - float(prev[1]))
    return -v_sep / v0
