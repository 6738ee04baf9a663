"""Primary + absorber systems.

Both systems share one vector field, composed as *linear primary structure + coupling*:
the primary (mass, spring, dashpot to ground, forced) and an absorber mass joined to it by
a coupling force.  The coupling is the contact law at the two walls of a clearance
(``ImpactAbsorber``) or a spring, dashpot and friction law (``FrictionAbsorber``).

Internal state (what the integrator sees): ``[x1, v1, u, w, *z]`` with the absorber's motion
*relative* to the primary, ``u = x2 - x1`` and ``w = v2 - v1`` (accurate near contact and
during sticking), then the friction law's internal states ``z`` (Dahl, LuGre only).
Public state (``y0``, trajectories): absolute ``[x1, v1, x2, v2, *z]``.
"""

from __future__ import annotations

import abc
import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp

from .._core import units
from .._core.checks import as_float, nonnegative, positive
from .._laws.contact import AbstractContactLaw
from .._laws.friction import AbstractFrictionLaw
from .._laws.restitution import RIGID_STEPS_PER_PERIOD
from .base import AbstractHybridSystem, not_linear
from .linear import _internal, finite_or_zero, harmonic_response, state_at_zero, two_mass_matrices

# a rigid-impact absorber counts as stuck at a wall at the start of an integration when
# within this fraction of the gap of it and slower than this fraction of the velocity scale
STICK_TOLERANCE = 1e-9


def regime(ts, sliding, period):
    """Regime per instant from the fraction of the forcing period ending there spent in gross
    sliding: < 2 % jammed (0), > 80 % totally gliding (2), else partially gliding (1)."""
    frac_cum = jnp.concatenate([jnp.zeros(1), jnp.cumsum(sliding.astype(ts.dtype))])
    j = jnp.searchsorted(ts, ts - period, side="right")
    i = jnp.arange(ts.shape[0]) + 1
    frac = (frac_cum[i] - frac_cum[j]) / jnp.maximum(i - j, 1)
    return jnp.where(frac < 0.02, 0, jnp.where(frac > 0.8, 2, 1))


class AbstractAbsorberSystem(AbstractHybridSystem):
    """A forced linear primary carrying one absorber through a nonlinear coupling
    (outputs ``x1``, ``x2``; observable ``x1``; stroke ``x2 - x1``)."""

    @property
    @abc.abstractmethod
    def primary(self):
        """``(mass, stiffness, damping)`` of the primary."""

    @property
    @abc.abstractmethod
    def absorber_mass(self):
        """Mass of the absorber [kg]."""

    @property
    @abc.abstractmethod
    def num_law_states(self) -> int:
        """Internal states of the coupling law (bristle deflections; 0 when none)."""

    @property
    def num_states(self) -> int:
        return 4 + self.num_law_states

    @property
    def linear(self) -> bool:
        return False            # a contact or friction law couples the two masses

    def harmonic_response(self, forcing):
        raise not_linear(self)

    def prepared(self):
        return self     # two masses: nothing worth computing ahead

    @abc.abstractmethod
    def coupling(self, u, w, z):
        """``(force on the primary from the absorber [N], dz/dt)`` for relative motion
        ``u = x2 - x1``, ``w = v2 - v1`` and law state ``z``."""

    @abc.abstractmethod
    def coupling_potential(self, u, z):
        """Elastic energy [J] stored in the coupling (exact, nonsmooth expression)."""

    @abc.abstractmethod
    def coupling_dissipation(self, u, w, z):
        """Power [W] dissipated in the coupling."""

    @abc.abstractmethod
    def stiffness_rate(self):
        """Rough largest rate [1/s] of the linearised dynamics (solver choice)."""

    @abc.abstractmethod
    def linear_guess(self, forcing):
        """A starting orbit for shooting from the linear limits of the scene (internal
        state at ``t = 0``)."""

    @abc.abstractmethod
    def length_floor(self):
        """Smallest natural length [m] of the motion (the clearance of an impact absorber)."""

    @abc.abstractmethod
    def law_state_scale(self):
        """Natural size of the law's internal states (empty when it has none)."""

    @property
    def state_names(self) -> tuple:
        return ("x1", "v1", "x2", "v2") + tuple(f"z{i + 1}" for i in range(self.num_law_states))

    @property
    def output_names(self) -> tuple:
        return ("x1", "x2")

    def outputs(self, s):
        return jnp.stack([s[0], s[0] + s[2]])

    def observable(self, s):
        return s[0]

    def strokes(self, s):
        return s[2:3]

    def floating_pairs(self, stroke_max):
        return self.floats(stroke_max[0]).astype(int)

    @abc.abstractmethod
    def aliases(self) -> dict:
        """Parameter names of the paper mapped to field paths."""

    def parameter_path(self, name: str) -> str:
        return self.aliases().get(name, name)

    def parameter_names(self) -> list:
        names = [f.name for f in dataclasses.fields(self)
                 if f.init and f.name not in ("contact", "friction")]
        return names + list(self.aliases())

    @abc.abstractmethod
    def floats(self, u_max):
        """True when, on an orbit whose relative motion stays within ``|u| <= u_max``, the
        absorber's position is free (a structural Floquet multiplier 1, not a loss of
        stability)."""

    def condensation(self):
        return None     # the coupling acts on the relative coordinate, not a structure's DOF

    @property
    def force_names(self) -> tuple:
        return ()

    def signals(self):
        return units.generic_signals(self)

    def state_scale(self, forcing):
        """Per-component scale of the internal state, ``[L, Lω, L, Lω, z...]`` with
        ``L = F0 / (k + M ω²)`` (at least ``length_floor``): the integrator and the Newton
        tolerances of the steady-state layer work on the state divided by it."""
        M, k, _ = self.primary
        w = forcing.omega
        L = jnp.maximum(jnp.maximum(forcing.amplitude / (k + M * w**2), self.length_floor()),
                        1e-12)
        scale = L * jnp.stack([1.0, w, 1.0, w])
        return jnp.concatenate([scale, self.law_state_scale()])

    # -- state conversions ---------------------------------------------------------
    def to_internal(self, y):
        y = jnp.asarray(y)
        rel = jnp.stack([y[0], y[1], y[2] - y[0], y[3] - y[1]])
        return jnp.concatenate([rel, y[4:]])

    def to_public(self, s):
        s = jnp.asarray(s)
        ab = jnp.stack(
            [s[..., 0], s[..., 1], s[..., 0] + s[..., 2], s[..., 1] + s[..., 3]], axis=-1
        )
        return jnp.concatenate([ab, s[..., 4:]], axis=-1)

    def rest_state(self):
        """Internal state at rest (the absorber centred, bristles undeflected)."""
        return jnp.zeros((self.num_states,), dtype=jnp.result_type(float))

    # -- dynamics --------------------------------------------------------------------
    def accelerations(self, t, s, forcing):
        M, k, c = self.primary
        if self.hybrid:
            fp, zdot = self.mode_coupling(t, s, forcing, self.mode_of(t, s, forcing))
        else:
            fp, zdot = self.coupling(s[2], s[3], s[4:])
        a1 = (forcing(t) - c * s[1] - k * s[0] + fp) / M
        a2 = -fp / self.absorber_mass
        return a1, a2, fp, zdot

    def vector_field(self, t, s, forcing):
        """d/dt of the internal state ``s`` under ``forcing``."""
        a1, a2, _, zdot = self.accelerations(t, s, forcing)
        return jnp.concatenate([jnp.stack([s[1], a1, s[3], a2 - a1]), zdot])

    @abc.abstractmethod
    def mode_coupling(self, t, s, forcing, mode):
        """``coupling`` of the hybrid system in a given mode (called only where ``hybrid``)."""

    def mechanical_energy(self, s):
        """Kinetic + potential energy [J] of internal state ``s`` (exact contact potential)."""
        M, k, _ = self.primary
        v2 = s[1] + s[3]
        return (
            0.5 * M * s[1] ** 2
            + 0.5 * self.absorber_mass * v2**2
            + 0.5 * k * s[0] ** 2
            + self.coupling_potential(s[2], s[4:])
        )

    def power(self, t, s, forcing):
        """``(input power of the forcing, dissipated power)`` [W]."""
        _, _, c = self.primary
        return forcing(t) * s[1], c * s[1] ** 2 + self.coupling_dissipation(s[2], s[3], s[4:])


class ImpactAbsorber(AbstractAbsorberSystem):
    r"""Impact absorber (paper section 2; the equations, laws and the paper's Tables 1–3 are on
    the Mechanics page of the documentation).

    A primary ``M, k, c`` forced by ``F(t)`` carries an absorber mass ``m`` that moves freely
    in a cavity with clearance ``gap`` on each side.  With ``y = x2 - x1``,
    ``δ± = max(0, ±y - d)`` and ``Fc = f(δ+, ẏ) - f(δ-, -ẏ)``:

    $$M\ddot x_1 + c\dot x_1 + kx_1 = F_c + F(t),\qquad m\ddot x_2 = -F_c .$$

    **Arguments**

    - ``M``: primary mass [kg] (1); ``k``: primary stiffness [N/m] (1e3); ``c``: primary
      damping [N s/m] (0.1).
    - ``m``: absorber mass [kg] (0.4).
    - ``gap``: clearance ``d`` on each side [m] (the paper gives none; our default 1e-3).
    - ``contact``: a [`KelvinVoigt`][absorber_jax.KelvinVoigt], [`Hertz`][absorber_jax.Hertz] or
      [`HuntCrossley`][absorber_jax.HuntCrossley] law.

    ```python
    sys = ImpactAbsorber(M=1.0, k=1e3, c=0.1, m=0.4, gap=1e-3,
                         contact=KelvinVoigt(stiffness=400.0, damping=20.0))
    ```
    """

    M: object = eqx.field(converter=as_float)
    k: object = eqx.field(converter=as_float)
    c: object = eqx.field(converter=as_float)
    m: object = eqx.field(converter=as_float)
    gap: object = eqx.field(converter=as_float)
    contact: AbstractContactLaw

    def __check_init__(self):
        positive("ImpactAbsorber", "M", self.M)
        nonnegative("ImpactAbsorber", "k", self.k)
        nonnegative("ImpactAbsorber", "c", self.c)
        positive("ImpactAbsorber", "m", self.m)
        nonnegative("ImpactAbsorber", "gap", self.gap)
        if not isinstance(self.contact, AbstractContactLaw):
            raise ValueError(
                "ImpactAbsorber.contact must be a contact law (KelvinVoigt, Hertz, "
                f"HuntCrossley or Restitution), got {type(self.contact).__name__}"
            )
        if self.contact.exact:
            positive("ImpactAbsorber (rigid impacts: Restitution)", "gap", self.gap)

    @property
    def primary(self):
        return self.M, self.k, self.c

    @property
    def absorber_mass(self):
        return self.m

    def penetrations(self, s):
        """``(u - gap, -u - gap)`` with ``u = x2 - x1``: the right and left walls [m]."""
        return self.contact.clearance_penetrations(s[2], self.gap)

    def coupling(self, u, w, z):
        return (self.contact.clearance_force(u, w, self.gap),
                jnp.zeros((0,), dtype=jnp.result_type(u)))

    def coupling_potential(self, u, z):
        return self.contact.clearance_energy(u, self.gap)

    def coupling_dissipation(self, u, w, z):
        return self.contact.clearance_dissipation(u, w, self.gap)

    def length_floor(self):
        return self.gap

    @property
    def num_law_states(self) -> int:
        return 0

    def law_state_scale(self):
        return jnp.zeros((0,))

    def oscillation_rate(self):
        return jnp.zeros(())    # the contact adds no lightly damped fast mode of its own

    def trajectory_fields(self, ts, s, forcing):
        _, _, fp, _ = jax.vmap(lambda t, si: self.accelerations(t, si, forcing))(ts, s)
        return {"coupling_force": fp}

    def aliases(self) -> dict:
        if self.contact.exact:
            return {"e": "contact.e"}
        return {"k1": "contact.stiffness", "kHz": "contact.stiffness",
                "c1": "contact.damping", "eps": "contact.eps"}

    def floats(self, u_max):
        # never touching a wall: its free position and velocity give a structural double
        # multiplier 1 (a Jordan block, split by ~sqrt(rounding) numerically)
        return u_max < self.gap

    def linear_guess(self, forcing):
        """The primary alone with the absorber floating at rest in the middle of the cavity
        if that motion stays inside the clearance (always, for rigid impacts), else the
        tuned-mass damper with the contact law's secant stiffness and damping at a
        penetration of the gap's size."""
        F0, w = forcing.amplitude, forcing.omega
        X1 = F0 / (self.k - w**2 * self.M + 1j * w * self.c)
        zero = jnp.zeros(())
        free = _internal(jnp.stack([jnp.imag(X1), zero]), jnp.stack([w * jnp.real(X1), zero]))
        if self.contact.exact:
            return finite_or_zero(free)
        d = jnp.maximum(self.gap, 1e-3)
        k_c = self.contact.elastic_force(d) / d
        c_c = self.contact.viscous_force(d, 1.0)
        Q = harmonic_response(*two_mass_matrices(self.M, self.m, self.k, self.c, k_c, c_c),
                              jnp.array([1.0, 0.0]), F0, w)
        tmd = _internal(*state_at_zero(Q, w))
        return finite_or_zero(jnp.where(jnp.abs(X1) < self.gap, free, tmd))

    def stiffness_rate(self):
        meff = self.M * self.m / (self.M + self.m)
        structural = jnp.maximum(jnp.sqrt(self.k / self.M), self.c / self.M)
        return jnp.maximum(
            structural, self.contact.stiffness_rate(meff, jnp.maximum(self.gap, 1e-3))
        )

    # -- rigid impacts (contact.exact, Restitution): modes 0 free flight, +1 / -1 stuck at
    # the right / left wall (see absorber_jax._laws.restitution) --------------------------
    @property
    def hybrid(self) -> bool:
        return self.contact.exact

    @property
    def affine_modes(self) -> bool:
        # a linear primary; the absorber flies free or is held against a wall
        return self.contact.exact

    def _free_acceleration(self, t, s, forcing):
        """The primary's acceleration [m/s²] with the absorber flying free (the absorber's
        acceleration relative to it is minus this)."""
        return (forcing(t) - self.c * s[1] - self.k * s[0]) / self.M

    def _together_acceleration(self, t, s, forcing):
        """The common acceleration [m/s²] of primary and absorber stuck together."""
        return (forcing(t) - self.c * s[1] - self.k * s[0]) / (self.M + self.m)

    def _references(self, forcing):
        """Velocity [m/s] and force [N] scales of the forced pair (switching functions
        and tolerances are relative to them): the state's velocity scale ``Lω``, and the
        force ``F0 m/(M+m)`` that holds the absorber to the forced pair."""
        f_ref = forcing.amplitude * self.m / (self.M + self.m)
        return self.state_scale(forcing)[3], jnp.maximum(f_ref, 1e-300)

    def mode_of(self, t, s, forcing):
        u, w = s[2], s[3]
        side = jnp.where(u >= 0, 1, -1)
        v_ref, _ = self._references(forcing)
        at_wall = jnp.abs(u) >= self.gap * (1.0 - STICK_TOLERANCE)
        slow = jnp.abs(w) <= STICK_TOLERANCE * v_ref
        # pressed: the free relative acceleration (-a1) points into that wall
        pressed = -side * self._free_acceleration(t, s, forcing) > 0
        return jnp.where(at_wall & slow & pressed, side, 0)

    def mode_coupling(self, t, s, forcing, mode):
        # stuck: the absorber moves with the primary, held by the force fp = -m a on it
        fp = jnp.where(mode == 0, 0.0, -self.m * self._together_acceleration(t, s, forcing))
        return fp, jnp.zeros((0,), dtype=jnp.result_type(s))

    def mode_rate(self, t, s, forcing, mode):
        free = mode == 0
        a = jnp.where(free, self._free_acceleration(t, s, forcing),
                      self._together_acceleration(t, s, forcing))
        return jnp.stack([s[1], a, jnp.where(free, s[3], 0.0), jnp.where(free, -a, 0.0)])

    def switch_function(self, t, s, forcing, mode):
        # free flight: the nearer wall's penetration over the gap; stuck: the wall's pull
        # (tensile holding force, -mode·(-m a) < 0 while it pushes) over the force scale
        _, f_ref = self._references(forcing)
        # the nearer wall's penetration: |u| - gap (not a max over the walls: jnp.max's
        # derivative divides by the count of ties, which gives NaN tangents in the lanes
        # of a vmapped event location that hold no event)
        pen = jnp.abs(s[2]) / self.gap - 1.0
        pull = mode * self.m * self._together_acceleration(t, s, forcing) / f_ref
        return jnp.where(mode == 0, pen, pull)

    def next_mode(self, t, s, forcing, mode):
        # free -> an impact at the wall on the side of u: Newton's law with momentum
        # conserved, then sticking where the Zeno sequence settles (Restitution.settles);
        # stuck -> free flight from rest against the wall
        side = jnp.where(s[2] >= 0, 1.0, -1.0)
        w = s[3]
        meff = self.M * self.m / (self.M + self.m)
        impulse = self.contact.impulse(w, meff)      # on the absorber: -impulse
        v1 = s[1] + impulse / self.M
        w_after = w - impulse / meff                 # = -e w
        hit = jnp.stack([s[0], v1, side * self.gap, w_after])
        a_rel = -self._free_acceleration(t, hit, forcing)
        pressed = side * a_rel > 0
        # the motion's length scale (at least the gap: length_floor)
        length = self.state_scale(forcing)[0]
        stick = pressed & self.contact.settles(w_after, a_rel, forcing.period, length)
        # a plastic end of the sequence: both share the momentum's velocity
        v_common = s[1] + self.m * w / (self.M + self.m)
        stuck = jnp.stack([s[0], v_common, side * self.gap, jnp.zeros_like(w)])
        after_impact = jnp.where(stick, stuck, hit)
        new = jnp.where(mode == 0, jnp.where(stick, side, 0.0), 0.0).astype(int)
        return new, jnp.where(mode == 0, after_impact, s)

    def event_step_limit(self, forcing):
        # rigid walls: an excursion missed within one step is at most ~(ωh)²/8 of the
        # motion's length deep (h = T / RIGID_STEPS_PER_PERIOD: ~7.5e-5 at 256)
        return forcing.period / RIGID_STEPS_PER_PERIOD if self.contact.exact else None

    def admissible_state(self, t, s, forcing):
        """A start beyond a wall (a Newton iterate of shooting) moving into it is the state
        after the impact it went through, to first order: back along the free flight to the
        wall, Newton's law, then forward again for the same time (continuous and smooth to
        first order where it joins the states inside the clearance).  One moving out of
        the wall is put back on it."""
        u, w = s[2], s[3]
        side = jnp.where(u >= 0, 1.0, -1.0)
        pen = jnp.abs(u) - self.gap
        entering = side * w > 0
        dt = jnp.where((pen > 0) & entering, pen / jnp.where(entering, jnp.abs(w), 1.0), 0.0)
        at_wall = s - self.mode_rate(t, s, forcing, 0) * dt
        mode, after = self.next_mode(t, at_wall, forcing, jnp.zeros((), int))
        through = after + self.mode_rate(t, after, forcing, mode) * dt
        on_wall = s.at[2].set(side * self.gap)
        return jnp.where(pen > 0, jnp.where(entering, through, on_wall), s)

    def event_is_impact(self, t, s, forcing, mode):
        # an event in free flight approaching the wall (not the rounding about a wall just
        # left from rest, at zero relative velocity)
        v_ref, _ = self._references(forcing)
        side = jnp.where(s[2] >= 0, 1.0, -1.0)
        return (mode == 0) & (side * s[3] > STICK_TOLERANCE * v_ref)

    def in_contact(self, mode):
        return mode != 0


class FrictionAbsorber(AbstractAbsorberSystem):
    r"""Friction absorber (paper section 3; the equations below are written out from the two
    masses' Newton equations, the printed ones being garbled: see the Mechanics page of the
    documentation).

    A primary ``m1, k1, c1`` forced by ``F(t)`` carries an absorber ``m2`` tied to it by
    ``k2, c2`` and sliding on it under the normal force ``N``.  With ``X = x1 - x2``:

    $$m_1\ddot x_1 + c_1\dot x_1 + k_1x_1 + c_2\dot X + k_2X + F_{nl} = F(t),\qquad
    m_2\ddot x_2 - c_2\dot X - k_2X - F_{nl} = 0 .$$

    **Arguments**

    - ``m1``, ``k1``, ``c1``: primary mass [kg], stiffness [N/m], damping [N s/m]
      (Tables 4–5: 1, 1e4, 0; ``c1`` default 0).
    - ``m2``, ``k2``, ``c2``: absorber mass, tie stiffness and damping (1, 1e4, 0);
      ``c2`` default 0 (keyword only, as ``c1``).
    - ``normal_force``: ``N`` [N] (the paper gives none; see
      [`absorber_jax.presets`][absorber_jax.presets]).
    - ``friction``: a [`Coulomb`][absorber_jax.Coulomb], [`Stribeck`][absorber_jax.Stribeck],
      [`Dahl`][absorber_jax.Dahl] or [`LuGre`][absorber_jax.LuGre] law.

    ```python
    sys = FrictionAbsorber(m1=1.0, k1=1e4, c1=0.0, m2=1.0, k2=1e4, c2=0.0,
                           normal_force=10.0, friction=Coulomb(mu=0.5))
    ```
    """

    m1: object = eqx.field(converter=as_float)
    k1: object = eqx.field(converter=as_float)
    c1: object = eqx.field(converter=as_float, default=0.0, kw_only=True)
    m2: object = eqx.field(converter=as_float)
    k2: object = eqx.field(converter=as_float)
    c2: object = eqx.field(converter=as_float, default=0.0, kw_only=True)
    normal_force: object = eqx.field(converter=as_float)
    friction: AbstractFrictionLaw

    def __check_init__(self):
        positive("FrictionAbsorber", "m1", self.m1)
        nonnegative("FrictionAbsorber", "k1", self.k1)
        nonnegative("FrictionAbsorber", "c1", self.c1)
        positive("FrictionAbsorber", "m2", self.m2)
        nonnegative("FrictionAbsorber", "k2", self.k2)
        nonnegative("FrictionAbsorber", "c2", self.c2)
        nonnegative("FrictionAbsorber", "normal_force", self.normal_force)
        if not isinstance(self.friction, AbstractFrictionLaw):
            raise ValueError(
                "FrictionAbsorber.friction must be a friction law (Coulomb, "
                f"Stribeck, Dahl or LuGre), got {type(self.friction).__name__}"
            )

    @property
    def primary(self):
        return self.m1, self.k1, self.c1

    @property
    def absorber_mass(self):
        return self.m2

    @property
    def num_law_states(self) -> int:
        return self.friction.num_states

    def length_floor(self):
        return jnp.zeros(())

    def floats(self, u_max):
        return jnp.zeros((), bool)      # its spring k2 ties it to the primary

    def penetrations(self, s):
        return jnp.zeros((0,), dtype=jnp.result_type(s))

    def aliases(self) -> dict:
        law = {f.name: "friction." + f.name for f in dataclasses.fields(self.friction)
               if f.init}
        return {"N": "normal_force", **law}

    def trajectory_fields(self, ts, s, forcing):
        a1, a2, fp, _ = jax.vmap(lambda t, si: self.accelerations(t, si, forcing))(ts, s)
        u, w, z = s[:, 2], s[:, 3], s[:, 4:]
        fnl = jax.vmap(self.friction_force)(u, w, z)
        fa = self.m2 * (a1 - a2)
        tiny = 1e-12 * jnp.maximum(self.normal_force, 1e-300)
        sliding = jax.vmap(self.is_sliding)(u, w, z)
        return dict(coupling_force=fp, friction_force=fnl,
                    force_ratio=jnp.abs(fa) / jnp.maximum(jnp.abs(fnl), tiny),
                    sliding=sliding, regime=regime(ts, sliding, forcing.period))

    def friction_force(self, u, w, z):
        """``Fnl`` [N] (positive drags the absorber along with the primary)."""
        return self.friction.force(-w, z, self.normal_force)

    def coupling(self, u, w, z):
        X, V = -u, -w
        fnl = self.friction.force(V, z, self.normal_force)
        zdot = self.friction.state_rate(V, z, self.normal_force)
        return -(self.c2 * V + self.k2 * X + fnl), zdot

    def coupling_potential(self, u, z):
        return 0.5 * self.k2 * u**2 + self.friction.stored_energy(z)

    def coupling_dissipation(self, u, w, z):
        return self.c2 * w**2 + self.friction.dissipated_power(-w, z, self.normal_force)

    def is_sliding(self, u, w, z):
        return self.friction.is_sliding(-w, z, self.normal_force)

    # -- exact stick–slip (friction.exact): modes 0 stick, +1 / -1 slip with sign(Ẋ) ----
    @property
    def hybrid(self) -> bool:
        return self.friction.exact

    @property
    def affine_modes(self) -> bool:
        # kept on the general integrator (the slip modes' friction laws may be nonlinear
        # in the sliding velocity)
        return False

    def holding_force(self, t, s, forcing):
        """Friction force ``Fnl`` [N] that keeps the absorber stuck (``Ẋ = 0``): both masses
        then share the acceleration ``a = (F - c1 v1 - k1 x1) / (m1 + m2)`` and
        ``Fnl = m2 a - k2 X`` with ``X = x1 - x2 = -u``."""
        a = (forcing(t) - self.c1 * s[1] - self.k1 * s[0]) / (self.m1 + self.m2)
        return self.m2 * a + self.k2 * s[2]

    def _holding_mode(self, t, s, forcing):
        f = self.holding_force(t, s, forcing)
        stuck = jnp.abs(f) <= self.friction.breakaway_force(self.normal_force)
        return jnp.where(stuck, 0, jnp.where(f > 0, 1, -1))

    def mode_of(self, t, s, forcing):
        V = -s[3]
        return jnp.where(V > 0, 1, jnp.where(V < 0, -1, self._holding_mode(t, s, forcing)))

    def mode_coupling(self, t, s, forcing, mode):
        V, X = -s[3], -s[2]
        slip = mode * self.friction.kinetic_force(jnp.abs(V), self.normal_force)
        fnl = jnp.where(mode == 0, self.holding_force(t, s, forcing), slip)
        return -(self.c2 * V + self.k2 * X + fnl), jnp.zeros((0,), dtype=jnp.result_type(V))

    def mode_rate(self, t, s, forcing, mode):
        M, k, c = self.primary
        fp, _ = self.mode_coupling(t, s, forcing, mode)
        a1 = (forcing(t) - c * s[1] - k * s[0] + fp) / M
        a2 = -fp / self.m2
        stuck = mode == 0
        # stuck: the relative state is frozen exactly (both masses share a1)
        return jnp.stack([s[1], a1, jnp.where(stuck, 0.0, s[3]),
                          jnp.where(stuck, 0.0, a2 - a1)])

    def switch_function(self, t, s, forcing, mode):
        # stick: holding force over the breakaway limit; slip: Ẋ reversing.  Both are made
        # dimensionless (by the limit plus the holding-force scale F0 m2 / (m1 + m2) of the
        # forced pair, never zero even at N = 0, and by the velocity scale F0 ω / (k1 + m1 ω²)
        # of the forced primary), homogeneous of degree 0 in (F0, N): the event root
        # finder's tolerance then means the same for every scale of motion
        cap = self.friction.breakaway_force(self.normal_force)
        f = self.holding_force(t, s, forcing)
        w = forcing.omega
        f_ref = cap + forcing.amplitude * self.m2 / (self.m1 + self.m2)
        v_ref = forcing.amplitude * w / (self.k1 + self.m1 * w**2)
        return jnp.where(mode == 0, (jnp.abs(f) - cap) / jnp.maximum(f_ref, 1e-300),
                         mode * s[3] / jnp.maximum(v_ref, 1e-30))

    def next_mode(self, t, s, forcing, mode):
        # slip ending (Ẋ = 0): the relative velocity is exactly zero from here on; stick or
        # slip back the other way by the holding force.  Stick ending: slip in the
        # direction of the holding force (never back to stick: it is at the limit).
        s = s.at[3].set(jnp.where(mode == 0, s[3], 0.0))
        f = self.holding_force(t, s, forcing)
        new = jnp.where(mode == 0, jnp.where(f > 0, 1, -1), self._holding_mode(t, s, forcing))
        return new, s

    def event_step_limit(self, forcing):
        return None     # stick–slip switches change sign cleanly: no grazing excursions

    def admissible_state(self, t, s, forcing):
        return s        # every state is one of a stick or slip mode

    def event_is_impact(self, t, s, forcing, mode):
        return jnp.zeros((), bool)

    def in_contact(self, mode):
        return jnp.zeros((), bool)

    def law_state_scale(self):
        return self.friction.state_scale(self.normal_force)

    def linear_guess(self, forcing):
        """The two masses stuck together if the friction force needed stays below the
        kinetic level of the law, else the absorber sliding freely (N = 0)."""
        F0, w = forcing.amplitude, forcing.omega
        Xs = F0 / (self.k1 - w**2 * (self.m1 + self.m2) + 1j * w * self.c1)
        stuck = _internal(jnp.stack([jnp.imag(Xs)] * 2), jnp.stack([w * jnp.real(Xs)] * 2))
        need = self.m2 * w**2 * jnp.abs(Xs)  # friction force that keeps the absorber stuck
        Q = harmonic_response(*two_mass_matrices(self.m1, self.m2, self.k1, self.c1, self.k2,
                                                 self.c2), jnp.array([1.0, 0.0]), F0, w)
        free = _internal(*state_at_zero(Q, w))
        base = jnp.where(need <= self.friction.kinetic_level(self.normal_force), stuck, free)
        z0 = jnp.zeros((self.num_law_states,), base.dtype)
        return finite_or_zero(jnp.concatenate([base, z0]))

    def stiffness_rate(self):
        meff = self.m1 * self.m2 / (self.m1 + self.m2)
        structural = jnp.maximum(jnp.sqrt((self.k1 + self.k2) / meff), (self.c1 + self.c2) / meff)
        return jnp.maximum(structural, self.friction.stiffness_rate(self.normal_force, meff))

    def oscillation_rate(self):
        meff = self.m1 * self.m2 / (self.m1 + self.m2)
        return self.friction.oscillation_rate(self.normal_force, meff)
