r"""Friction laws of the friction absorber, paper section 3 (the laws, their units and the
paper's Tables 4–5 are on the Mechanics page of the documentation).

A law gives the friction force ``Fnl`` [N] that drags the absorber along with the primary,
as a function of the relative sliding velocity ``v = Ẋ = ẋ1 - ẋ2`` [m/s], the normal force
``N`` [N] (a field of the system, so it can be tuned) and, for Dahl and LuGre only, the
bristle deflection ``z`` [m] carried as an extra state.  ``eps`` [m/s] smooths ``sign(v)``
as ``tanh(v/eps)`` (Coulomb, Stribeck, on request) and ``|v|`` as ``v·tanh(v/eps)`` (Dahl,
LuGre, on request); by default every law is exact.
"""

# (no ``from __future__ import annotations`` here: equinox reads ``AbstractVar`` only from
# evaluated annotations; as strings they would become required fields of the base class)

import abc
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from .._core import units
from .._core.checks import as_float, check_scalar, is_traced, nonnegative, positive
from .smooth import abs_or_smooth, smooth_sign


class AbstractFrictionLaw(eqx.Module):
    """Base class of the friction laws.

    ``num_states`` is the number of internal states the law adds to the system's state
    (0 for Coulomb and Stribeck, 1 for Dahl and LuGre).
    """

    num_states: ClassVar[int]
    # True: the law is the nonsmooth eps -> 0 limit, integrated by switching between stick
    # and slip at events (see absorber_jax._integration.stickslip)
    exact: eqx.AbstractVar[bool]

    def __check_init__(self):
        if self.exact and not isinstance(self, AbstractStickSlipLaw):
            raise ValueError(f"{type(self).__name__}: exact=True needs a memoryless law "
                             "derived from AbstractStickSlipLaw (it gives breakaway_force "
                             "and kinetic_force); give eps for a smoothed law instead")

    @abc.abstractmethod
    def force(self, v, z, normal_force):
        """Friction force [N] at sliding velocity ``v`` and internal state ``z``
        (an array of shape ``(num_states,)``)."""

    @abc.abstractmethod
    def state_rate(self, v, z, normal_force):
        """Time derivative of the internal state."""

    def field_unit(self, field: str) -> str:
        """SI unit of the law's parameter field ``field`` (``eps``: a sliding velocity
        [m/s]; ``mu`` 1, ``sigma0`` [N/m] ...)."""
        return "m/s" if field == "eps" else units.field_unit(field)

    @abc.abstractmethod
    def stored_energy(self, z):
        """Elastic energy [J] held in the internal state."""

    @abc.abstractmethod
    def dissipated_power(self, v, z, normal_force):
        """Power [W] the law dissipates: ``Fnl·v - d/dt stored_energy``."""

    @abc.abstractmethod
    def steady_force(self, v, normal_force):
        """Friction force [N] in steady sliding at constant velocity ``v`` (the law's
        friction curve, paper Figs. 9, 10, 15, 16)."""

    @abc.abstractmethod
    def is_sliding(self, v, z, normal_force):
        """Boolean: the contact is in gross sliding (not stuck / pre-sliding)."""

    @abc.abstractmethod
    def stiffness_rate(self, normal_force, meff):
        """A rough largest rate [1/s] the law adds to the dynamics (solver choice)."""

    @abc.abstractmethod
    def oscillation_rate(self, normal_force, meff):
        """Angular frequency [rad/s] of a lightly damped fast oscillation the law adds (a
        bristle mode), which any solver must resolve step by step at tight tolerances
        (solver choice; 0 when the law has none)."""

    def initial_state(self):
        return jnp.zeros((self.num_states,), dtype=jnp.result_type(float))

    @abc.abstractmethod
    def kinetic_level(self, normal_force):
        """Kinetic (Coulomb) level ``μc N`` [N] of the friction force in gross sliding."""

    @abc.abstractmethod
    def state_scale(self, normal_force):
        """Natural size of the internal states."""


class AbstractMemorylessFrictionLaw(AbstractFrictionLaw):
    """A friction law without internal states: the force is a function of the sliding
    velocity and the normal force alone (Coulomb, Stribeck, or one's own), so nothing is
    stored, the power dissipated is ``Fnl·v`` and no bristle mode is added."""

    num_states: ClassVar[int] = 0

    def state_rate(self, v, z, normal_force):
        return jnp.zeros((0,), dtype=jnp.result_type(v))

    def stored_energy(self, z):
        return jnp.zeros((), dtype=jnp.result_type(float))

    def dissipated_power(self, v, z, normal_force):
        return self.force(v, z, normal_force) * v

    def oscillation_rate(self, normal_force, meff):
        del normal_force, meff
        return jnp.zeros(())

    def state_scale(self, normal_force):
        return jnp.zeros((0,))


class AbstractStickSlipLaw(AbstractMemorylessFrictionLaw):
    """A memoryless friction law (no internal state) that can also be integrated exactly:
    with ``exact=True`` the contact switches between stick and slip at events (see
    ``absorber_jax._integration.stickslip``), and the law gives the two levels those events
    need.  Coulomb and Stribeck are such laws; a law with internal states (Dahl, LuGre) is
    not."""

    @abc.abstractmethod
    def breakaway_force(self, normal_force):
        """Largest friction force [N] the contact holds while stuck (``μs N``)."""

    @abc.abstractmethod
    def kinetic_force(self, speed, normal_force):
        """Friction force magnitude [N] while slipping at ``speed = |Ẋ| >= 0``."""


# Sliding speed [m/s] at which the bristle relaxation rate σ0|v|/F is taken for the automatic
# solver choice.  Calibrated by measurement (scripts/work_precision.py, LuGre σ1 = 1e2, N = 2,
# 50 rad/s): Tsit5 finds the steady state faster than Kvaerno5 up to σ0 = 1e7 (7.8 s against
# 102 s; 3 periods: 55k against 12k steps, 0.21 s against 0.30 s) and fails to converge at
# σ0 = 1e8, where Kvaerno5 succeeds; at 5 mm/s the switch falls between the two.
BRISTLE_SLIDING_SPEED = 5e-3


# Dahl and LuGre use |v| itself by default (eps = 0).  Their vector field is then continuous
# (a kink at v = 0, no jump), so no event is needed: the flow is C^1 across transversal
# crossings of v = 0 (the saltation matrix of a continuous field is the identity: Leine &
# Nijmeijer, Dynamics and Bifurcations of Non-Smooth Mechanical Systems, 2004), and
# forward-mode tangents give the monodromy matrix.  The smoothed |v| ~ v tanh(v/eps) turns the
# bristle into a plain linear spring once its velocity falls below eps, so the bound
# |sigma0 z| <= max g no longer holds; stiff bristles stick at ~omega mu_s N / sigma0, and at
# sigma0 = 1e8, eps = 1e-4 the smoothed model has a fully stuck orbit holding 5 N against
# mu_s N = 1.2 N (scripts/study_lugre_stiff_bristles.py).


def _bristle_rate(v, z, sigma0, eps, level):
    """``ż = v - σ0 |v| z / level`` (Dahl: ``level = F_c``; LuGre: ``level = g(v)``), with
    ``|v|`` exact (``eps = 0``) or smoothed."""
    return jnp.stack([v - sigma0 * abs_or_smooth(v, eps) * z[0] / level])


# smoothing length [m/s] of Coulomb and Stribeck when they are asked to smooth without one
DEFAULT_EPS = 1e-4


def _exact_and_eps(eps, exact):
    """The default of the memoryless laws is the exact (event-driven) law; giving ``eps``
    asks for the tanh-smoothed law instead (``exact=False, eps=None`` smooths with
    ``DEFAULT_EPS``)."""
    if exact is None:
        exact = eps is None
    if not isinstance(exact, bool):
        raise ValueError(f"exact must be True or False, got {exact!r}")
    return exact, (DEFAULT_EPS if eps is None else eps)


class Coulomb(AbstractStickSlipLaw):
    r"""Coulomb kinetic friction, paper section 3.2, Fig. 9:

    $$F_{nl} = \mu N\,\mathrm{sign}(\dot X) \approx \mu N \tanh(\dot X/\varepsilon).$$

    **Arguments**

    - ``mu``: friction coefficient $\mu_c$ [-] (Table 4: 0.5).
    - ``eps``: give it to smooth ``sign`` as ``tanh(Ẋ/eps)`` [m/s]. The smoothed law
      converges like ``eps`` to the exact one; small ``eps`` makes the scene stiff, and a
      fixed ``eps`` makes results depend on the scale of the motion.
    - ``exact``: default ``True`` when no ``eps`` is given: the nonsmooth law itself, with
      stick and slip segments switched at events, exact to the integrator's tolerance and
      independent of the scale of the motion, with derivatives through the event times
      (the saltation matrices of the switches).

    ```python
    law = Coulomb(mu=0.5)            # exact stick–slip
    law.force(1.0, None, 10.0)       # 0.5 * 10 = 5 N (sliding forwards)
    Coulomb(mu=0.5, eps=1e-4)        # tanh-smoothed, eps = 1e-4 m/s
    ```
    """

    mu: object = eqx.field(converter=as_float)
    eps: object = eqx.field(converter=as_float)
    exact: bool = eqx.field(static=True)

    def __init__(self, mu, eps=None, exact=None):
        self.mu = mu
        self.exact, self.eps = _exact_and_eps(eps, exact)

    def __check_init__(self):
        nonnegative("Coulomb", "mu", self.mu)
        positive("Coulomb", "eps", self.eps)

    def force(self, v, z, normal_force):
        sgn = jnp.sign(v) if self.exact else smooth_sign(v, self.eps)
        return self.mu * normal_force * sgn

    def steady_force(self, v, normal_force):
        return self.force(v, None, normal_force)

    def is_sliding(self, v, z, normal_force):
        return jnp.abs(v) > (0.0 if self.exact else 10.0 * self.eps)

    def stiffness_rate(self, normal_force, meff):
        if self.exact:  # no smoothing layer: only the structure's own rates remain
            return jnp.zeros(())
        return self.mu * normal_force / (self.eps * meff)

    def kinetic_level(self, normal_force):
        return self.mu * normal_force

    def breakaway_force(self, normal_force):
        return self.mu * normal_force

    def kinetic_force(self, speed, normal_force):
        return self.mu * normal_force * jnp.ones_like(speed)


class Stribeck(AbstractStickSlipLaw):
    r"""Coulomb friction with a Stribeck static peak, paper section 3.2, Fig. 10:

    $$F_{nl} = N\left(\mu_c + (\mu_s-\mu_c)\,e^{-(\dot X/v_s)^2}\right)\mathrm{sign}(\dot X).$$

    **Arguments**

    - ``mu_c``, ``mu_s``: kinetic and static coefficients, ``mu_s >= mu_c`` (Table 4: 0.5,
      0.6).
    - ``v_s``: Stribeck velocity [m/s] (Table 4 prints 1e4, which makes the exponential 1
      for any realistic speed, i.e. Coulomb with ``mu_s``; a physical value is ~1e-2).
    - ``eps``, ``exact``: as for [`Coulomb`][absorber_jax.Coulomb]; the exact law (the default)
      sticks while the holding force stays within ``μs N`` and slips at
      ``N(μc + (μs-μc)e^{-(Ẋ/vs)²})``.

    ```python
    law = Stribeck(mu_c=0.5, mu_s=0.6, v_s=1e-2)
    law.steady_force(1.0, 10.0)  # -> 5.0 N (kinetic level far above v_s)
    ```
    """

    mu_c: object = eqx.field(converter=as_float)
    mu_s: object = eqx.field(converter=as_float)
    v_s: object = eqx.field(converter=as_float)
    eps: object = eqx.field(converter=as_float)
    exact: bool = eqx.field(static=True)

    def __init__(self, mu_c, mu_s, v_s, eps=None, exact=None):
        self.mu_c, self.mu_s, self.v_s = mu_c, mu_s, v_s
        self.exact, self.eps = _exact_and_eps(eps, exact)

    def __check_init__(self):
        nonnegative("Stribeck", "mu_c", self.mu_c)
        check_scalar(
            "Stribeck", "mu_s", self.mu_s, lo=float(self.mu_c) if not is_traced(self.mu_c) else None
        )
        positive("Stribeck", "v_s", self.v_s)
        positive("Stribeck", "eps", self.eps)

    def level(self, v, normal_force):
        return normal_force * (
            self.mu_c + (self.mu_s - self.mu_c) * jnp.exp(-((v / self.v_s) ** 2))
        )

    def force(self, v, z, normal_force):
        sgn = jnp.sign(v) if self.exact else smooth_sign(v, self.eps)
        return self.level(v, normal_force) * sgn

    def steady_force(self, v, normal_force):
        return self.force(v, None, normal_force)

    def is_sliding(self, v, z, normal_force):
        return jnp.abs(v) > (0.0 if self.exact else 10.0 * self.eps)

    def stiffness_rate(self, normal_force, meff):
        if self.exact:
            return jnp.zeros(())
        return self.mu_s * normal_force / (self.eps * meff)

    def kinetic_level(self, normal_force):
        return self.mu_c * normal_force

    def breakaway_force(self, normal_force):
        return self.mu_s * normal_force

    def kinetic_force(self, speed, normal_force):
        return self.level(speed, normal_force)


class Dahl(AbstractFrictionLaw):
    r"""Dahl bristle friction, paper section 3.3, Fig. 15:

    $$F_{nl} = \sigma_0 z,\qquad \dot z = \dot X - \frac{\sigma_0 |\dot X|}{F_c} z,
    \qquad F_c = \mu_c N .$$

    Dahl, *Aerospace Corp. report* TOR-0158 (1968).  ``|z| <= F_c/σ0`` is invariant.

    **Arguments**

    - ``mu_c``: kinetic coefficient (Table 5: 0.5).
    - ``sigma0``: bristle stiffness σ0 [N/m] (Table 5: 1e4).
    - ``eps``: ``0`` (default): ``|Ẋ|`` exactly, and ``|z| <= F_c/σ0`` holds (the field is
      continuous, no events are needed); ``eps > 0``: smoothed as ``Ẋ tanh(Ẋ/eps)`` [m/s],
      which behaves as a linear spring below ``eps`` and lets the bristle overshoot
      ``F_c/σ0`` when it moves slower than that (stiff bristles).

    ```python
    law = Dahl(mu_c=0.5, sigma0=1e4)
    law.steady_force(0.1, 10.0)  # -> 5.0 N
    ```
    """

    num_states: ClassVar[int] = 1
    exact: ClassVar[bool] = False
    mu_c: object = eqx.field(converter=as_float)
    sigma0: object = eqx.field(converter=as_float)
    eps: object = eqx.field(converter=as_float, default=0.0)

    def __check_init__(self):
        nonnegative("Dahl", "mu_c", self.mu_c)
        positive("Dahl", "sigma0", self.sigma0)
        nonnegative("Dahl", "eps", self.eps)

    def _fc(self, normal_force):
        # a tiny floor keeps N = 0 finite: the bristle then never deflects (z -> 0)
        return jnp.maximum(self.mu_c * normal_force, 1e-300)

    def force(self, v, z, normal_force):
        return self.sigma0 * z[0]

    def state_rate(self, v, z, normal_force):
        return _bristle_rate(v, z, self.sigma0, self.eps, self._fc(normal_force))

    def stored_energy(self, z):
        return 0.5 * self.sigma0 * z[0] ** 2

    def kinetic_level(self, normal_force):
        return self.mu_c * normal_force

    def state_scale(self, normal_force):
        # bristle deflection: its natural size is the saturation value μc N / σ0
        return jnp.stack([jnp.maximum(self.mu_c * normal_force / self.sigma0, 1e-15)])

    def dissipated_power(self, v, z, normal_force):
        # σ0 z (v - ż) = σ0² |v| z² / Fc >= 0
        return self.sigma0 * z[0] * (v - self.state_rate(v, z, normal_force)[0])

    def steady_force(self, v, normal_force):
        return self.mu_c * normal_force * jnp.sign(v)

    def is_sliding(self, v, z, normal_force):
        # gross sliding: bristles past half their saturation, loaded in the sliding direction
        f = self.sigma0 * z[0]
        return (jnp.abs(f) > 0.5 * self.mu_c * normal_force) & (f * v > 0)

    def stiffness_rate(self, normal_force, meff):
        # bristle vibration, and the relaxation rate σ0|v|/Fc of z while sliding
        return jnp.maximum(jnp.sqrt(self.sigma0 / meff),
                           self.sigma0 * BRISTLE_SLIDING_SPEED / self._fc(normal_force))

    def oscillation_rate(self, normal_force, meff):
        del normal_force
        return jnp.sqrt(self.sigma0 / meff)  # the undamped bristle mode


class LuGre(AbstractFrictionLaw):
    r"""LuGre bristle friction, paper section 3.3, Fig. 16:

    $$F_{nl} = \sigma_0 z + \sigma_1 \dot z + \sigma_2 \dot X,\qquad
    \dot z = \dot X - \frac{\sigma_0|\dot X|}{g(\dot X)} z,\qquad
    g(v) = F_c + (F_s - F_c)e^{-(v/v_s)^2},$$

    with ``F_c = μc N`` and ``F_s = μs N``.  Canudas de Wit, Olsson, Åström & Lischinsky,
    *IEEE TAC* 40 (1995) 419.  Steady sliding gives ``g(v) sign(v) + σ2 v``.

    **Arguments**

    - ``mu_c``, ``mu_s``: kinetic and static coefficients (Table 5: 0.5, 0.6).
    - ``v_s``: Stribeck velocity [m/s] (Table 5 prints 1e4).
    - ``sigma0``: bristle stiffness [N/m] (1e4); ``sigma1``: bristle damping [N s/m] (1e2);
      ``sigma2``: viscous (lubrication) damping [N s/m] (0).
    - ``eps``: ``0`` (default): ``|Ẋ|`` exactly, and ``|z| <= F_s/σ0`` holds; ``eps > 0``:
      smoothed as ``Ẋ tanh(Ẋ/eps)`` [m/s] (as [`Dahl`][absorber_jax.Dahl]; with σ0 = 1e8 and eps =
      1e-4 the smoothed law sticks through a whole period holding 5 N against ``F_s`` = 1.2 N).

    ```python
    law = LuGre(mu_c=0.5, mu_s=0.6, v_s=1e-2, sigma0=1e4, sigma1=1e2, sigma2=0.0)
    law.steady_force(1.0, 10.0)  # -> 5.0 N
    ```
    """

    num_states: ClassVar[int] = 1
    exact: ClassVar[bool] = False
    mu_c: object = eqx.field(converter=as_float)
    mu_s: object = eqx.field(converter=as_float)
    v_s: object = eqx.field(converter=as_float)
    sigma0: object = eqx.field(converter=as_float)
    sigma1: object = eqx.field(converter=as_float)
    sigma2: object = eqx.field(converter=as_float, default=0.0)
    eps: object = eqx.field(converter=as_float, default=0.0)

    def __check_init__(self):
        nonnegative("LuGre", "mu_c", self.mu_c)
        check_scalar(
            "LuGre", "mu_s", self.mu_s, lo=float(self.mu_c) if not is_traced(self.mu_c) else None
        )
        positive("LuGre", "v_s", self.v_s)
        positive("LuGre", "sigma0", self.sigma0)
        nonnegative("LuGre", "sigma1", self.sigma1)
        nonnegative("LuGre", "sigma2", self.sigma2)
        nonnegative("LuGre", "eps", self.eps)

    def g(self, v, normal_force):
        lvl = normal_force * (self.mu_c + (self.mu_s - self.mu_c) * jnp.exp(-((v / self.v_s) ** 2)))
        return jnp.maximum(lvl, 1e-300)

    def state_rate(self, v, z, normal_force):
        return _bristle_rate(v, z, self.sigma0, self.eps, self.g(v, normal_force))

    def force(self, v, z, normal_force):
        zdot = self.state_rate(v, z, normal_force)[0]
        return self.sigma0 * z[0] + self.sigma1 * zdot + self.sigma2 * v

    def stored_energy(self, z):
        return 0.5 * self.sigma0 * z[0] ** 2

    def kinetic_level(self, normal_force):
        return self.mu_c * normal_force

    def state_scale(self, normal_force):
        # bristle deflection: its natural size is the saturation value μc N / σ0
        return jnp.stack([jnp.maximum(self.mu_c * normal_force / self.sigma0, 1e-15)])

    def dissipated_power(self, v, z, normal_force):
        zdot = self.state_rate(v, z, normal_force)[0]
        return self.force(v, z, normal_force) * v - self.sigma0 * z[0] * zdot

    def steady_force(self, v, normal_force):
        return self.g(v, normal_force) * jnp.sign(v) + self.sigma2 * v

    def is_sliding(self, v, z, normal_force):
        f = self.sigma0 * z[0]
        return (jnp.abs(f) > 0.5 * self.g(v, normal_force)) & (f * v > 0)

    def stiffness_rate(self, normal_force, meff):
        # bristle vibration and damping, and the relaxation rate σ0|v|/g of z while sliding
        fc = jnp.maximum(self.mu_c * normal_force, 1e-300)
        return jnp.maximum(
            jnp.maximum(jnp.sqrt(self.sigma0 / meff), (self.sigma1 + self.sigma2) / meff),
            self.sigma0 * BRISTLE_SLIDING_SPEED / fc,
        )

    def oscillation_rate(self, normal_force, meff):
        del normal_force
        return jnp.sqrt(self.sigma0 / meff)  # the bristle mode, damped by σ1 only


FRICTION_LAWS = {"coulomb": Coulomb, "stribeck": Stribeck, "dahl": Dahl, "lugre": LuGre}
