"""The abstract system (``AbstractSystem``): the only members the generic layers talk to."""

from __future__ import annotations

import abc

import equinox as eqx

from .._core import units


class AbstractSystem(eqx.Module):
    """A forced mechanical system: the interface that ``simulate``, the steady-state solvers,
    the sweeps, continuation, design and the CLI use, and nothing else.

    Two families implement it: the paper's one-mass-one-absorber systems
    ([`ImpactAbsorber`][absorber_jax.ImpactAbsorber],
    [`FrictionAbsorber`][absorber_jax.FrictionAbsorber]) and the general
    [`StructuralSystem`][absorber_jax.StructuralSystem] (a
    [`LinearStructure`][absorber_jax.LinearStructure] carrying any number of elements).  Each
    declares:

    - its state: ``num_states``, ``state_names`` (the named slices of the flat *public*
      state), ``to_internal``/``to_public`` (the integrator's state and the user's),
      ``rest_state``, ``state_scale`` (the per-component scale the integrator and Newton
      work in);
    - its dynamics: ``vector_field``, ``mechanical_energy``, ``power``, the solver hints
      ``stiffness_rate``/``oscillation_rate`` (``AbstractHybridSystem`` adds the modes and
      switches of exact stick–slip and rigid impacts);
    - what is measured on it: ``output_names``/``outputs`` (displacements at named degrees
      of freedom [m or rad]), ``observable`` (the scalar signal that ``amplitude``, ``rms``,
      ``harmonic`` and the design objectives use), ``strokes`` (each absorber's motion
      relative to its host), ``floating_pairs`` (structural Floquet multipliers 1 of
      absorbers that never touch anything), ``penetrations`` (each contact wall's signed
      penetration, for counting impacts);
    - its named parameters: ``parameter_path`` and ``parameter_names``.
    """

    # -- state ------------------------------------------------------------------------
    @property
    @abc.abstractmethod
    def num_states(self) -> int:
        """Length of the (internal and public) state vector."""

    @property
    @abc.abstractmethod
    def state_names(self) -> tuple:
        """Names of the public state's components, in order."""

    @abc.abstractmethod
    def to_internal(self, y):
        """Public state -> the integrator's state."""

    @abc.abstractmethod
    def to_public(self, s):
        """The integrator's state (with any leading batch axes) -> public state."""

    @abc.abstractmethod
    def rest_state(self):
        """Internal state at rest."""

    @abc.abstractmethod
    def state_scale(self, forcing):
        """Per-component natural scale of the internal state under ``forcing``."""

    @abc.abstractmethod
    def linear_guess(self, forcing):
        """A starting orbit for shooting (internal state at ``t = 0``)."""

    @property
    @abc.abstractmethod
    def linear(self) -> bool:
        """``True`` when the vector field is linear in the state and in the forcing's value,
        and the observable linear in the state (a linear structure carrying linear elements
        only): the periodic response is then ``harmonic_response``'s closed form, and the
        design objectives evaluate it without integrating."""

    @abc.abstractmethod
    def harmonic_response(self, forcing):
        """The periodic response of a ``linear`` system to a periodic ``forcing``,
        ``s(t) = Im Σ_j X_j e^{i k_j ω t}`` over the forcing's harmonics
        (``forcing.harmonics()``: ``F(t) = Im Σ_j c_j e^{i k_j ω t}``): ``(orders, X)``,
        ``X`` complex of shape ``(harmonics, num_states)`` (internal state).  A system
        that is not ``linear`` raises ``ValueError``."""

    # -- dynamics ---------------------------------------------------------------------
    @abc.abstractmethod
    def vector_field(self, t, s, forcing):
        """d/dt of the internal state ``s`` under ``forcing``."""

    @abc.abstractmethod
    def mechanical_energy(self, s):
        """Kinetic + potential energy [J] of internal state ``s``."""

    @abc.abstractmethod
    def power(self, t, s, forcing):
        """``(input power of the forcing, dissipated power)`` [W]."""

    @abc.abstractmethod
    def stiffness_rate(self):
        """Rough largest rate [1/s] of the linearised dynamics (solver choice)."""

    @abc.abstractmethod
    def oscillation_rate(self):
        """Angular frequency [rad/s] of a fast, lightly damped internal oscillation that any
        solver must resolve at tight tolerances (solver choice; 0 when none)."""

    @abc.abstractmethod
    def trajectory_fields(self, ts, s, forcing):
        """Extra per-instant fields of a simulated [`Trajectory`][absorber_jax.Trajectory]
        (``coupling_force`` and, where they apply, friction diagnostics) from internal states ``s``
        at ``ts``."""

    @abc.abstractmethod
    def condensation(self):
        """The linear part and the nonlinear forces that harmonic balance condenses onto the
        degrees of freedom where the forces act (a ``Condensation``), or ``None`` where the
        system does not separate so."""

    # -- what is measured ---------------------------------------------------------------
    @property
    @abc.abstractmethod
    def output_names(self) -> tuple:
        """Names of the degrees of freedom reported per result (``dof_amplitude`` ...)."""

    @abc.abstractmethod
    def outputs(self, s):
        """Displacements [m or rad] at the ``output_names`` for internal state ``s``."""

    @abc.abstractmethod
    def observable(self, s):
        """The scalar signal whose amplitude, RMS and harmonic a result reports and the
        design objectives minimise."""

    @abc.abstractmethod
    def strokes(self, s):
        """Each absorber's displacement relative to its host (empty when none)."""

    @abc.abstractmethod
    def penetrations(self, s):
        """Signed penetration [m] of each contact wall at internal state ``s`` (``> 0``
        while that wall is closed), in a fixed order; empty when the system has no contact.
        Impacts are counted from its sign changes (attractor statistics)."""

    @abc.abstractmethod
    def floating_pairs(self, stroke_max):
        """How many absorbers float on an orbit whose strokes stay within ``stroke_max``
        (each gives a structural double Floquet multiplier 1, not a loss of stability)."""

    # -- named parameters ---------------------------------------------------------------
    @abc.abstractmethod
    def parameter_path(self, name: str) -> str:
        """Dotted field path of parameter ``name`` (aliases resolved; integers index
        tuples).  Unknown names are caught by the caller."""

    @abc.abstractmethod
    def parameter_names(self) -> list:
        """The names [`replace_params`][absorber_jax.replace_params], sweeps and ``tune`` accept."""

    def field_unit(self, field: str) -> str:
        """SI unit of this system's own parameter field ``field`` (``M``, ``k``, ``gap`` ...;
        fields of its laws and elements are theirs to say)."""
        return units.field_unit(field)

    @property
    @abc.abstractmethod
    def force_names(self) -> tuple:
        """Names of the columns of a trajectory's ``coupling_force`` where it has one per
        element (a structure's elements); empty where it is one force."""

    # -- what results measure --------------------------------------------------------------
    @abc.abstractmethod
    def signals(self) -> units.Signals:
        """The names and SI units of what its results measure (the observable, the absorber
        stroke, each output, state component and parameter): CSV headers, plot labels and
        dataset attributes."""


class AbstractHybridSystem(AbstractSystem):
    """A system that can be integrated exactly as a hybrid system: modes, each with a
    smooth vector field, left where a switching function crosses zero upwards, with a jump
    map at each switch (exact stick–slip, rigid impacts; see
    ``absorber_jax._integration.stickslip``).  Whether it is, ``hybrid``, depends on the
    laws it is built with (an exact Coulomb law, a ``Restitution`` contact): with smooth or
    compliant laws it is an ordinary ODE and none of the other members is called."""

    @property
    @abc.abstractmethod
    def hybrid(self) -> bool:
        """``True`` when integrated by switching modes at events."""

    @property
    @abc.abstractmethod
    def affine_modes(self) -> bool:
        """``True`` when every mode's rate is affine in the state and in the forcing's
        value and depends on time through the forcing only,
        ``mode_rate(t, s, F, m) = A_m s + b_m F(t) + d_m`` (a linear structure with rigid
        impact elements): its flights between events are then integrated in closed form
        under a forcing with exact harmonics (``absorber_jax._integration.flights``)."""

    @abc.abstractmethod
    def prepared(self):
        """The system as one hybrid integration uses it: the same modes, switches and jumps,
        with what they share and what stays fixed along an integration computed once (a
        structure's contact matrices); ``self`` where there is nothing to compute."""

    @abc.abstractmethod
    def mode_of(self, t, s, forcing):
        """Integer mode (or per-element modes) of internal state ``s`` at time ``t``."""

    @abc.abstractmethod
    def mode_rate(self, t, s, forcing, mode):
        """d/dt of ``s`` within ``mode``."""

    @abc.abstractmethod
    def switch_function(self, t, s, forcing, mode):
        """Leaves ``mode`` where this crosses zero upwards (dimensionless)."""

    @abc.abstractmethod
    def next_mode(self, t, s, forcing, mode):
        """``(new mode, projected state)`` after ``mode``'s switch fired at ``(t, s)``."""

    @abc.abstractmethod
    def event_step_limit(self, forcing):
        """The longest integrator step [s] of a hybrid integration (``None``: no limit).  An
        event is located from a sign change of the switching function at the ends of a step,
        so a switch crossed and crossed back within one step (a rigid wall grazed) is not
        seen; a limit bounds how deep such an excursion can be."""

    @abc.abstractmethod
    def admissible_state(self, t, s, forcing):
        """Internal state ``s`` at the start of a hybrid integration, mapped into the set the
        modes are defined on (a rigid contact: no penetration), continuously and smooth to
        first order at its boundary (the identity where every state is admissible)."""

    @abc.abstractmethod
    def event_is_impact(self, t, s, forcing, mode):
        """Whether the switch leaving ``mode`` at ``(t, s)`` (the state before it) is an
        impact (counted per period)."""

    @abc.abstractmethod
    def in_contact(self, mode):
        """Whether a contact is held closed in ``mode`` (time in contact)."""


def not_linear(system):
    """The ``ValueError`` of ``harmonic_response`` on a system that is not ``linear``."""
    return ValueError(f"{type(system).__name__} is not linear: its periodic response has no "
                      "closed form (use steady_state)")


def is_hybrid(system) -> bool:
    """Whether ``system`` is integrated as a hybrid system (switching modes at events)."""
    return isinstance(system, AbstractHybridSystem) and bool(system.hybrid)
