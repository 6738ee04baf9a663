"""Elements attached to a ``LinearStructure``: absorbers that bring a mass of their own,
and connections between two degrees of freedom or one and ground.

Each element reads the displacements and velocities of the degrees of freedom it touches,
``x = (x_a, x_b)`` and ``v = (v_a, v_b)`` (``x_b = v_b = 0`` when ``other`` is ground), and
returns the forces ``(f_a, f_b)`` [N] it applies to them; an element with states of its own
(an absorber's motion relative to its host ``u = x_abs - x_a``, ``w = u̇``; a bristle
deflection ``z``) also gives their rates once the accelerations ``a = (a_a, a_b)`` of its
degrees of freedom are known.  Generic code (``_systems.structural``) talks to these members
only.

Displacements and velocities are those of the structure's model: relative to the support
under a base excitation (ground is the moving support then), while the accelerations ``a``
given to ``AbstractElement.state_rate`` are absolute (the support's acceleration
included), so that an element's own mass feels its inertial load.

The classes:

- ``AbstractElement``: any element (write your own by subclassing it: a cubic spring
  needs ``evaluate`` and ``energy``);
- ``AbstractAbsorber``: a mass riding on one degree of freedom through a coupling force
  (write your own by giving ``coupling``, ``coupling_energy``, ``coupling_dissipation``);
- ``ImpactDamper``: a mass in a clearance (any contact law) at one degree of freedom;
- ``FrictionDamper``: a mass tied by a spring and dashpot, sliding under a normal force
  (any smoothed or bristle friction law, or the exact stick–slip one) at one degree of
  freedom;
- ``TunedMassDamper``: a mass on a spring and dashpot (linear);
- ``Contact``: a one- or two-sided contact with a gap between a degree of freedom and
  ground or another degree of freedom (any contact law);
- ``FrictionContact``: a friction contact between a degree of freedom and ground or
  another one (any smoothed or bristle friction law).

Units: SI; on a rotational degree of freedom forces are moments [N m] and lengths [rad].
"""

# (no ``from __future__ import annotations`` here: equinox reads ``AbstractVar`` only from
# evaluated annotations; as strings they would become required dataclass fields of the
# abstract classes, ordered before the concrete classes' own)
import abc
import dataclasses
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from .._core import units
from .._core.checks import as_float, nonnegative, positive
from .._laws.contact import AbstractContactLaw
from .._laws.friction import AbstractFrictionLaw


def _zeros(n, like):
    return jnp.zeros((n,), dtype=jnp.result_type(like, float))


class AbstractElement(eqx.Module):
    r"""An element attached to a [`LinearStructure`][absorber_jax.LinearStructure] in a
    [`StructuralSystem`][absorber_jax.StructuralSystem]: the base class of the absorbers,
    tuned mass dampers and contacts, and of your own elements.

    An element reads the displacements and velocities of the degrees of freedom it touches,
    ``x = (x_a, x_b)`` and ``v = (v_a, v_b)`` (``x_b = v_b = 0`` when ``other`` is ground),
    and returns the forces ``(f_a, f_b)`` [N] it applies to them; an element with states of
    its own (an absorber's motion relative to its host, a bristle deflection) also gives
    their rates once the accelerations ``a = (a_a, a_b)`` of its degrees of freedom are
    known.  Displacements and velocities are relative to the support under a base
    excitation, while the accelerations given to ``state_rate`` are absolute, so that an
    element's own mass feels its inertial load.  Units: SI; on a rotational degree of
    freedom forces are moments [N m] and lengths [rad].

    **Fields a concrete element declares**

    - ``dof``: the degree of freedom it acts on (name or index), a static field:
      ``dof: str = eqx.field(static=True)``.
    - ``other``: the second degree of freedom, or ``None`` for ground (the support):
      ``other: str | None = eqx.field(static=True, default=None)``.
    - ``name``: its name in parameter paths (``<name>.<field>``) and outputs, or ``None`` for
      ``<kind><count>``: ``name: str | None = eqx.field(static=True, default=None)``.
    - ``kind``: a class variable, the stem of default names (default ``"element"``).

    Its other fields are its parameters (``<name>.<field>`` in
    [`replace_params`][absorber_jax.replace_params], sweeps and ``tune``).

    **Methods it must define**

    - ``evaluate(x, v, z) -> (forces, aux)``: ``x``, ``v``: displacements [m] and velocities
      [m/s] of ``(dof, other)``, shape ``(2,)`` (ground reads 0); ``z``: its own states,
      shape ``(num_states,)``.  ``forces``: the forces [N] it applies to ``(dof, other)``,
      shape ``(2,)`` (the second is ignored for ground); ``aux``: anything
      ``state_rate`` needs (``None`` when nothing).
    - ``energy(x, v, z)``: the potential energy it stores plus the kinetic energy of its own
      masses [J] (energy bookkeeping).

    and the members below, which two bases give for the common cases:
    [`AbstractForceElement`][absorber_jax.AbstractForceElement] (no states and no mass of its
    own) and [`AbstractSpring`][absorber_jax.AbstractSpring] (also conservative, without
    walls or fast dynamics: a spring of one's own needs only ``evaluate`` and ``energy``):
    ``dissipation``, ``num_states``/``state_labels``/``state_rate``/``state_scale``,
    ``momentum``, ``num_strokes``/``strokes``/``floats`` (an absorber's motion),
    ``stiffness_rate``/``oscillation_rate`` (its fast dynamics), ``penetrations`` and
    ``length_floor`` (contact walls), ``aliases`` (short parameter names).

    ```python
    import equinox as eqx, jax.numpy as jnp, absorber_jax as aj

    class CubicSpring(aj.AbstractSpring):
        dof: str = eqx.field(static=True)
        k3: float                                          # [N/m³]
        other: str | None = eqx.field(static=True, default=None)
        name: str | None = eqx.field(static=True, default=None)
        kind = "cubic"

        def evaluate(self, x, v, z):
            f = self.k3 * (x[0] - x[1]) ** 3               # tension pulling dof back
            return jnp.stack([-f, f]), None

        def energy(self, x, v, z):
            return 0.25 * self.k3 * (x[0] - x[1]) ** 4
    ```
    """

    dof: eqx.AbstractVar[object]
    other: eqx.AbstractVar[object]
    name: eqx.AbstractVar[object]
    kind: ClassVar[str] = "element"

    @property
    @abc.abstractmethod
    def num_states(self) -> int:
        """How many states of its own it adds to the system's state."""

    @property
    @abc.abstractmethod
    def state_labels(self) -> tuple:
        """Names of its states (suffixes of ``<name>.`` in ``state_names``)."""

    @abc.abstractmethod
    def evaluate(self, x, v, z):
        """``(forces (f_dof, f_other) [N], aux)`` for displacements ``x`` [m], velocities
        ``v`` [m/s] of its two degrees of freedom (ground: 0) and its states ``z``; ``aux``
        goes to ``state_rate``."""

    @abc.abstractmethod
    def state_rate(self, x, v, a, z, aux):
        """d/dt of its states given the absolute accelerations ``a`` [m/s²] of its degrees
        of freedom (the support's included under a base excitation) and ``aux`` from
        ``evaluate``."""

    @abc.abstractmethod
    def energy(self, x, v, z):
        """Kinetic energy of its own masses plus the potential energy it stores [J]."""

    @abc.abstractmethod
    def dissipation(self, x, v, z):
        """Power [W] it dissipates (>= 0)."""

    @abc.abstractmethod
    def momentum(self, x, v, z):
        """Momentum [kg m/s] of its own masses along its degree of freedom, in the
        structure's frame (the power a support acceleration ``a_g`` puts into them is
        ``-a_g r · momentum``)."""

    @property
    @abc.abstractmethod
    def num_strokes(self) -> int:
        """1 for an absorber (a mass riding on its host), else 0."""

    @abc.abstractmethod
    def strokes(self, z):
        """Its absorber's displacement relative to the host (empty if not an absorber)."""

    def field_unit(self, field: str) -> str:
        """SI unit of its parameter field ``field`` (``m`` [kg], ``k`` [N/m], ``gap`` [m],
        ``N`` [N] ...; its laws' fields are theirs to say)."""
        return units.field_unit(field)

    @abc.abstractmethod
    def penetrations(self, x, v, z):
        """Signed penetration [m] of each of its contact walls (``> 0``: closed); empty
        when it has none."""

    @abc.abstractmethod
    def floats(self, stroke_max):
        """1 when its absorber floats free on an orbit within ``stroke_max``, else 0."""

    @abc.abstractmethod
    def state_scale(self, length, omega):
        """Natural size of its states for a motion of size ``length`` [m] at ``omega``
        [rad/s] (the integrator's tolerances apply to the states divided by it)."""

    @abc.abstractmethod
    def length_floor(self):
        """Smallest natural length [m] of the motion it allows (a gap; 0 without one)."""

    @abc.abstractmethod
    def stiffness_rate(self, host_mass):
        """Rough largest rate [1/s] it adds to the dynamics (``host_mass`` [kg]: the
        structure's effective mass at its degree of freedom), for the automatic choice of an
        implicit solver (0: nothing faster than the structure)."""

    @abc.abstractmethod
    def oscillation_rate(self, host_mass):
        """Angular frequency [rad/s] of a fast, lightly damped oscillation it adds (0:
        none)."""

    @abc.abstractmethod
    def aliases(self) -> dict:
        """Short parameter names mapped to field paths within the element."""

    def parameter_names(self) -> list:
        fields = [f.name for f in dataclasses.fields(self)
                  if f.init and f.name not in ("dof", "other", "name", "contact", "friction")]
        return fields + list(self.aliases())

    def check(self):
        """Element-level checks that need the structure (none by default)."""


class AbstractMasslessElement(AbstractElement):
    """An element without a mass of its own: no momentum, no stroke, never floating (a
    contact, a spring, a friction contact)."""

    def momentum(self, x, v, z):
        return jnp.zeros((), dtype=jnp.result_type(x, float))

    @property
    def num_strokes(self) -> int:
        return 0

    def strokes(self, z):
        return _zeros(0, z)

    def floats(self, stroke_max):
        return jnp.zeros((), int)


class AbstractForceElement(AbstractMasslessElement):
    """An element that only applies forces: no states and no mass of its own (so no
    stroke, no floating and no bristle mode).  A concrete one gives ``evaluate``,
    ``energy``, ``dissipation``, ``stiffness_rate``, ``penetrations``, ``length_floor`` and
    ``aliases``."""

    @property
    def num_states(self) -> int:
        return 0

    @property
    def state_labels(self) -> tuple:
        return ()

    def state_rate(self, x, v, a, z, aux):
        return _zeros(0, x)

    def state_scale(self, length, omega):
        return jnp.ones((0,), dtype=jnp.result_type(length, float))

    def oscillation_rate(self, host_mass):
        return jnp.zeros(())


class AbstractSpring(AbstractForceElement):
    """A conservative force element without contact walls or fast dynamics of its own: a
    nonlinear spring of one's own (a cubic spring, a softening law).  A concrete one gives
    ``evaluate`` (the forces) and ``energy`` (the potential energy it stores); it dissipates
    nothing, has no gap and no short parameter names, and adds no rate faster than the
    structure's (``stiffness_rate`` 0)."""

    def dissipation(self, x, v, z):
        return jnp.zeros((), dtype=jnp.result_type(x, float))

    def stiffness_rate(self, host_mass):
        return jnp.zeros(())

    def penetrations(self, x, v, z):
        return _zeros(0, x)

    def length_floor(self):
        return jnp.zeros(())

    def aliases(self) -> dict:
        return {}


class AbstractStickSlipElement(AbstractElement):
    """An element whose friction may be the exact nonsmooth law, integrated by switching
    between stick and slip at events (one such element per system; see
    ``StructuralSystem``'s hybrid members).  ``FrictionDamper`` implements it."""

    @property
    @abc.abstractmethod
    def exact(self) -> bool:
        """True when the element's friction is the exact nonsmooth law (event-driven)."""

    @abc.abstractmethod
    def slip_velocity(self, z):
        """Sliding velocity ``V`` [m/s] whose sign is the slip mode."""

    @abc.abstractmethod
    def evaluate_mode(self, x, v, z, friction_force):
        """``evaluate`` with the friction force [N] given."""

    @abc.abstractmethod
    def holding_friction(self, z, host_acceleration, host_compliance):
        """Friction force [N] that keeps it stuck, from the host's absolute acceleration
        [m/s²] without its force and the host's acceleration per unit force on it
        [1/kg]."""

    @abc.abstractmethod
    def stuck_rate(self, rate):
        """Its state rate while stuck (the sliding coordinates frozen)."""

    @abc.abstractmethod
    def breakaway(self):
        """Largest friction force [N] it holds while stuck."""

    @abc.abstractmethod
    def kinetic(self, speed):
        """Friction force magnitude [N] while slipping at ``speed`` [m/s]."""

    @abc.abstractmethod
    def inertia(self):
        """The mass [kg] whose inertia force scales its holding force."""

    @abc.abstractmethod
    def stop_slip(self, z):
        """Its states with the sliding velocity set exactly to zero (end of a slip)."""


class AbstractRigidImpactElement(AbstractElement):
    """An element whose contact may be the rigid impact law (``Restitution``), integrated
    event by event (see ``StructuralSystem``'s hybrid members): a normal coordinate ``r``
    [m] (an absorber's displacement relative to its host, or the relative displacement of
    two degrees of freedom) meets a wall at ``r = gap`` (and at ``r = -gap`` when
    two-sided), where its rate ``ṙ`` jumps by Newton's law.  ``ImpactDamper`` and
    ``Contact`` implement it."""

    gap: eqx.AbstractVar[object]
    contact: eqx.AbstractVar[object]

    @property
    @abc.abstractmethod
    def rigid(self) -> bool:
        """True when the element's contact is the rigid impact law (event-driven)."""

    @property
    @abc.abstractmethod
    def two_sided(self) -> bool:
        """True for walls at ``±gap``, False for one wall at ``+gap``."""

    @abc.abstractmethod
    def normal(self, x, v, z):
        """``(r, ṙ)``: the normal coordinate [m] and its rate [m/s]."""

    @abc.abstractmethod
    def evaluate_force(self, x, v, z, force):
        """``evaluate`` with the contact force given: ``force`` [N] along ``r`` (positive
        pushes the wall at ``+gap`` apart), zero in free flight."""

    @abc.abstractmethod
    def impact_mass(self, host_mass):
        """A mass [kg] that scales its contact forces (tolerances only)."""

    @abc.abstractmethod
    def held_rate(self, rate):
        """Its own states' rate while held against a wall (``rate`` itself where it has no
        coordinate of its own)."""

    @abc.abstractmethod
    def on_wall(self, z, side):
        """Its own states with its coordinate put on the wall ``side`` (``z`` itself where
        it has none)."""


class AbstractLinearElement(AbstractElement):
    """An element whose forces and own states' rates are linear in the displacements,
    velocities and accelerations of its degrees of freedom and in its own states (a tuned
    mass damper; a linear spring or dashpot of your own: subclass this besides your base).
    A structure of such elements only is ``linear``: its exact peaks come from its
    closed-form response (``StructuralSystem.harmonic_response``).  With rigid impact
    elements, and no other kind beside them, a structure's modes stay affine, so its
    flights between impacts are integrated in closed form (matrix exponentials) instead of
    by an ODE solver.  It adds no member to implement."""


def is_linear(element) -> bool:
    """Whether ``element`` declares itself linear (``AbstractLinearElement``)."""
    return isinstance(element, AbstractLinearElement)


def is_rigid(element) -> bool:
    """Whether ``element`` is integrated with rigid (event-driven) impacts."""
    return isinstance(element, AbstractRigidImpactElement) and bool(element.rigid)


def is_exact(element) -> bool:
    """Whether ``element`` is integrated with exact (event-driven) stick–slip."""
    return isinstance(element, AbstractStickSlipElement) and bool(element.exact)


def _law_aliases(law, prefix):
    return {f.name: f"{prefix}.{f.name}" for f in dataclasses.fields(law)
            if f.init and f.name != "exact"}


def _check_contact(owner, law):
    if not isinstance(law, AbstractContactLaw):
        raise ValueError(f"{owner}.contact must be a contact law (KelvinVoigt, Hertz, "
                         f"HuntCrossley, Restitution or another AbstractContactLaw), got "
                         f"{type(law).__name__}")


def _check_friction(owner, law, *, exact_ok):
    if not isinstance(law, AbstractFrictionLaw):
        raise ValueError(f"{owner}.friction must be a friction law (Coulomb, Stribeck, Dahl, "
                         f"LuGre or another AbstractFrictionLaw), got {type(law).__name__}")
    if law.exact and not exact_ok:
        raise ValueError(
            f"{owner}.friction: exact stick–slip (events) is available in FrictionDamper; "
            f"here give a smoothing length (e.g. Coulomb(mu, eps=1e-5)) or a bristle law "
            f"(Dahl, LuGre)")


class AbstractAbsorber(AbstractElement):
    r"""An absorber: a mass ``m`` [kg] riding on its host degree of freedom ``dof`` through a
    coupling force.  Its states are ``u = x_abs - x_host`` [m], ``w = u̇`` [m/s] and the
    coupling's own states ``z`` (a bristle deflection); its equation of motion is
    ``m (a_host + ẇ) = -f`` with ``f = coupling(u, w, z)`` the force it applies to the host
    and ``a_host`` the host's absolute acceleration.

    **A concrete absorber declares** the fields ``dof``, ``m`` (its mass [kg]), ``name`` and
    ``other = eqx.field(static=True, default=None, init=False)`` (an absorber has no second
    degree of freedom), and defines:

    - ``coupling(u, w, z) -> (f, dz/dt)``: the force [N] on the host and the rates of the
      coupling's states (empty when it has none);
    - ``coupling_energy(u, z)``: the potential energy [J] of the coupling;
    - ``coupling_dissipation(u, w, z)``: the power [W] it dissipates.

    and the members ``AbstractElement`` leaves to it: ``num_law_states`` and
    ``law_state_scale`` (coupling states), ``penetrations``, ``floats`` and ``length_floor``
    (walls and a gap), ``stiffness_rate`` and ``oscillation_rate`` (a stiff coupling, a
    bristle mode), ``aliases``.
    """

    m: eqx.AbstractVar[object]

    @property
    def num_states(self) -> int:
        return 2 + self.num_law_states

    @property
    @abc.abstractmethod
    def num_law_states(self) -> int:
        """States of the coupling itself (0 when none)."""

    @property
    def state_labels(self) -> tuple:
        return ("u", "w") + tuple(f"z{i + 1}" for i in range(self.num_law_states))

    @abc.abstractmethod
    def coupling(self, u, w, z):
        """``(force on the host [N], dz/dt)`` for the relative motion ``u`` [m], ``w``
        [m/s] and the coupling's states ``z``."""

    @abc.abstractmethod
    def coupling_energy(self, u, z):
        """Potential energy [J] of the coupling."""

    @abc.abstractmethod
    def coupling_dissipation(self, u, w, z):
        """Power [W] dissipated in the coupling."""

    def evaluate(self, x, v, z):
        f, zdot = self.coupling(z[0], z[1], z[2:])
        return jnp.stack([f, jnp.zeros_like(f)]), (f, zdot)

    def state_rate(self, x, v, a, z, aux):
        f, zdot = aux
        # the absorber feels -f: its acceleration relative to the host
        return jnp.concatenate([jnp.stack([z[1], -f / self.m - a[0]]), zdot])

    def energy(self, x, v, z):
        return 0.5 * self.m * (v[0] + z[1]) ** 2 + self.coupling_energy(z[0], z[2:])

    def dissipation(self, x, v, z):
        return self.coupling_dissipation(z[0], z[1], z[2:])

    def momentum(self, x, v, z):
        return self.m * (v[0] + z[1])

    @property
    def num_strokes(self) -> int:
        return 1

    def strokes(self, z):
        return z[:1]

    def state_scale(self, length, omega):
        L = jnp.maximum(length, self.length_floor())
        return jnp.concatenate([jnp.stack([L, L * omega]), self.law_state_scale()])

    @abc.abstractmethod
    def law_state_scale(self):
        """Natural size of the coupling's states (empty when it has none)."""


class AbstractSpringAbsorber(AbstractAbsorber):
    """An absorber on a coupling without states of its own, contact walls or fast modes (a
    tuned mass damper, a nonlinear energy sink): a concrete one gives ``coupling``,
    ``coupling_energy``, ``coupling_dissipation`` and ``stiffness_rate`` (the coupling's
    rough largest rate [1/s], for the solver choice); its spring ties it to its host, so it
    never floats free."""

    @property
    def num_law_states(self) -> int:
        return 0

    def law_state_scale(self):
        return jnp.ones((0,))

    def penetrations(self, x, v, z):
        return _zeros(0, x)

    def floats(self, stroke_max):
        return jnp.zeros((), int)

    def length_floor(self):
        return jnp.zeros(())

    def oscillation_rate(self, host_mass):
        return jnp.zeros(())

    def aliases(self) -> dict:
        return {}


class ImpactDamper(AbstractAbsorber, AbstractRigidImpactElement):
    r"""An impact absorber at a degree of freedom: a mass ``m`` [kg] moving freely in a
    cavity of the host with clearance ``gap`` [m] on each side, ``contact`` any contact law
    (the paper's section 2 with the host as primary).  With ``u = x_abs - x_host``,
    ``δ± = max(0, ±u - gap)``, the force on the host is ``f(δ+, u̇) - f(δ-, -u̇)``.

    ```python
    ImpactDamper("x3", m=0.05, gap=2e-3, contact=KelvinVoigt(stiffness=1e5, damping=20.0))
    ```
    """

    dof: object = eqx.field(static=True)
    m: object = eqx.field(converter=as_float)
    gap: object = eqx.field(converter=as_float)
    contact: AbstractContactLaw
    name: object = eqx.field(static=True, default=None)
    other: object = eqx.field(static=True, default=None, init=False)
    kind: ClassVar[str] = "impact"

    def __check_init__(self):
        positive("ImpactDamper", "m", self.m)
        nonnegative("ImpactDamper", "gap", self.gap)
        _check_contact("ImpactDamper", self.contact)
        if self.contact.exact:
            positive("ImpactDamper (rigid impacts: Restitution)", "gap", self.gap)

    def coupling(self, u, w, z):
        return self.contact.clearance_force(u, w, self.gap), _zeros(0, u)

    @property
    def rigid(self) -> bool:
        return self.contact.exact

    @property
    def two_sided(self) -> bool:
        return True

    def normal(self, x, v, z):
        return z[0], z[1]

    def evaluate_force(self, x, v, z, force):
        f = jnp.asarray(force, dtype=jnp.result_type(z))
        return jnp.stack([f, jnp.zeros_like(f)]), (f, _zeros(0, z))

    @property
    def num_law_states(self) -> int:
        return 0

    def law_state_scale(self):
        return jnp.ones((0,))

    def oscillation_rate(self, host_mass):
        return jnp.zeros(())

    def impact_mass(self, host_mass):
        return self.m

    def held_rate(self, rate):
        return jnp.zeros_like(rate)

    def on_wall(self, z, side):
        return z.at[0].set(side * self.gap)

    def penetrations(self, x, v, z):
        return self.contact.clearance_penetrations(z[0], self.gap)

    def coupling_energy(self, u, z):
        return self.contact.clearance_energy(u, self.gap)

    def coupling_dissipation(self, u, w, z):
        return self.contact.clearance_dissipation(u, w, self.gap)

    def length_floor(self):
        return self.gap

    def floats(self, stroke_max):
        return (stroke_max[0] < self.gap).astype(int)

    def stiffness_rate(self, host_mass):
        meff = self.m * host_mass / (self.m + host_mass)
        return self.contact.stiffness_rate(meff, jnp.maximum(self.gap, 1e-3))

    def aliases(self):
        return _law_aliases(self.contact, "contact")


class FrictionDamper(AbstractAbsorber, AbstractStickSlipElement):
    r"""A friction absorber at a degree of freedom: a mass ``m`` [kg] tied to the host by a
    spring ``k`` [N/m] and a dashpot ``c`` [N s/m] and sliding on it under the normal force
    ``normal_force`` [N] (parameter alias ``N``) with ``friction`` a smoothed (``eps``) or
    bristle law (the paper's section 3 with the host as primary).  With ``u = x_abs - x_host``
    the force on the host is ``k u + c u̇ - F_nl(-u̇)``.

    ```python
    FrictionDamper("w9", m=0.2, k=5e3, c=0.0, normal_force=2.0,
                   friction=Coulomb(mu=0.5, eps=1e-5))
    ```
    """

    dof: object = eqx.field(static=True)
    m: object = eqx.field(converter=as_float)
    k: object = eqx.field(converter=as_float)
    c: object = eqx.field(converter=as_float)
    normal_force: object = eqx.field(converter=as_float)
    friction: AbstractFrictionLaw
    name: object = eqx.field(static=True, default=None)
    other: object = eqx.field(static=True, default=None, init=False)
    kind: ClassVar[str] = "friction"

    def __check_init__(self):
        positive("FrictionDamper", "m", self.m)
        nonnegative("FrictionDamper", "k", self.k)
        nonnegative("FrictionDamper", "c", self.c)
        nonnegative("FrictionDamper", "normal_force", self.normal_force)
        _check_friction("FrictionDamper", self.friction, exact_ok=True)

    @property
    def num_law_states(self) -> int:
        return self.friction.num_states

    def coupling(self, u, w, z):
        # X = x_host - x_abs = -u: the same law and signs as FrictionAbsorber
        fnl = self.friction.force(-w, z, self.normal_force)
        zdot = self.friction.state_rate(-w, z, self.normal_force)
        return self.c * w + self.k * u - fnl, zdot

    def coupling_energy(self, u, z):
        return 0.5 * self.k * u**2 + self.friction.stored_energy(z)

    def coupling_dissipation(self, u, w, z):
        return self.c * w**2 + self.friction.dissipated_power(-w, z, self.normal_force)

    def law_state_scale(self):
        return self.friction.state_scale(self.normal_force)

    def penetrations(self, x, v, z):
        return _zeros(0, x)

    def floats(self, stroke_max):
        return jnp.zeros((), int)       # its spring k ties it to the host

    def length_floor(self):
        return jnp.zeros(())

    def stiffness_rate(self, host_mass):
        meff = self.m * host_mass / (self.m + host_mass)
        return jnp.maximum(jnp.maximum(jnp.sqrt(self.k / meff), self.c / meff),
                           self.friction.stiffness_rate(self.normal_force, meff))

    def oscillation_rate(self, host_mass):
        meff = self.m * host_mass / (self.m + host_mass)
        return self.friction.oscillation_rate(self.normal_force, meff)

    def aliases(self):
        return {"N": "normal_force", **_law_aliases(self.friction, "friction")}

    # -- exact stick–slip: the same law and signs as FrictionAbsorber (X = -u, V = -w) -----
    @property
    def exact(self) -> bool:
        return self.friction.exact

    def slip_velocity(self, z):
        return -z[1]

    def evaluate_mode(self, x, v, z, friction_force):
        f = self.c * z[1] + self.k * z[0] - friction_force
        return jnp.stack([f, jnp.zeros_like(f)]), (f, _zeros(0, f))

    def holding_friction(self, z, host_acceleration, host_compliance):
        # stuck: the absorber moves with its host, -f/m = a0 + h f, so f = -m a0 / (1 + m h)
        f = -self.m * host_acceleration / (1.0 + self.m * host_compliance)
        return self.c * z[1] + self.k * z[0] - f

    def stuck_rate(self, rate):
        return jnp.zeros_like(rate)

    def breakaway(self):
        return self.friction.breakaway_force(self.normal_force)

    def kinetic(self, speed):
        return self.friction.kinetic_force(speed, self.normal_force)

    def inertia(self):
        return self.m

    def stop_slip(self, z):
        return z.at[1].set(0.0)


class TunedMassDamper(AbstractSpringAbsorber, AbstractLinearElement):
    r"""A linear tuned mass damper at a degree of freedom: a mass ``m`` [kg] on a spring
    ``k`` [N/m] and a dashpot ``c`` [N s/m]; force on the host ``k u + c u̇``.

    ```python
    TunedMassDamper("x3", m=0.1, k=90.0, c=0.6)
    ```
    """

    dof: object = eqx.field(static=True)
    m: object = eqx.field(converter=as_float)
    k: object = eqx.field(converter=as_float)
    c: object = eqx.field(converter=as_float)
    name: object = eqx.field(static=True, default=None)
    other: object = eqx.field(static=True, default=None, init=False)
    kind: ClassVar[str] = "tmd"

    def __check_init__(self):
        positive("TunedMassDamper", "m", self.m)
        nonnegative("TunedMassDamper", "k", self.k)
        nonnegative("TunedMassDamper", "c", self.c)

    def coupling(self, u, w, z):
        return self.k * u + self.c * w, _zeros(0, u)

    def coupling_energy(self, u, z):
        return 0.5 * self.k * u**2

    def coupling_dissipation(self, u, w, z):
        return self.c * w**2

    def stiffness_rate(self, host_mass):
        meff = self.m * host_mass / (self.m + host_mass)
        return jnp.maximum(jnp.sqrt(self.k / meff), self.c / meff)


class Contact(AbstractForceElement, AbstractRigidImpactElement):
    r"""A contact with a gap between the degree of freedom ``dof`` and ``other`` (another
    degree of freedom, or ground when ``None``), ``contact`` any contact law.

    With ``r = x_dof - x_other``: ``sides="one"`` acts when ``direction · r > gap``
    (penetration ``δ = direction · r - gap``), pushing ``dof`` back with ``-direction · f(δ,
    δ̇)`` and ``other`` the other way; ``sides="two"`` acts on both sides (``|r| > gap``), a
    clearance.  NLvib's unilateral spring of stiffness 100 when ``q1 > 1`` is
    ``Contact("x1", gap=1.0, contact=KelvinVoigt(stiffness=100.0, damping=0.0))``; a rigid
    stop there with restitution 0.8 is ``Contact("x1", gap=1.0, contact=Restitution(0.8))``
    (a two-sided rigid contact needs ``gap > 0``).
    """

    dof: object = eqx.field(static=True)
    gap: object = eqx.field(converter=as_float)
    contact: AbstractContactLaw
    other: object = eqx.field(static=True, default=None)
    sides: str = eqx.field(static=True, default="one")
    direction: int = eqx.field(static=True, default=1)
    name: object = eqx.field(static=True, default=None)
    kind: ClassVar[str] = "contact"

    def __check_init__(self):
        nonnegative("Contact", "gap", self.gap)
        _check_contact("Contact", self.contact)
        if self.contact.exact and self.sides == "two":
            positive("Contact (two-sided, rigid impacts: Restitution)", "gap", self.gap)
        if self.sides not in ("one", "two"):
            raise ValueError(f"Contact.sides must be 'one' or 'two', got {self.sides!r}")
        if self.direction not in (1, -1):
            raise ValueError(f"Contact.direction must be +1 or -1, got {self.direction!r}")

    def _walls(self, x, v):
        r, rd = self.direction * (x[0] - x[1]), self.direction * (v[0] - v[1])
        walls = [(r - self.gap, rd, 1.0)]
        if self.sides == "two":
            walls.append((-r - self.gap, -rd, -1.0))
        return walls

    def penetrations(self, x, v, z):
        return jnp.stack([p for p, _, _ in self._walls(x, v)])

    @property
    def rigid(self) -> bool:
        return self.contact.exact

    @property
    def two_sided(self) -> bool:
        return self.sides == "two"

    def normal(self, x, v, z):
        return self.direction * (x[0] - x[1]), self.direction * (v[0] - v[1])

    def evaluate_force(self, x, v, z, force):
        f = self.direction * jnp.asarray(force, dtype=jnp.result_type(x))
        return jnp.stack([-f, f]), None

    def impact_mass(self, host_mass):
        return host_mass

    def evaluate(self, x, v, z):
        f = sum(sgn * self.contact.wall_force(p, pd)[0] for p, pd, sgn in self._walls(x, v))
        f = self.direction * f  # along +r, pushing dof back and other forward
        return jnp.stack([-f, f]), None

    def energy(self, x, v, z):
        return sum(self.contact.wall_energy(p) for p, _, _ in self._walls(x, v))

    def dissipation(self, x, v, z):
        return sum(self.contact.dissipated_power(p, pd) for p, pd, _ in self._walls(x, v))

    def length_floor(self):
        return self.gap

    def stiffness_rate(self, host_mass):
        return self.contact.stiffness_rate(host_mass, jnp.maximum(self.gap, 1e-3))

    def aliases(self):
        return _law_aliases(self.contact, "contact")

    def held_rate(self, rate):
        return rate     # no coordinate of its own

    def on_wall(self, z, side):
        return z


class FrictionContact(AbstractMasslessElement):
    r"""A friction contact between ``dof`` and ``other`` (another degree of freedom, or
    ground when ``None``) pressed by ``normal_force`` [N] (alias ``N``), ``friction`` a
    smoothed or bristle law: with the slip velocity ``V = v_dof - v_other`` it pushes ``dof``
    with ``-F(V, z)`` and ``other`` with ``+F``.  A bristle law's deflection ``z`` is its state.
    """

    dof: object = eqx.field(static=True)
    normal_force: object = eqx.field(converter=as_float)
    friction: AbstractFrictionLaw
    other: object = eqx.field(static=True, default=None)
    name: object = eqx.field(static=True, default=None)
    kind: ClassVar[str] = "friction_contact"

    def __check_init__(self):
        nonnegative("FrictionContact", "normal_force", self.normal_force)
        _check_friction("FrictionContact", self.friction, exact_ok=False)

    @property
    def num_states(self) -> int:
        return self.friction.num_states

    @property
    def state_labels(self) -> tuple:
        return tuple(f"z{i + 1}" for i in range(self.num_states))

    def evaluate(self, x, v, z):
        V = v[0] - v[1]
        f = self.friction.force(V, z, self.normal_force)
        return jnp.stack([-f, f]), self.friction.state_rate(V, z, self.normal_force)

    def state_rate(self, x, v, a, z, aux):
        return aux

    def energy(self, x, v, z):
        return self.friction.stored_energy(z)

    def dissipation(self, x, v, z):
        return self.friction.dissipated_power(v[0] - v[1], z, self.normal_force)

    def state_scale(self, length, omega):
        return self.friction.state_scale(self.normal_force)

    def stiffness_rate(self, host_mass):
        return self.friction.stiffness_rate(self.normal_force, host_mass)

    def oscillation_rate(self, host_mass):
        return self.friction.oscillation_rate(self.normal_force, host_mass)

    def aliases(self):
        return {"N": "normal_force", **_law_aliases(self.friction, "friction")}

    def penetrations(self, x, v, z):
        return _zeros(0, x)

    def length_floor(self):
        return jnp.zeros(())
