r"""The general system: a ``LinearStructure`` carrying any number of elements
(absorbers, tuned mass dampers, contacts, friction contacts, your own), loaded by ``F(t)``
distributed over its degrees of freedom,

$$M_q\ddot q + C_q\dot q + K_q q = \Phi^T\Big(b\,F(t) + \sum_e f_e(\Phi q, \Phi\dot q, z_e)\Big),$$

each element ``e`` reading the displacements ``x = Φ q`` of its degrees of freedom and its own
states ``z_e`` (an absorber's relative motion, a bristle deflection) and pushing back with
``f_e``; its states then evolve with the degrees of freedom's accelerations ``Φ q̈``.

Or shaken at its support (``BaseExcitation``): ``F(t) = a_g(t)`` is then the support's
acceleration [m/s²] along the influence vector ``r`` over the degrees of freedom, and the
model is written relative to the support, ``x = x_abs - r u_g``: the load is the inertia
``-M_q r_q a_g(t)`` of the structure (``Φ r_q = r``), and every element's own mass feels
``-m r a_g`` too (its state rate is given the absolute accelerations ``Φ q̈ + r a_g``).

State (internal = public), a flat vector with named slices (``state_names``, ``slice_of``):
``[q (n), q̇ (n), element states ...]`` in the structure's coordinates (the degrees of freedom
themselves for a matrix model, modal coordinates for a modal one); relative to the support
under a base excitation.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core import units
from .._core.checks import is_traced
from .._laws.restitution import RIGID_STEPS_PER_PERIOD
from .base import AbstractHybridSystem, not_linear
from .elements import AbstractElement, is_exact, is_linear, is_rigid
from .linear import finite_or_zero
from .structure import LinearStructure


def _weights(structure, value, field):
    """A vector over the degrees of freedom from a name, a ``{name: weight}`` dict or an
    array (ValueError naming ``field`` otherwise)."""
    n = structure.num_dofs
    if isinstance(value, str):
        value = {value: 1.0}
    if isinstance(value, dict):
        w = np.zeros(n)
        for k, v in value.items():
            try:
                i = structure.dof_index(k)
            except ValueError as e:
                raise ValueError(f"StructuralSystem.{field}: {e}") from None
            w[i] += float(v)
        return jnp.asarray(w)
    arr = jnp.asarray(value, dtype=float)
    if arr.shape != (n,):
        raise ValueError(f"StructuralSystem.{field} must be a degree-of-freedom name, a "
                         f"{{name: weight}} dict or an array of shape ({n},), got shape "
                         f"{arr.shape}")
    return arr


# a rigid impact element counts as held against a wall at the start of an integration when
# within this fraction of its gap of it and slower than this fraction of its velocity scale
STICK_TOLERANCE = 1e-9


class BaseExcitation(eqx.Module):
    r"""The ``load`` of a ``StructuralSystem`` shaken at its support: the forcing is then
    the support's acceleration ``a_g(t)`` [m/s²] (any forcing object: ``Harmonic``,
    ``MultiHarmonic``, ``PeriodicForcing``, a recorded signal of your own...).

    The system is written relative to the support, ``x = x_abs - r u_g`` with ``r`` the
    ``influence`` vector (the displacement of each degree of freedom for a unit rigid motion
    of the support): the structure is loaded by ``-M r a_g(t)`` (``-M_q r_q a_g`` in its
    coordinates, ``Φ r_q = r``), and each element's own mass ``m`` by ``-m r a_g`` (absorbers
    and tuned mass dampers move with the absolute acceleration of their host).  Elements
    "to ground" connect to the moving support.  Results (displacements, velocities,
    ``dof_amplitude``, trajectories) are relative to the support; an absorber's stroke is
    relative to its host either way.  Add ``r u_g(t)`` for absolute displacements.

    **Arguments**

    - ``influence``: ``r``: ``None`` (every degree of freedom moves with the support: a shear
      building, any model of translations), a degree-of-freedom name, a ``{name: weight}``
      dict or a vector over the degrees of freedom (a beam shaken sideways: ``1`` on the
      deflections ``w*``, ``0`` on the slopes ``th*``).
    - ``participation``: ``M_q r_q`` in the structure's coordinates [kg], for structures
      observed at fewer degrees of freedom than they have coordinates (a truncated modal
      model: its participation factors, ``LinearStructure.modal_participation`` of the
      full model).  Default: computed from ``r`` through ``Φ`` (square).

    ```python
    building = shear_building([1.0] * 3, [1e3] * 3, rayleigh=(0.1, 1e-4))
    sys = StructuralSystem(building, [TunedMassDamper("floor3", m=0.1, k=25.0, c=0.5)],
                           load=BaseExcitation(), observe="floor3")
    steady_state(sys, Harmonic(amplitude=0.5, omega=15.0))   # a_g = 0.5 sin(15 t) m/s²
    ```
    """

    influence: object = None
    participation: object = None

    def vectors(self, structure):
        """``(r, M_q r_q)``: the influence over the degrees of freedom and the inertia per
        unit support acceleration in the coordinates [kg] (ValueError when they cannot be
        formed)."""
        n, nc = structure.num_dofs, structure.num_coords
        r = (jnp.ones((n,)) if self.influence is None
             else _weights(structure, self.influence, "load (BaseExcitation.influence)"))
        if self.participation is not None:
            p = jnp.asarray(self.participation, dtype=float)
            if p.shape != (nc,):
                raise ValueError(f"BaseExcitation.participation must have one value per "
                                 f"coordinate of the structure ({nc}), got shape {p.shape}")
            return r, p
        if n != nc:
            raise ValueError(f"BaseExcitation: the structure has {nc} coordinates observed at "
                             f"{n} degrees of freedom, so its rigid motion cannot be read from "
                             f"them: give participation= (M_q r_q in its coordinates, e.g. "
                             f"full.modal_participation(n_modes) of the full model)")
        r_q = jnp.linalg.solve(structure.dof_map, r)
        return r, structure.mass @ r_q


def _all_diagonal(*mats) -> bool:
    """Whether every matrix is (concretely) diagonal; False for traced ones."""
    if any(is_traced(m) for m in mats):
        return False
    return all(not np.any(np.asarray(m) - np.diag(np.diag(np.asarray(m)))) for m in mats)


class StructuralSystem(AbstractHybridSystem):
    r"""A linear structure with elements attached, forced by ``F(t) · load`` or shaken at its
    support.

    With the structure's mass, damping and stiffness ``M_q``, ``C_q``, ``K_q`` in its
    coordinates ``q``, ``x = Φ q`` the displacements of the degrees of freedom and ``b`` the
    ``load`` vector:

    $$
    M_q\ddot q + C_q\dot q + K_q q = \Phi^T\Big(b\,F(t) + \sum_e f_e(\Phi q, \Phi\dot q, z_e)\Big),
    $$

    each element ``e`` reading the displacements and velocities of its degrees of freedom
    and its own states ``z_e`` (an absorber's relative motion, a bristle deflection) and
    pushing back with ``f_e``; its states evolve with the accelerations ``Φ q̈``.  Under a
    ``BaseExcitation`` load, ``F(t)`` is the support's acceleration [m/s²] and the model is
    written relative to the support.  The state (internal = public) is a flat vector with
    named slices (``state_names``, ``slice_of``): ``[q (n), q̇ (n), element states ...]`` in
    the structure's coordinates (the degrees of freedom themselves for a matrix model, modal
    coordinates for a modal one).  Worked examples: the Structures guide of the
    documentation.

    **Arguments**

    - ``structure``: a [`LinearStructure`][absorber_jax.LinearStructure] (matrices or modes).
    - ``elements``: a sequence of elements ([`ImpactDamper`][absorber_jax.ImpactDamper],
      [`FrictionDamper`][absorber_jax.FrictionDamper],
      [`TunedMassDamper`][absorber_jax.TunedMassDamper], [`Contact`][absorber_jax.Contact],
      [`FrictionContact`][absorber_jax.FrictionContact] or any
      [`AbstractElement`][absorber_jax.AbstractElement] of your own), each named by its ``name`` or
      ``<kind><count>`` (``impact1``, ``tmd2``, ...); their parameters are ``<name>.<field>``
      (``tmd1.k``, ``friction1.N``).
    - ``load``: where ``F(t)`` acts: a degree-of-freedom name (unit weight), a
      ``{name: weight}`` dict or a vector over the degrees of freedom (a force [N] per unit
      ``F``); or a ``BaseExcitation``: ``F(t)`` is the support's acceleration [m/s²]
      and the model is relative to the support.
    - ``observe``: the observable of the results and design objectives: a degree of freedom,
      or a ``{name: weight}`` dict / vector for the weighted signal ``Σ w_i x_i`` (e.g. an
      inter-storey drift ``{"x3": 1, "x2": -1}``); default the loaded degree of freedom
      when the load acts on one (required under a base excitation).

    Fields: ``load`` (the weights over the degrees of freedom, or the
    ``BaseExcitation`` with its ``influence`` and ``participation`` as arrays),
    ``observe``, ``mass_inverse``; ``base_excited`` (static).

    ```python
    building = shear_building([1.0] * 3, [1e3] * 3, rayleigh=(0.1, 1e-4))
    sys = StructuralSystem(building, [TunedMassDamper("x3", m=0.1, k=25.0, c=0.5)],
                           load="x1", observe="x3")
    ```
    """

    structure: LinearStructure
    elements: tuple
    load: jax.Array | BaseExcitation
    observe: jax.Array
    mass_inverse: jax.Array
    base_excited: bool = eqx.field(static=True, init=False)
    # mass, damping and stiffness all diagonal (a modal model): the equations of motion are
    # then evaluated mode by mode (elementwise) instead of by matrix products
    diagonal: bool = eqx.field(static=True, init=False)
    # the rigid impact elements' matrices (``prepared``); None on a system as built
    contact_matrices: object = eqx.field(init=False)

    def __init__(self, structure, elements=(), *, load, observe=None, mass_inverse=None):
        if not isinstance(structure, LinearStructure):
            raise ValueError(f"StructuralSystem.structure must be a LinearStructure, got "
                             f"{type(structure).__name__}")
        elements = tuple(elements)
        for e in elements:
            if not isinstance(e, AbstractElement):
                raise ValueError(f"StructuralSystem.elements must be elements (ImpactDamper, "
                                 f"FrictionDamper, TunedMassDamper, Contact, FrictionContact "
                                 f"or another AbstractElement), got {type(e).__name__}")
            for d in (e.dof,) + (() if e.other is None else (e.other,)):
                try:
                    structure.dof_index(d)
                except ValueError as err:
                    raise ValueError(f"StructuralSystem.elements: {type(e).__name__}: "
                                     f"{err}") from None
        self.structure = structure
        self.elements = elements
        self.base_excited = isinstance(load, BaseExcitation)
        if self.base_excited:
            r, p = load.vectors(structure)
            self.load = BaseExcitation(influence=r, participation=p)
        else:
            self.load = _weights(structure, load, "load")
        if observe is None:
            if self.base_excited:
                raise ValueError("StructuralSystem.observe must be given with a "
                                 "BaseExcitation load")
            nz = np.flatnonzero(np.asarray(self.load))
            if nz.size != 1:
                raise ValueError("StructuralSystem.observe must be given when the load acts on "
                                 "several degrees of freedom")
            observe = structure.dof_names[int(nz[0])]
        self.observe = _weights(structure, observe, "observe")
        self.mass_inverse = (jnp.linalg.inv(structure.mass) if mass_inverse is None
                             else jnp.asarray(mass_inverse, dtype=float))
        self.diagonal = _all_diagonal(structure.mass, structure.damping, structure.stiffness,
                                      self.mass_inverse)
        self.contact_matrices = None
        if sum(is_exact(e) for e in elements) > 1:
            raise ValueError("StructuralSystem.elements: at most one friction damper with an "
                             "exact (event-driven) law; give the others an eps")
        if any(is_exact(e) for e in elements) and any(is_rigid(e) for e in elements):
            raise ValueError("StructuralSystem.elements: an exact friction damper and rigid "
                             "impacts (Restitution) in one system are not available; give the "
                             "friction law an eps or the impacts a compliant law")
        names = self.element_names
        clash = set(names) & set(structure.dof_names)
        if len(set(names)) != len(names) or clash:
            raise ValueError(f"StructuralSystem.elements: names must be distinct and differ "
                             f"from the degrees of freedom, got {list(names)}")

    # -- layout ----------------------------------------------------------------------
    @property
    def element_names(self) -> tuple:
        names, count = [], {}
        for e in self.elements:
            count[e.kind] = count.get(e.kind, 0) + 1
            names.append(e.name if e.name is not None else f"{e.kind}{count[e.kind]}")
        return tuple(names)

    @property
    def num_coords(self) -> int:
        return self.structure.num_coords

    def _offsets(self):
        off, out = 2 * self.num_coords, []
        for e in self.elements:
            out.append(off)
            off += e.num_states
        return out, off

    @property
    def num_states(self) -> int:
        return self._offsets()[1]

    def slice_of(self, name):
        """The slice of the state holding element ``name``'s states (or ``"q"``, ``"qd"``)."""
        n = self.num_coords
        if name == "q":
            return slice(0, n)
        if name == "qd":
            return slice(n, 2 * n)
        if name not in self.element_names:
            raise ValueError(f"slice_of: unknown {name!r}; known: q, qd, "
                             f"{', '.join(self.element_names)}")
        i = self.element_names.index(name)
        off = self._offsets()[0][i]
        return slice(off, off + self.elements[i].num_states)

    @property
    def state_names(self) -> tuple:
        n = self.num_coords
        names = [f"q{i + 1}" for i in range(n)] + [f"qd{i + 1}" for i in range(n)]
        for nm, e in zip(self.element_names, self.elements):
            names += [f"{nm}.{lab}" for lab in e.state_labels]
        return tuple(names)

    def to_internal(self, y):
        return jnp.asarray(y)       # the integrator works in the public coordinates

    def to_public(self, s):
        return jnp.asarray(s)

    def rest_state(self):
        return jnp.zeros((self.num_states,), dtype=jnp.result_type(float))

    def _dofs(self):
        st = self.structure
        return [(st.dof_index(e.dof), -1 if e.other is None else st.dof_index(e.other))
                for e in self.elements]

    def _used(self):
        """The degrees of freedom the elements attach to (sorted), and each element's pair of
        positions in that list (``-1``: ground)."""
        dofs = self._dofs()
        used = sorted({d for pair in dofs for d in pair if d >= 0})
        return used, [(used.index(ia), used.index(ib) if ib >= 0 else -1) for ia, ib in dofs]

    def _at_elements(self, y):
        """``Φ y`` at the elements' degrees of freedom only (``y`` in the coordinates: ``q``,
        ``q̇`` or ``q̈``): the rows of ``Φ`` nobody reads are never multiplied."""
        used, _ = self._used()
        return self.structure.dof_map[np.asarray(used, dtype=int)] @ y

    def _pieces(self, s):
        n = self.num_coords
        q, qd = s[:n], s[n:2 * n]
        offs, _ = self._offsets()
        zs = [s[o:o + e.num_states] for o, e in zip(offs, self.elements)]
        return q, qd, zs

    @staticmethod
    def _pair(x, ia, ib):
        return jnp.stack([x[ia], x[ib] if ib >= 0 else jnp.zeros_like(x[ia])])

    def _element_views(self, s):
        """Per element ``(x_e, v_e, z_e)``: the displacements and velocities of its two
        degrees of freedom (ground: 0) and its own states."""
        q, qd, zs = self._pieces(s)
        xu, vu = self._at_elements(q), self._at_elements(qd)
        _, pos = self._used()
        return [(self._pair(xu, a, b), self._pair(vu, a, b), z) for (a, b), z in zip(pos, zs)]

    # -- dynamics ----------------------------------------------------------------------
    def _forces(self, views, exact_force=None, skip=None, rigid_forces=None):
        """The elements' forces at their degrees of freedom (a vector over ``_used``) and
        each element's ``aux``; the exact element's friction force is ``exact_force`` when
        given, the rigid impact elements' contact forces ``rigid_forces`` (in the order of
        ``_rigid``); element ``skip`` is left out."""
        used, pos = self._used()
        f = jnp.zeros((len(used),))
        auxes = []
        rigid = self._rigid()
        for i, (e, (a, b), (xe, ve, z)) in enumerate(zip(self.elements, pos, views)):
            if exact_force is not None and i == self._exact_index():
                fe, aux = e.evaluate_mode(xe, ve, z, exact_force)
            elif rigid_forces is not None and i in rigid:
                fe, aux = e.evaluate_force(xe, ve, z, rigid_forces[rigid.index(i)])
            else:
                fe, aux = e.evaluate(xe, ve, z)
            auxes.append(aux)
            if i == skip:
                continue
            f = f.at[a].add(fe[0])
            if b >= 0:
                f = f.at[b].add(fe[1])
        return f, auxes

    def coordinate_load(self):
        """The load per unit ``F`` in the structure's coordinates: ``Φᵀ load`` [N], or
        ``-M_q r_q`` [kg] under a base excitation."""
        if self.base_excited:
            return -self.load.participation
        return self.load @ self.structure.dof_map

    def _support_at(self, idx, f_ext):
        """The support's acceleration ``r a_g`` at the degrees of freedom ``idx`` (zero
        unless base-excited)."""
        if not self.base_excited:
            return jnp.zeros((len(idx),))
        return self.load.influence[np.asarray(idx, dtype=int)] * f_ext

    def _accelerations(self, s, f_used, f_ext):
        """``q̈`` under the element forces ``f_used`` (at ``_used``) and the load ``F = f_ext``."""
        st = self.structure
        q, qd, _ = self._pieces(s)
        used, _ = self._used()
        rhs = (st.dof_map[np.asarray(used, dtype=int)].T @ f_used
               + self.coordinate_load() * f_ext)
        if self.diagonal:
            return jnp.diagonal(self.mass_inverse) * (
                rhs - jnp.diagonal(st.damping) * qd - jnp.diagonal(st.stiffness) * q)
        return self.mass_inverse @ (rhs - st.damping @ qd - st.stiffness @ q)

    def _rate(self, s, f_ext, exact_force=None, stuck=None, rigid_forces=None):
        """d/dt of ``s`` under the external force ``F = f_ext`` [N] (the exact element's
        friction force given, its sliding coordinates frozen when ``stuck``; the rigid
        impact elements' contact forces given)."""
        views = self._element_views(s)
        f, auxes = self._forces(views, exact_force, rigid_forces=rigid_forces)
        qdd = self._accelerations(s, f, f_ext)
        used, pos = self._used()
        # absolute accelerations: an element's own mass feels the support's too
        au = self._at_elements(qdd) + self._support_at(used, f_ext)
        rates = []
        for i, (e, (a, b), (xe, ve, z), aux) in enumerate(zip(self.elements, pos, views,
                                                               auxes)):
            r = e.state_rate(xe, ve, self._pair(au, a, b), z, aux)
            if stuck is not None and i == self._exact_index():
                r = jnp.where(stuck, e.stuck_rate(r), r)
            rates.append(r)
        n = self.num_coords
        return jnp.concatenate([s[n:2 * n], qdd, *rates])

    # -- exact stick–slip of one friction damper (modes 0 stick, ±1 slip with sign(V)) -----
    def _exact_index(self):
        idx = [i for i, e in enumerate(self.elements) if is_exact(e)]
        return idx[0] if idx else -1

    @property
    def hybrid(self) -> bool:
        return self._exact_index() >= 0 or bool(self._rigid())

    @property
    def affine_modes(self) -> bool:
        # a linear structure with rigid impact elements (no force in flight; held elements'
        # forces from linear constraints) and otherwise linear elements only
        return bool(self._rigid()) and all(is_rigid(e) or is_linear(e) for e in self.elements)

    def prepared(self):
        """This system with its rigid impact elements' matrices (``ContactMatrices``)
        computed once, for one hybrid integration: every switch, jump and mode rate then
        reads them instead of evaluating the elements again (the same values; far less to
        trace).  ``self`` without rigid elements or when already prepared."""
        if not self._rigid() or self.contact_matrices is not None:
            return self
        cm = ContactMatrices.of(self)
        return eqx.tree_at(lambda s: s.contact_matrices, self, cm, is_leaf=lambda x: x is None)

    def mode_of(self, t, s, forcing):
        if self._rigid():
            return self._rigid_mode_of(t, s, forcing)
        return self._friction_mode_of(t, s, forcing)

    def mode_rate(self, t, s, forcing, mode):
        if self._rigid():
            return self._rigid_rate(t, s, forcing, mode)[0]
        return self._friction_mode_rate(t, s, forcing, mode)

    def switch_function(self, t, s, forcing, mode):
        if self._rigid():
            g = self._rigid_switches(t, s, forcing, mode)
            # the largest, picked by index (jnp.max's derivative divides by the count of
            # ties: NaN tangents in the lanes of a vmapped event location without an event)
            return g[jnp.argmax(g)]
        return self._friction_switch(t, s, forcing, mode)

    def next_mode(self, t, s, forcing, mode):
        if self._rigid():
            return self._rigid_next(t, s, forcing, mode)
        return self._friction_next(t, s, forcing, mode)

    # -- rigid impacts (Restitution in ImpactDamper and Contact elements): per element, 0
    # free flight, ±1 held against its wall on that side of its normal coordinate r; the
    # contact forces of the held elements from their constraints r̈ = 0 (the Delassus
    # matrix W = ∂r̈/∂λ = G M⁻¹ Gᵀ + 1/m), the impulses of an impact from the same W ---------
    def _rigid(self):
        return [i for i, e in enumerate(self.elements) if is_rigid(e)]

    def _rigid_elements(self):
        return [self.elements[i] for i in self._rigid()]

    def _rigid_gaps(self):
        return jnp.stack([e.gap for e in self._rigid_elements()])

    def _two_sided(self):
        return np.array([e.two_sided for e in self._rigid_elements()])

    def _normals(self, s):
        """Per rigid element, its normal coordinate ``r`` [m] and rate ``ṙ`` [m/s]."""
        if self.contact_matrices is not None:
            return self.contact_matrices.Gx @ s, self.contact_matrices.Gv @ s
        views = self._element_views(s)
        rs = [self.elements[i].normal(*views[i]) for i in self._rigid()]
        return jnp.stack([r for r, _ in rs]), jnp.stack([rd for _, rd in rs])

    def _normal_rates(self, s, ds):
        """``ṙ`` of the rigid elements, differentiated along ``ds`` (``r̈`` when ``ds`` is the
        rate; linear in ``ds``)."""
        if self.contact_matrices is not None:
            return self.contact_matrices.Gv @ ds
        return jax.jvp(lambda y: self._normals(y)[1], (s,), (ds,))[1]

    def _rigid_response(self, t, s, forcing):
        """``(rate at zero contact force, ∂rate/∂forces, r̈ at zero force, W = ∂r̈/∂forces)``:
        the rate is affine in the rigid elements' contact forces."""
        f_ext = forcing(t)
        k = len(self._rigid())
        cm = self.contact_matrices
        if cm is not None:
            r0 = (cm.rate_at_rest + cm.A @ s + cm.b * f_ext if cm.A is not None
                  else self._rate(s, f_ext, rigid_forces=jnp.zeros((k,), s.dtype)))
            return r0, cm.R, cm.Gv @ r0, cm.W
        rate = lambda lam: self._rate(s, f_ext, rigid_forces=lam)  # noqa: E731
        # both maps are linearized once (one trace each) and applied to every direction
        r0, in_forces = jax.linearize(rate, jnp.zeros((k,), s.dtype))
        R = jax.vmap(in_forces, out_axes=1)(jnp.eye(k, dtype=s.dtype))
        _, normal_rate = jax.linearize(lambda y: self._normals(y)[1], s)
        a0 = normal_rate(r0)
        W = jax.vmap(normal_rate, in_axes=1, out_axes=1)(R)
        return r0, R, a0, W

    def _held(self, rate, mode):
        """``rate`` with the held elements' own relative coordinates frozen."""
        offs = self._offsets()[0]
        for k, i in enumerate(self._rigid()):
            e, o = self.elements[i], offs[i]
            if e.num_states:
                part = rate[o:o + e.num_states]
                rate = rate.at[o:o + e.num_states].set(jnp.where(mode[k] != 0, e.held_rate(part),
                                                                 part))
        return rate

    def _rigid_rate(self, t, s, forcing, mode):
        """The rate in ``mode`` and the held elements' contact forces [N] (0 when free)."""
        r0, R, a0, W = self._rigid_response(t, s, forcing)
        held = mode != 0
        both = held[:, None] & held[None, :]
        A = jnp.where(both, W, jnp.eye(W.shape[0], dtype=s.dtype))
        lam = jnp.linalg.solve(A, jnp.where(held, -a0, 0.0))
        return self._held(r0 + R @ lam, mode), lam

    def _rigid_scales(self, forcing):
        """Per rigid element: length [m], velocity [m/s] and force [N] scales (the motion's
        length at its degree of freedom or its gap; ``× ω``; its mass ``× ω ×`` velocity)."""
        L_dof = self._dof_lengths(forcing)
        dofs = self._dofs()
        hm = self._host_masses()
        L, mass = [], []
        for i in self._rigid():
            e, (ia, _) = self.elements[i], dofs[i]
            L.append(jnp.maximum(L_dof[ia], e.gap))
            mass.append(e.impact_mass(hm[ia]))
        L, mass = jnp.stack(L), jnp.stack(mass)
        v = L * forcing.omega
        return L, v, jnp.maximum(mass * forcing.omega * v, 1e-300)

    def _sides(self, r):
        return jnp.where(self._two_sided() & (r < 0), -1, 1)

    def _rigid_switches(self, t, s, forcing, mode):
        r, _ = self._normals(s)
        _, lam = self._rigid_rate(t, s, forcing, mode)
        L, _, f_ref = self._rigid_scales(forcing)
        # free: the nearer wall's penetration over the length scale; held against the wall
        # on side ±1: its pull -mode·λ over the force scale
        reach = jnp.where(self._two_sided(), jnp.abs(r), r)
        return jnp.where(mode == 0, (reach - self._rigid_gaps()) / L, -mode * lam / f_ref)

    def _rigid_mode_of(self, t, s, forcing):
        r, rd = self._normals(s)
        side = self._sides(r)
        _, v_ref, _ = self._rigid_scales(forcing)
        _, _, a0, _ = self._rigid_response(t, s, forcing)
        at_wall = side * r >= self._rigid_gaps() - STICK_TOLERANCE * self._rigid_scales(
            forcing)[0]
        slow = jnp.abs(rd) <= STICK_TOLERANCE * v_ref
        pressed = side * a0 > 0
        return jnp.where(at_wall & slow & pressed, side, 0)

    def _rigid_fired(self, t, s, forcing, mode):
        """The rigid element whose switch fired (the largest) and the side of its wall."""
        g = self._rigid_switches(t, s, forcing, mode)
        k = jnp.argmax(g)
        r, _ = self._normals(s)
        return k, self._sides(r)[k]

    def _on_wall(self, s, k, side):
        """``s`` with element ``k``'s own relative coordinate put on its wall (elements that
        keep one)."""
        offs = self._offsets()[0]
        for j, i in enumerate(self._rigid()):
            e, o = self.elements[i], offs[i]
            if e.num_states:
                z = s[o:o + e.num_states]
                s = s.at[o:o + e.num_states].set(jnp.where(k == j, e.on_wall(z, side), z))
        return s

    def _rigid_next(self, t, s, forcing, mode):
        k, side = self._rigid_fired(t, s, forcing, mode)
        _, R, _, W = self._rigid_response(t, s, forcing)
        _, rd = self._normals(s)
        held = mode != 0
        hit = jnp.arange(W.shape[0]) == k

        def impulse(e):
            # the held elements stay held (their normal velocity unchanged), the one hit
            # leaves at -e times its approach velocity; every velocity of the state (the
            # structure's, each absorber's relative one) jumps by R P
            rows = held | hit
            A = jnp.where(rows[:, None] & rows[None, :], W, jnp.eye(W.shape[0], dtype=s.dtype))
            P = jnp.linalg.solve(A, jnp.where(hit, -(1.0 + e) * rd, 0.0))
            return self._on_wall(s + R @ P, k, side)

        laws = [e.contact for e in self._rigid_elements()]
        e_k = jnp.stack([law.e for law in laws])[k]
        bounced, plastic = impulse(e_k), impulse(0.0)
        r_free, _ = self._rigid_rate(t, bounced, forcing, jnp.where(hit, 0, mode))
        a_rel = self._normal_rates(bounced, r_free)[k]
        w_after = self._normals(bounced)[1][k]
        length = self._rigid_scales(forcing)[0][k]
        settles = jnp.stack([law.settles(w_after, a_rel, forcing.period, length)
                             for law in laws])[k]
        stick = (side * a_rel > 0) & settles
        impact = mode[k] == 0
        new_mode = jnp.where(hit, jnp.where(impact & stick, side, 0), mode)
        return new_mode, jnp.where(impact, jnp.where(stick, plastic, bounced), s)

    def event_step_limit(self, forcing):
        # rigid walls: an excursion missed within one step is at most ~(ωh)²/8 of the
        # motion's length deep (h = T / RIGID_STEPS_PER_PERIOD: ~7.5e-5 at 256)
        return forcing.period / RIGID_STEPS_PER_PERIOD if self._rigid() else None

    def admissible_state(self, t, s, forcing):
        if not self._rigid():
            return s
        # the deepest element beyond its wall and moving into it: back along the free
        # flight to the wall, its impact, forward again (first order, as ImpactAbsorber);
        # an element beyond its wall moving out of it is put back on it (its own
        # coordinate; a contact between degrees of freedom is left to the flight)
        r, rd = self._normals(s)
        side = self._sides(r)
        pen = side * r - self._rigid_gaps()
        entering = side * rd > 0
        dts = jnp.where((pen > 0) & entering, pen / jnp.where(entering, jnp.abs(rd), 1.0), 0.0)
        k = jnp.argmax(dts)
        dt = dts[k]
        free = jnp.zeros(r.shape, int)
        at_wall = s - self._rigid_rate(t, s, forcing, free)[0] * dt
        mode, after = self._rigid_next(t, at_wall, forcing, free)
        through = after + self._rigid_rate(t, after, forcing, mode)[0] * dt
        on_wall = s
        for j in range(r.shape[0]):
            on_wall = jnp.where((pen[j] > 0) & ~entering[j],
                                self._on_wall(on_wall, j, side[j]), on_wall)
        return jnp.where(dt > 0, through, on_wall)

    def event_is_impact(self, t, s, forcing, mode):
        if not self._rigid():
            return jnp.zeros((), bool)
        k, side = self._rigid_fired(t, s, forcing, mode)
        _, rd = self._normals(s)
        _, v_ref, _ = self._rigid_scales(forcing)
        return (mode[k] == 0) & (side * rd[k] > STICK_TOLERANCE * v_ref[k])

    def in_contact(self, mode):
        if not self._rigid():
            return jnp.zeros((), bool)
        return jnp.any(mode != 0)

    def _exact(self, s):
        i = self._exact_index()
        e = self.elements[i]
        off = self._offsets()[0][i]
        return i, e, s[off:off + e.num_states], self._dofs()[i][0]

    def holding_force(self, t, s, forcing):
        """Friction force [N] that keeps the exact damper stuck to its host."""
        i, e, z, ia = self._exact(s)
        f_ext = forcing(t)
        f, _ = self._forces(self._element_views(s), exact_force=jnp.zeros(()), skip=i)
        phi = self.structure.dof_map[ia]
        a0 = phi @ self._accelerations(s, f, f_ext) + self._support_at([ia], f_ext)[0]
        return e.holding_friction(z, a0, phi @ self.mass_inverse @ phi)

    def _holding_mode(self, t, s, forcing):
        _, e, _, _ = self._exact(s)
        f = self.holding_force(t, s, forcing)
        stuck = jnp.abs(f) <= e.breakaway()
        return jnp.where(stuck, 0, jnp.where(f > 0, 1, -1))

    def _friction_mode_of(self, t, s, forcing):
        _, e, z, _ = self._exact(s)
        V = e.slip_velocity(z)
        return jnp.where(V > 0, 1, jnp.where(V < 0, -1, self._holding_mode(t, s, forcing)))

    def _friction_mode_rate(self, t, s, forcing, mode):
        _, e, z, _ = self._exact(s)
        slip = mode * e.kinetic(jnp.abs(e.slip_velocity(z)))
        fnl = jnp.where(mode == 0, self.holding_force(t, s, forcing), slip)
        return self._rate(s, forcing(t), exact_force=fnl, stuck=mode == 0)

    def _friction_switch(self, t, s, forcing, mode):
        # dimensionless as in FrictionAbsorber: the holding force over the breakaway limit
        # plus the inertia force m ω² L of the host's motion scale; the sliding velocity
        # over the host's velocity scale L ω (rising through 0 when the slip stops)
        i, e, z, _ = self._exact(s)
        cap = e.breakaway()
        f = self.holding_force(t, s, forcing)
        scale = self.state_scale(forcing)[self._offsets()[0][i] + 1]     # L ω at the host
        f_ref = cap + e.inertia() * forcing.omega * scale
        return jnp.where(mode == 0, (jnp.abs(f) - cap) / jnp.maximum(f_ref, 1e-300),
                         -mode * e.slip_velocity(z) / jnp.maximum(scale, 1e-30))

    def _friction_next(self, t, s, forcing, mode):
        i, e, z, _ = self._exact(s)
        off = self._offsets()[0][i]
        z = jnp.where(mode == 0, z, e.stop_slip(z))
        s = s.at[off:off + e.num_states].set(z)
        f = self.holding_force(t, s, forcing)
        new = jnp.where(mode == 0, jnp.where(f > 0, 1, -1), self._holding_mode(t, s, forcing))
        return new, s

    def vector_field(self, t, s, forcing):
        return self._rate(s, forcing(t))

    def condensation(self):
        """A ``Condensation`` where every element is a force law of its degrees of freedom
        (no states of its own, no exact event-driven law; none at all on a linear
        structure), else ``None``."""
        if self.hybrid or any(e.num_states for e in self.elements):
            return None
        return Condensation(self)

    def element_forces(self, s):
        """Force [N] each element applies to its (first) degree of freedom."""
        out = [e.evaluate(xe, ve, z)[0][0]
               for e, (xe, ve, z) in zip(self.elements, self._element_views(s))]
        return jnp.stack(out) if out else jnp.zeros((0,), s.dtype)

    def trajectory_fields(self, ts, s, forcing):
        return {"coupling_force": jax.vmap(self.element_forces)(s)}

    def mechanical_energy(self, s):
        st = self.structure
        q, qd, _ = self._pieces(s)
        e = 0.5 * qd @ st.mass @ qd + 0.5 * q @ st.stiffness @ q
        for el, (xe, ve, z) in zip(self.elements, self._element_views(s)):
            e = e + el.energy(xe, ve, z)
        return e

    def power(self, t, s, forcing):
        """``(input power, dissipated power)`` [W]; under a base excitation the input is the
        power of the inertia loads ``-M r a_g`` and ``-m r a_g`` in the support's frame."""
        st = self.structure
        _, qd, _ = self._pieces(s)
        diss = qd @ st.damping @ qd
        f_ext = forcing(t)
        pin = f_ext * (self.coordinate_load() @ qd)
        views = self._element_views(s)
        for el, (xe, ve, z) in zip(self.elements, views):
            diss = diss + el.dissipation(xe, ve, z)
        if self.base_excited:
            for (ia, _), el, (xe, ve, z) in zip(self._dofs(), self.elements, views):
                pin = pin - f_ext * self.load.influence[ia] * el.momentum(xe, ve, z)
        return pin, diss

    # -- scales, guesses, solver hints ---------------------------------------------------
    def _host_masses(self):
        """Effective mass of the structure at each degree of freedom, ``1 / (Φ_i M⁻¹ Φ_iᵀ)``."""
        Phi = self.structure.dof_map
        return 1.0 / jnp.maximum(jnp.einsum("ij,jk,ik->i", Phi, self.mass_inverse, Phi),
                                 1e-300)

    def _length_floor(self):
        floors = [e.length_floor() for e in self.elements]
        return jnp.max(jnp.stack(floors)) if floors else jnp.zeros(())

    def _coordinate_lengths(self, forcing):
        """The length scale of each coordinate: ``F0 |Φᵀ b|_∞ / (K_jj + ω² M_jj)``, at least
        the largest gap (in the coordinate's units)."""
        st = self.structure
        w = forcing.omega
        g = forcing.amplitude * jnp.max(jnp.abs(self.coordinate_load()))
        Lc = g / (jnp.diag(st.stiffness) + w**2 * jnp.diag(st.mass))
        reach = jnp.maximum(jnp.max(jnp.abs(st.dof_map), axis=0), 1e-300)
        return jnp.maximum(jnp.maximum(Lc, self._length_floor() / reach), 1e-12)

    def _dof_lengths(self, forcing):
        """The length scale [m] at each degree of freedom."""
        return jnp.abs(self.structure.dof_map) @ self._coordinate_lengths(forcing)

    def state_scale(self, forcing):
        """Coordinates: ``F0 |Φᵀ b|_∞ / (K_jj + ω² M_jj)``, at least the largest gap (in the
        coordinate's units, ``/ max_i |Φ_ij|``); velocities ``× ω``; each element's states
        from the resulting length at its degree of freedom."""
        w = forcing.omega
        Lc = self._coordinate_lengths(forcing)
        Ldof = self._dof_lengths(forcing)
        parts = [Lc, Lc * w]
        for e, (ia, _) in zip(self.elements, self._dofs()):
            parts.append(e.state_scale(Ldof[ia], w))
        return jnp.concatenate(parts)

    @property
    def linear(self) -> bool:
        return not self.hybrid and all(is_linear(e) for e in self.elements)

    def harmonic_response(self, forcing):
        """``(orders, X)``: the response ``s(t) = Im Σ_j X_j e^{i k_j ω t}`` of this linear
        system (``linear``) to the harmonics ``F = Im Σ_j c_j e^{i k_j ω t}`` of
        ``forcing``: ``X_j = (i k_j ω I - A)⁻¹ b c_j``, ``A = ∂ṡ/∂s`` and ``b = ∂ṡ/∂F``
        (exact: the rate is linear).  Differentiable in the system's parameters and ω."""
        if not self.linear:
            raise not_linear(self)
        A, b = jax.jacfwd(self._rate, argnums=(0, 1))(self.rest_state(), 0.0)
        orders, coefficients = forcing.harmonics()
        Z = (1j * forcing.omega * jnp.asarray(orders, dtype=float)[:, None, None]
             * jnp.eye(A.shape[0]) - A)
        return orders, jnp.linalg.solve(Z, (jnp.asarray(coefficients, dtype=complex)[:, None]
                                            * b)[..., None])[..., 0]

    @eqx.filter_jit
    def linear_guess(self, forcing):
        """The periodic response of the system linearised at rest (open gaps, floating
        impact absorbers, smoothed friction at its initial slope) at ``t = 0``: the
        responses to the forcing's harmonics (``forcing.harmonics()``) superposed.  A
        harmonic the linearisation cannot respond to (a floating absorber under a constant
        load) is left out.  One compiled program (not op by op: a first call in a new
        process would compile every operation of the rate's Jacobian on its own)."""
        rest = self.rest_state()
        A = jax.jacfwd(self._rate)(rest, 0.0)
        b = jax.jacfwd(self._rate, argnums=1)(rest, 0.0)
        n = A.shape[0]
        orders, coefficients = forcing.harmonics()

        def response(w, c):
            # c e^{iwt} -> X e^{iwt}; the forcing is Im(Σ c e^{iwt})
            X = jnp.linalg.solve(1j * w * jnp.eye(n) - A, (b * c).astype(complex))
            return finite_or_zero(jnp.imag(X))

        w = forcing.omega * jnp.asarray(orders, dtype=float)
        return jnp.sum(jax.vmap(response)(w, jnp.asarray(coefficients, dtype=complex)), axis=0)

    def stiffness_rate(self):
        st = self.structure
        MK = self.mass_inverse @ st.stiffness
        MC = self.mass_inverse @ st.damping
        rate = jnp.maximum(jnp.sqrt(jnp.linalg.norm(MK, 2)), jnp.linalg.norm(MC, 2))
        hm = self._host_masses()
        for e, (ia, _) in zip(self.elements, self._dofs()):
            rate = jnp.maximum(rate, e.stiffness_rate(hm[ia]))
        return rate

    def oscillation_rate(self):
        hm = self._host_masses()
        rates = [e.oscillation_rate(hm[ia]) for e, (ia, _) in zip(self.elements, self._dofs())]
        return jnp.max(jnp.stack(rates)) if rates else jnp.zeros(())

    # -- what is measured ------------------------------------------------------------------
    @property
    def force_names(self) -> tuple:
        """The elements' names: a trajectory's coupling force has one column each."""
        return self.element_names

    def signals(self) -> units.Signals:
        """The observable as the weighted sum of degrees of freedom it is (``"floor3"``,
        ``"floor3 - floor2"``) in their unit, each absorber's output in its host's unit,
        the absorber stroke(s) by name, the state components (``q<i>`` in the degrees of
        freedom's units where the coordinates are the degrees of freedom) and the
        parameters."""
        sdofs = tuple(self.structure.dof_names)
        dof_units = [units.dof_unit(n) for n in sdofs]
        hosts = {nm: e.dof for nm, e, _ in self._absorbers()}
        dofs = tuple((n, units.dof_unit(hosts.get(n, n))) for n in self.output_names)
        w = np.asarray(self.observe, dtype=float)
        nz = np.flatnonzero(w)
        observable = units.weighted_name([sdofs[i] for i in nz], w[nz]) if nz.size else "0"
        strokes = [f"{nm} - {host}" for nm, host in hosts.items()]
        stroke = (strokes[0] if len(strokes) == 1
                  else "largest absorber stroke" if strokes else "absorber stroke (none)")
        dm = np.asarray(self.structure.dof_map)
        identity = dm.shape[0] == dm.shape[1] and np.array_equal(dm, np.eye(dm.shape[0]))
        states = tuple((n, units.state_unit(n, dof_units, identity)) for n in self.state_names)
        return units.Signals(observable=observable,
                             observable_unit=units.common_unit([dof_units[i] for i in nz]),
                             stroke=stroke, dofs=dofs, states=states,
                             parameters=units.parameter_units(self))

    def _absorbers(self):
        return [(nm, e, o) for nm, e, o in zip(self.element_names, self.elements,
                                               self._offsets()[0]) if e.num_strokes]

    @property
    def output_names(self) -> tuple:
        """The structure's degrees of freedom, then each absorber's (absolute) position."""
        return tuple(self.structure.dof_names) + tuple(nm for nm, _, _ in self._absorbers())

    def outputs(self, s):
        x = self.structure.dof_map @ s[:self.num_coords]
        hosts = [x[self.structure.dof_index(e.dof)] + e.strokes(s[o:o + e.num_states])[0]
                 for _, e, o in self._absorbers()]
        return jnp.concatenate([x, jnp.stack(hosts)]) if hosts else x

    def observable(self, s):
        return self.observe @ (self.structure.dof_map @ s[:self.num_coords])

    def strokes(self, s):
        parts = [e.strokes(s[o:o + e.num_states]) for _, e, o in self._absorbers()]
        return jnp.concatenate(parts) if parts else jnp.zeros((0,), s.dtype)

    def penetrations(self, s):
        parts = [e.penetrations(xe, ve, z)
                 for e, (xe, ve, z) in zip(self.elements, self._element_views(s))]
        return jnp.concatenate(parts) if parts else jnp.zeros((0,), s.dtype)

    def floating_pairs(self, stroke_max):
        counts = [e.floats(stroke_max[i:i + 1]) for i, (_, e, _) in
                  enumerate(self._absorbers())]
        return sum(counts) if counts else jnp.zeros((), int)

    # -- parameters ------------------------------------------------------------------------
    def parameter_path(self, name: str) -> str:
        head, _, field = name.partition(".")
        if head in self.element_names and field:
            i = self.element_names.index(head)
            return f"elements.{i}." + self.elements[i].aliases().get(field, field)
        return name

    def parameter_names(self) -> list:
        return [f"{nm}.{p}" for nm, e in zip(self.element_names, self.elements)
                for p in e.parameter_names()]


class ContactMatrices(eqx.Module):
    r"""A structure's rigid impact elements as matrices (``StructuralSystem.prepared``).

    With the contact forces ``λ`` [N] of the ``k`` rigid elements and ``F`` the load's
    value, the structure's rate is affine in ``λ``, ``ṡ = r_0(s, F) + R λ``; the normal
    coordinates and their rates are linear in the state, ``r = G_x s`` [m] and ``ṙ = G_v s``
    [m/s]; so the normal accelerations are ``r̈ = G_v r_0 + W λ`` with the Delassus matrix
    ``W = G_v R`` [m/s²/N].  ``R``, ``G_x``, ``G_v`` and ``W`` do not depend on the state (a
    linear structure's constant mass matrix).  Where every element is rigid or linear
    (``affine_modes``), ``r_0 = d + A s + b F`` as well.

    Fields: ``R`` (n×k), ``Gx``, ``Gv`` (k×n), ``W`` (k×k); ``A`` (n×n), ``b`` (n) and
    ``rate_at_rest`` ``d`` (n) where affine, else ``None``."""

    R: jax.Array
    Gx: jax.Array
    Gv: jax.Array
    W: jax.Array
    A: jax.Array | None
    b: jax.Array | None
    rate_at_rest: jax.Array | None

    @classmethod
    def of(cls, system):
        """The matrices of ``system``'s rigid elements: its rate linearized once in ``(s, F,
        λ)`` (its value at rest with it) and its normals differentiated in ``s``."""
        n, k = system.num_states, len(system._rigid())
        dtype = jnp.result_type(float)

        def rate(v):
            return system._rate(v[:n], v[n], rigid_forces=v[n + 1:])

        v0 = jnp.zeros((n + 1 + k,), dtype)
        d, tangent = jax.linearize(rate, v0)        # one trace: the value and the map
        J = jax.vmap(tangent, out_axes=1)(jnp.eye(n + 1 + k, dtype=dtype))
        G = jax.jacfwd(lambda s: jnp.concatenate(system._normals(s)))(jnp.zeros((n,), dtype))
        R, Gx, Gv = J[:, n + 1:], G[:k], G[k:]
        if system.affine_modes:
            A, b = J[:, :n], J[:, n]
        else:
            A = b = d = None
        return cls(R=R, Gx=Gx, Gv=Gv, W=Gv @ R, A=A, b=b, rate_at_rest=d)


class Condensation(eqx.Module):
    r"""A structure whose nonlinearity is a set of force laws at a few degrees of freedom
    ``u`` (the elements' degrees of freedom), seen from them:

    $$M\ddot q + C\dot q + K q = \Phi_u^T f(x_u, \dot x_u) + l\,F(t),\qquad x_u = \Phi_u q.$$

    At a harmonic ``Ω = kω`` (complex amplitudes, ``x = Re(X e^{iΩt})``) the linear part is
    exact: ``Q = Z(Ω)^{-1}(Φ_uᵀ F_f + l F)`` (``responses``), ``Z(Ω) = K - Ω² M + iΩ C``, so
    ``X_u = G(Ω) F_f + g(Ω) F`` with the receptance ``G = Φ_u Z⁻¹ Φ_uᵀ`` between the
    nonlinear degrees of freedom and ``g = Φ_u Z⁻¹ l`` the load's response there: harmonic
    balance needs the harmonics of ``x_u`` only (exact condensation, not a reduction)."""

    system: StructuralSystem

    def forces(self, x, v):
        """The elements' forces [N] at the degrees of freedom ``u`` (``_used`` order) from
        displacements ``x`` and velocities ``v`` there."""
        _, pos = self.system._used()
        empty = jnp.zeros((0,), jnp.result_type(x))
        views = [(self.system._pair(x, a, b), self.system._pair(v, a, b), empty)
                 for a, b in pos]
        return self.system._forces(views)[0]

    def _solve(self, omega, rhs):
        st = self.system.structure
        Z = st.dynamic_stiffness(omega)
        if self.system.diagonal:
            return rhs / jnp.diagonal(Z)[:, None]
        return jnp.linalg.solve(Z, rhs)

    @property
    def dof_map(self):
        """``Φ_u`` ``(u, n_coords)``: the rows of the structure's output map at the degrees of
        freedom ``u``."""
        used, _ = self.system._used()
        return self.system.structure.dof_map[np.asarray(used, dtype=int)]

    def responses(self, omega):
        """The coordinates' complex amplitudes at ``omega`` [rad/s] under unit forces at
        each degree of freedom of ``u`` and under a unit load ``F``: ``Z⁻¹ [Φ_uᵀ, l]``
        ``(n_coords, u + 1)``; ``at_dofs`` of it gives the receptances ``G`` and ``g``."""
        rhs = jnp.concatenate([self.dof_map.T, self.system.coordinate_load()[:, None]],
                              axis=1).astype(complex)
        return self._solve(omega, rhs)

    def at_dofs(self, s):
        """The displacements at the degrees of freedom ``u`` of internal state ``s``, or of
        coordinate amplitudes ``s`` ``(n_coords, …)``: ``Φ_u s[:n_coords]``."""
        return self.dof_map @ s[:self.system.num_coords]

    def to_state(self, q, qd):
        """The system's internal state from coordinates and their rates."""
        return jnp.concatenate([q, qd])

    @property
    def size(self) -> int:
        """The number of nonlinear degrees of freedom ``u``."""
        return len(self.system._used()[0])
