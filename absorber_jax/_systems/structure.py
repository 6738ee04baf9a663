"""Linear structures: the primary of a multi-degree-of-freedom scene.

A ``LinearStructure`` is a linear second-order model in its own coordinates ``q``,

$$M_q\\ddot q + C_q\\dot q + K_q q = \\Phi^T f(t),\\qquad x = \\Phi q,$$

observed and loaded at named physical degrees of freedom ``x`` through the output map
``Φ`` (``n_dofs × n_coords``).  A matrix model has ``q = x`` and ``Φ = I``; a modal model has
modal coordinates, ``M_q = I``, ``C_q = diag(2 ζ_r ω_r)``, ``K_q = diag(ω_r²)`` and ``Φ`` the
mass-normalised mode shapes at the degrees of freedom that matter.  Elements attached at a
degree of freedom read ``x = Φ q`` and push back with ``Φ^T f``, so both models carry the same
elements.  Units: SI (kg, N/m, N s/m, rad/s); degrees of freedom may be rotations (a beam's
slopes, [rad], with moments [N m]).

Constructors: ``structure_from_matrices`` (damping as a matrix, Rayleigh coefficients or
modal damping ratios), ``structure_from_modes``, ``shear_building``,
``cantilever_beam``; ``LinearStructure.modal`` reduces a structure to its modes
(``LinearStructure.modal_participation``: their participation in a support motion),
``LinearStructure.with_tuned_mass_dampers`` adds linear absorbers as coordinates of
their own.  ``LinearStructure.receptance`` is the closed-form complex FRF
``Φ (K_q - ω² M_q + iω C_q)^{-1} Φ^T``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp

from .._core.checks import as_float, check_scalar

# models up to this many degrees of freedom may be given as sparse matrices to
# ``structure_from_matrices`` (converted to dense); larger ones are reduced first
# (``craig_bampton``)
DENSE_LIMIT = 4000


def _matrix(owner, name, a, shape=None):
    a = dense_if_small(owner, name, a)
    try:
        arr = np.asarray(a, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{owner}.{name} must be a real matrix, got {a!r}") from e
    if arr.ndim != 2 or (shape is not None and arr.shape != shape):
        want = "a square matrix" if shape is None else f"shape {shape}"
        raise ValueError(f"{owner}.{name} must be {want}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{owner}.{name} must be finite")
    return arr


def dense_if_small(owner, name, a):
    """A scipy sparse matrix of at most ``DENSE_LIMIT`` rows as a dense array (ValueError
    pointing to ``craig_bampton`` for larger ones); other inputs unchanged."""
    if not sp.issparse(a):
        return a
    if a.shape[0] > DENSE_LIMIT:
        raise ValueError(f"{owner}.{name}: a sparse matrix of size {a.shape[0]} is too large "
                         f"for a dense model (at most {DENSE_LIMIT}); reduce it with "
                         "aj.craig_bampton onto the degrees of freedom the elements and loads "
                         "use")
    return a.toarray()


def _symmetric(owner, name, a, *, definite):
    a = _matrix(owner, name, a)
    if a.shape[0] != a.shape[1]:
        raise ValueError(f"{owner}.{name} must be square, got shape {a.shape}")
    scale = max(np.max(np.abs(a)), 1e-300)
    if np.max(np.abs(a - a.T)) > 1e-10 * scale:
        raise ValueError(f"{owner}.{name} must be symmetric")
    ev = np.linalg.eigvalsh(0.5 * (a + a.T))
    if definite and ev.min() <= 1e-12 * scale:
        raise ValueError(f"{owner}.{name} must be positive definite (smallest eigenvalue "
                         f"{ev.min():.3g})")
    if not definite and ev.min() < -1e-10 * scale:
        raise ValueError(f"{owner}.{name} must be positive semi-definite (smallest "
                         f"eigenvalue {ev.min():.3g})")
    return 0.5 * (a + a.T)


def _names(owner, dof_names, n, prefix="x"):
    if dof_names is None:
        return tuple(f"{prefix}{i + 1}" for i in range(n))
    names = tuple(str(s) for s in dof_names)
    if len(names) != n or len(set(names)) != n:
        raise ValueError(f"{owner}.dof_names must be {n} distinct names, got {dof_names!r}")
    return names


class LinearStructure(eqx.Module):
    r"""A linear structure in coordinates ``q`` observed at named degrees of freedom ``x``:

    $$M_q\ddot q + C_q\dot q + K_q q = \Phi^T f(t),\qquad x = \Phi q,$$

    loaded and observed through the output map ``Φ`` (``n_dofs × n_coords``).  A matrix
    model has ``q = x`` and ``Φ = I``; a modal model has modal coordinates, ``M_q = I``,
    ``C_q = diag(2 ζ_r ω_r)``, ``K_q = diag(ω_r²)`` and ``Φ`` the mass-normalised mode shapes
    at the degrees of freedom that matter.  Elements attached at a degree of freedom read
    ``x = Φ q`` and push back with ``Φ^T f``, so both models carry the same elements.  Units:
    SI (kg, N/m, N s/m, rad/s); degrees of freedom may be rotations (a beam's slopes [rad],
    with moments [N m]).

    Build it with the constructors rather than by hand:
    [`structure_from_matrices`][absorber_jax.structure_from_matrices] (damping as a matrix,
    Rayleigh coefficients or modal damping ratios),
    [`structure_from_modes`][absorber_jax.structure_from_modes],
    [`shear_building`][absorber_jax.shear_building],
    [`cantilever_beam`][absorber_jax.cantilever_beam].

    **Fields**: ``mass``, ``damping``, ``stiffness`` (``n_coords × n_coords``, in the
    coordinates), ``dof_map`` ``Φ`` (``n_dofs × n_coords``), ``dof_names`` (static).
    """

    mass: object = eqx.field(converter=as_float)
    damping: object = eqx.field(converter=as_float)
    stiffness: object = eqx.field(converter=as_float)
    dof_map: object = eqx.field(converter=as_float)
    dof_names: tuple = eqx.field(static=True)

    @property
    def num_coords(self) -> int:
        return self.mass.shape[0]

    @property
    def num_dofs(self) -> int:
        return self.dof_map.shape[0]

    def dof_index(self, dof) -> int:
        """The index of a degree of freedom given by name or index (ValueError otherwise)."""
        if isinstance(dof, str):
            if dof not in self.dof_names:
                raise ValueError(f"dof must be one of {list(self.dof_names)}, got {dof!r}")
            return self.dof_names.index(dof)
        if isinstance(dof, (int, np.integer)) and not isinstance(dof, bool) and (
                -self.num_dofs <= dof < self.num_dofs):
            return int(dof) % self.num_dofs
        raise ValueError(f"dof must be a name in {list(self.dof_names)} or an index in "
                         f"[0, {self.num_dofs}), got {dof!r}")

    def dynamic_stiffness(self, omega):
        """``K_q - ω² M_q + iω C_q`` in the coordinates at ``omega`` [rad/s]."""
        return self.stiffness - omega**2 * self.mass + 1j * omega * self.damping

    def receptance(self, omega):
        """The complex receptance matrix ``H(ω)`` [m/N] between the degrees of freedom:
        the steady displacement amplitudes ``X = H(ω) F`` under a load ``F cos ωt``
        (complex amplitudes, ``x = Re(X e^{iωt})``).  Vectorises over a 1-D ``omega``."""
        omega = jnp.asarray(omega, dtype=float)

        def one(w):
            sol = jnp.linalg.solve(self.dynamic_stiffness(w), self.dof_map.T.astype(complex))
            return self.dof_map @ sol

        return one(omega) if omega.ndim == 0 else jax.vmap(one)(omega.reshape(-1))

    def accelerations(self, q, qdot, f):
        """``q̈`` under the coordinates' state ``(q, q̇)`` and the forces ``f`` [N] at the
        degrees of freedom."""
        rhs = self.dof_map.T @ f - self.damping @ qdot - self.stiffness @ q
        return jnp.linalg.solve(self.mass, rhs)

    def natural_frequencies(self):
        """Undamped natural frequencies [rad/s], ascending."""
        lam, _ = _modes(self.mass, self.stiffness)
        return jnp.sqrt(jnp.maximum(lam, 0.0))

    def modal(self, n_modes=None, *, dofs=None):
        """The modal model of this structure: its lowest ``n_modes`` (default all) modes,
        mass-normalised, observed at ``dofs`` (names or indices; default all).  The modal
        damping matrix is ``Ψ^T C_q Ψ``'s diagonal, exact for classically damped structures
        (Rayleigh, modal damping); its off-diagonal part is dropped."""
        n = self.num_coords if n_modes is None else n_modes
        if not isinstance(n, int) or not 1 <= n <= self.num_coords:
            raise ValueError(f"modal.n_modes must be an integer in [1, {self.num_coords}], "
                             f"got {n_modes!r}")
        idx = list(range(self.num_dofs)) if dofs is None else [self.dof_index(d) for d in dofs]
        lam, psi = _modes(self.mass, self.stiffness)
        psi = psi[:, :n]
        zeta_2w = jnp.diag(psi.T @ self.damping @ psi)
        shapes = (self.dof_map @ psi)[jnp.asarray(idx)]
        return LinearStructure(mass=jnp.eye(n), damping=jnp.diag(zeta_2w),
                               stiffness=jnp.diag(lam[:n]), dof_map=shapes,
                               dof_names=tuple(self.dof_names[i] for i in idx))

    def modal_participation(self, n_modes=None, influence=None):
        """The participation factors ``Γ_r = ψ_rᵀ M_q r_q`` [kg^½] of the lowest ``n_modes``
        modes (default all; normalised and ordered as ``modal`` gives them) for a
        support motion along ``influence`` (``r`` over the degrees of freedom: ``None`` for
        all ones, or a vector; ``Φ r_q = r``, ``Φ`` square): what
        ``BaseExcitation(participation=...)`` needs for ``self.modal(n_modes, ...)``, whose
        modal load under a support acceleration ``a_g`` is ``-Γ a_g``."""
        n = self.num_coords if n_modes is None else n_modes
        if not isinstance(n, int) or not 1 <= n <= self.num_coords:
            raise ValueError(f"modal_participation.n_modes must be an integer in "
                             f"[1, {self.num_coords}], got {n_modes!r}")
        if self.num_dofs != self.num_coords:
            raise ValueError("modal_participation needs a structure observed at as many "
                             "degrees of freedom as it has coordinates (the full model)")
        r = (jnp.ones((self.num_dofs,)) if influence is None
             else jnp.asarray(influence, dtype=float))
        if r.shape != (self.num_dofs,):
            raise ValueError(f"modal_participation.influence must have shape "
                             f"({self.num_dofs},), got {r.shape}")
        _, psi = _modes(self.mass, self.stiffness)
        r_q = jnp.linalg.solve(self.dof_map, r)
        return psi[:, :n].T @ self.mass @ r_q

    def with_tuned_mass_dampers(self, dampers):
        """This structure with linear tuned mass dampers added, each a coordinate (and a
        degree of freedom, named ``tmd1``, ``tmd2``, ...) of its own.

        ``dampers``: a sequence of ``(dof, mass, stiffness, damping)``: a mass [kg] tied by a
        spring [N/m] and a dashpot [N s/m] to the degree of freedom ``dof`` (name or index)."""
        M, C, K, Phi = self.mass, self.damping, self.stiffness, self.dof_map
        names = list(self.dof_names)
        for i, d in enumerate(dampers):
            try:
                dof, m, k, c = d
            except (TypeError, ValueError) as e:
                raise ValueError("with_tuned_mass_dampers: each damper is (dof, mass, "
                                 f"stiffness, damping), got {d!r}") from e
            j = self.dof_index(dof)
            check_scalar("TunedMassDamper", "mass", m, lo=0.0, lo_open=True)
            check_scalar("TunedMassDamper", "stiffness", k, lo=0.0, lo_open=True)
            check_scalar("TunedMassDamper", "damping", c, lo=0.0)
            phi = Phi[j]                               # x_j = phi . q
            nq = M.shape[0]
            # coupling energy k/2 (y - phi q)^2 in the augmented coordinates (q, y)
            b = jnp.concatenate([-phi, jnp.ones(1)])
            grow = lambda A: jnp.pad(A, ((0, 1), (0, 1)))  # noqa: E731
            M = grow(M).at[nq, nq].set(m)
            K = grow(K) + k * jnp.outer(b, b)
            C = grow(C) + c * jnp.outer(b, b)
            Phi = jnp.pad(Phi, ((0, 1), (0, 1))).at[-1, -1].set(1.0)
            name = f"tmd{i + 1}"
            names.append(name if name not in names else f"tmd{i + 1}_{len(names)}")
        return LinearStructure(mass=M, damping=C, stiffness=K, dof_map=Phi,
                               dof_names=tuple(names))


def _modes(M, K):
    """Generalised eigenpairs ``K ψ = λ M ψ``, ``ψ^T M ψ = 1``, ascending ``λ``."""
    L = jnp.linalg.cholesky(M)
    Linv = jnp.linalg.inv(L)
    A = Linv @ K @ Linv.T
    lam, v = jnp.linalg.eigh(0.5 * (A + A.T))
    return lam, Linv.T @ v


def structure_from_matrices(mass, stiffness, *, damping=None, rayleigh=None,
                            modal_damping=None, dof_names=None) -> LinearStructure:
    """A structure from its mass and stiffness matrices [kg, N/m] and one damping model:

    - ``damping``: the damping matrix [N s/m];
    - ``rayleigh``: ``(α, β)``, ``C = α M + β K`` (α [1/s], β [s]);
    - ``modal_damping``: damping ratios ``ζ_r`` of the modes (one per mode, or one for all),
      ``C = M Ψ diag(2 ζ_r ω_r) Ψ^T M`` with mass-normalised modes ``Ψ``;
    - none of them: undamped.
    """
    M = _symmetric("structure", "mass", mass, definite=True)
    K = _symmetric("structure", "stiffness", stiffness, definite=False)
    n = M.shape[0]
    if K.shape != M.shape:
        raise ValueError(f"structure.stiffness must have the mass matrix's shape {M.shape}, "
                         f"got {K.shape}")
    given = [g for g in (damping, rayleigh, modal_damping) if g is not None]
    if len(given) > 1:
        raise ValueError("structure: give at most one of damping, rayleigh, modal_damping")
    if damping is not None:
        C = _symmetric("structure", "damping", damping, definite=False)
        if C.shape != M.shape:
            raise ValueError(f"structure.damping must have shape {M.shape}, got {C.shape}")
    elif rayleigh is not None:
        try:
            alpha, beta = (float(v) for v in rayleigh)
        except (TypeError, ValueError) as e:
            raise ValueError(f"structure.rayleigh must be (alpha, beta), got {rayleigh!r}") from e
        check_scalar("structure", "rayleigh alpha", alpha, lo=0.0)
        check_scalar("structure", "rayleigh beta", beta, lo=0.0)
        C = alpha * M + beta * K
    elif modal_damping is not None:
        z = np.broadcast_to(np.asarray(modal_damping, dtype=float), (n,)) if np.ndim(
            modal_damping) == 0 else np.asarray(modal_damping, dtype=float)
        if z.shape != (n,) or np.any(~np.isfinite(z)) or np.any(z < 0):
            raise ValueError(f"structure.modal_damping must be {n} ratios >= 0 (or one), got "
                             f"{modal_damping!r}")
        lam, psi = (np.asarray(a) for a in _modes(jnp.asarray(M), jnp.asarray(K)))
        w = np.sqrt(np.maximum(lam, 0.0))
        C = M @ psi @ np.diag(2 * z * w) @ psi.T @ M
    else:
        C = np.zeros_like(M)
    return LinearStructure(mass=M, damping=C, stiffness=K, dof_map=np.eye(n),
                           dof_names=_names("structure", dof_names, n))


def structure_from_modes(frequencies, damping_ratios, mode_shapes, *,
                         dof_names=None) -> LinearStructure:
    """A modal model: natural ``frequencies`` [rad/s] (> 0), ``damping_ratios`` (>= 0, one
    per mode or one for all) and mass-normalised ``mode_shapes`` (``n_dofs × n_modes``) at
    the degrees of freedom that matter."""
    w = np.asarray(frequencies, dtype=float).reshape(-1)
    if w.size < 1 or np.any(~np.isfinite(w)) or np.any(w <= 0):
        raise ValueError(f"modes.frequencies must be positive and finite, got {frequencies!r}")
    z = np.broadcast_to(np.asarray(damping_ratios, dtype=float), w.shape) if np.ndim(
        damping_ratios) == 0 else np.asarray(damping_ratios, dtype=float)
    if z.shape != w.shape or np.any(~np.isfinite(z)) or np.any(z < 0):
        raise ValueError(f"modes.damping_ratios must be {w.size} ratios >= 0 (or one), got "
                         f"{damping_ratios!r}")
    phi = _matrix("modes", "mode_shapes", mode_shapes)
    if phi.shape[1] != w.size:
        raise ValueError(f"modes.mode_shapes must have one column per mode ({w.size}), got "
                         f"shape {phi.shape}")
    return LinearStructure(mass=np.eye(w.size), damping=np.diag(2 * z * w),
                           stiffness=np.diag(w**2), dof_map=phi,
                           dof_names=_names("modes", dof_names, phi.shape[0]))


def shear_building(masses, storey_stiffnesses, *, damping=None, rayleigh=None,
                   modal_damping=None) -> LinearStructure:
    """A shear building: floor ``masses`` [kg] (ground floor first) on storeys of lateral
    stiffness ``storey_stiffnesses`` [N/m] (storey ``i`` joins floor ``i`` to the one below,
    storey 1 to the ground).  Degrees of freedom ``floor1 … floorN`` (lateral
    displacements); damping as in
    [`structure_from_matrices`][absorber_jax.structure_from_matrices]."""
    m = np.asarray(masses, dtype=float).reshape(-1)
    k = np.asarray(storey_stiffnesses, dtype=float).reshape(-1)
    if m.size < 1 or np.any(~np.isfinite(m)) or np.any(m <= 0):
        raise ValueError(f"shear_building.masses must be positive, got {masses!r}")
    if k.shape != m.shape or np.any(~np.isfinite(k)) or np.any(k <= 0):
        raise ValueError(f"shear_building.storey_stiffnesses must be {m.size} positive "
                         f"values, got {storey_stiffnesses!r}")
    n = m.size
    K = np.zeros((n, n))
    for i in range(n):
        K[i, i] += k[i]
        if i + 1 < n:
            K[i, i] += k[i + 1]
            K[i, i + 1] = K[i + 1, i] = -k[i + 1]
    return structure_from_matrices(np.diag(m), K, damping=damping, rayleigh=rayleigh,
                                   modal_damping=modal_damping,
                                   dof_names=[f"floor{i + 1}" for i in range(n)])


def cantilever_beam(n_elements, *, length, EI, rho_A, damping=None, rayleigh=None,
                    modal_damping=None) -> LinearStructure:
    """A clamped-free Euler–Bernoulli beam by cubic Hermite finite elements with consistent
    mass: ``length`` [m], bending stiffness ``EI`` [N m²], mass per length ``rho_A``
    [kg/m].  Degrees of freedom ``w1, th1, …, wN, thN`` (deflection [m] and slope [rad] at
    the nodes, the clamp removed; ``wN`` is the tip); damping as in
    [`structure_from_matrices`][absorber_jax.structure_from_matrices]."""
    M, K, names = beam_matrices(n_elements, length=length, EI=EI, rho_A=rho_A)
    return structure_from_matrices(M.toarray(), K.toarray(), damping=damping,
                                   rayleigh=rayleigh, modal_damping=modal_damping,
                                   dof_names=names)


def beam_matrices(n_elements, *, length, EI, rho_A):
    """The sparse mass and stiffness matrices [kg, N/m] of a clamped-free Euler–Bernoulli
    beam by cubic Hermite elements with consistent mass (the clamp's two degrees of freedom
    removed), and the names of the degrees of freedom ``w1, th1, …, wN, thN`` (deflection
    [m], slope [rad]; ``wN`` is the tip): ``(M, K, names)``, ``M`` and ``K`` scipy CSR
    matrices of size ``2 n_elements``.  ``cantilever_beam`` builds its structure from them."""
    if not isinstance(n_elements, int) or n_elements < 1:
        raise ValueError(f"beam.n_elements must be a positive integer, got {n_elements!r}")
    for name, v in (("length", length), ("EI", EI), ("rho_A", rho_A)):
        if not np.isfinite(float(v)) or float(v) <= 0:
            raise ValueError(f"beam.{name} must be positive and finite, got {v!r}")
    h = float(length) / n_elements
    ke = float(EI) / h**3 * np.array([[12, 6 * h, -12, 6 * h],
                                      [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                                      [-12, -6 * h, 12, -6 * h],
                                      [6 * h, 2 * h * h, -6 * h, 4 * h * h]])
    me = float(rho_A) * h / 420 * np.array([[156, 22 * h, 54, -13 * h],
                                            [22 * h, 4 * h * h, 13 * h, -3 * h * h],
                                            [54, 13 * h, 156, -22 * h],
                                            [-13 * h, -3 * h * h, -22 * h, 4 * h * h]])
    idx = 2 * np.arange(n_elements)[:, None] + np.arange(4)          # (elements, 4)
    rows = np.repeat(idx, 4, axis=1).reshape(-1)
    cols = np.tile(idx, (1, 4)).reshape(-1)
    nd = 2 * (n_elements + 1)

    def assemble(e):
        A = sp.coo_matrix((np.tile(e.reshape(-1), n_elements), (rows, cols)), shape=(nd, nd))
        return A.tocsr()[2:, 2:]

    names = [f"{q}{i}" for i in range(1, n_elements + 1) for q in ("w", "th")]
    return assemble(me), assemble(ke), names
