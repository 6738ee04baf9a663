r"""Finite-element-size structures: sparse matrices and their Craig–Bampton reduction.

A model of thousands of degrees of freedom is too large to integrate or to solve densely at
every harmonic, but its nonlinearity sits at a few of them (a friction contact, an impact
stop).  The Craig–Bampton reduction keeps those degrees of freedom ``b`` (the *boundary*)
exactly and represents the rest ``i`` (the *interior*) by the static response to the
boundary plus ``m`` fixed-interface modes:

$$
\begin{bmatrix}x_b\\ x_i\end{bmatrix} = T\begin{bmatrix}x_b\\ \eta\end{bmatrix},\qquad
T = \begin{bmatrix}I & 0\\ \Psi & \Phi_i\end{bmatrix},\qquad
\Psi = -K_{ii}^{-1}K_{ib},\qquad K_{ii}\Phi_i = M_{ii}\Phi_i\Lambda,\ \Phi_i^TM_{ii}\Phi_i = I,
$$

and the reduced matrices are ``Tᵀ M T``, ``Tᵀ K T`` (block-diagonal: ``K_bb + K_bi Ψ`` and
``Λ``) and ``Tᵀ C T``.  The static response at the boundary is exact (``Ψ`` is the exact
static condensation); dynamics converge as modes are added, the error of a receptance at
frequency ``Ω`` falling like ``(Ω/ω_{m+1})²`` for the first mode dropped (R. R. Craig, M. C. C.
Bampton, *Coupling of substructures for dynamic analyses*, AIAA J. 6 (1968) 1313).  The
sparse factorisation of ``K_ii`` and the shift-invert Lanczos solve for the ``m`` lowest
fixed-interface modes (``scipy.sparse.linalg.eigsh``) cost about linearly in the size of a
banded model; everything after (simulation, shooting, harmonic balance) sees ``n_b + m``
coordinates only.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .structure import LinearStructure, structure_from_matrices


def as_sparse(owner, name, a):
    """``a`` (a dense array or a scipy sparse matrix) as a square CSC matrix of floats,
    checked finite and symmetric (ValueError naming ``owner.name`` otherwise)."""
    try:
        A = sp.csc_matrix(a, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{owner}.{name} must be a real matrix (dense or scipy sparse), "
                         f"got {type(a).__name__}") from e
    if A.shape[0] != A.shape[1]:
        raise ValueError(f"{owner}.{name} must be square, got shape {A.shape}")
    if not np.all(np.isfinite(A.data)):
        raise ValueError(f"{owner}.{name} must be finite")
    scale = max(abs(A).max(), 1e-300)
    if abs(A - A.T).max() > 1e-10 * scale:
        raise ValueError(f"{owner}.{name} must be symmetric")
    return A


def _index(names, dof, field):
    if isinstance(dof, str):
        if names is None or dof not in names:
            raise ValueError(f"craig_bampton.{field}: unknown degree of freedom {dof!r}"
                             + ("" if names is None else " (give dof_names or indices)"))
        return names.index(dof)
    return int(dof)


def craig_bampton(mass, stiffness, boundary, n_modes, *, damping=None, rayleigh=None,
                  modal_damping=None, observe=(), dof_names=None) -> LinearStructure:
    """The Craig–Bampton reduction of a (large, sparse) structure onto the degrees of
    freedom ``boundary`` plus ``n_modes`` fixed-interface modes (see the module above).

    **Arguments**

    - ``mass``, ``stiffness``: symmetric matrices [kg, N/m], dense or scipy sparse (e.g.
      from [`read_matrix`][absorber_jax.read_matrix]); ``mass`` positive definite, the
      stiffness of the interior (the model with the boundary held) positive definite.
    - ``boundary``: the degrees of freedom kept exactly (names if ``dof_names`` is given,
      or indices): where elements attach and loads act.
    - ``n_modes``: fixed-interface modes kept (``0``: static condensation, Guyan).
    - one damping model: ``damping`` (a matrix [N s/m], reduced as ``Tᵀ C T``),
      ``rayleigh`` ``(α, β)`` (``α M + β K`` of the reduced matrices, exact) or
      ``modal_damping`` (ratios of the reduced model's modes); none: undamped.
    - ``observe``: interior degrees of freedom to observe (and load), recovered as
      ``x_o = Ψ_o x_b + Φ_o η``.
    - ``dof_names``: names of all the degrees of freedom (default ``x1 …``).

    Returns a [`LinearStructure`][absorber_jax.LinearStructure] with coordinates
    ``(x_b, η)``, observed at ``boundary`` then ``observe`` (named as in ``dof_names``).

    ```python
    M, K, names = aj.beam_matrices(500, length=1.0, EI=100.0, rho_A=1.0)
    beam = aj.craig_bampton(M, K, ["w500"], 10, rayleigh=(0.0, 1e-4), dof_names=names)
    ```
    """
    M = as_sparse("craig_bampton", "mass", mass)
    K = as_sparse("craig_bampton", "stiffness", stiffness)
    n = M.shape[0]
    if K.shape != M.shape:
        raise ValueError(f"craig_bampton.stiffness must have the mass matrix's shape "
                         f"{M.shape}, got {K.shape}")
    names = None if dof_names is None else [str(s) for s in dof_names]
    if names is not None and (len(names) != n or len(set(names)) != n):
        raise ValueError(f"craig_bampton.dof_names must be {n} distinct names")
    b = [_index(names, d, "boundary") for d in boundary]
    o = [_index(names, d, "observe") for d in observe]
    if not b or len(set(b)) != len(b) or any(not 0 <= j < n for j in b):
        raise ValueError(f"craig_bampton.boundary must be distinct degrees of freedom in "
                         f"[0, {n}), got {boundary!r}")
    if len(set(o)) != len(o) or any(not 0 <= j < n or j in b for j in o):
        raise ValueError("craig_bampton.observe must be distinct interior degrees of freedom "
                         f"(not in boundary), got {observe!r}")
    i = np.setdiff1d(np.arange(n), b)
    if not isinstance(n_modes, int) or not 0 <= n_modes < len(i):
        raise ValueError(f"craig_bampton.n_modes must be an integer in [0, {len(i) - 1}], got "
                         f"{n_modes!r}")
    given = [g for g in (damping, rayleigh, modal_damping) if g is not None]
    if len(given) > 1:
        raise ValueError("craig_bampton: give at most one of damping, rayleigh, modal_damping")

    # the interior problems solved in symmetrically equilibrated form (unit diagonal of
    # K_ii): a fine beam mesh mixes deflections and slopes whose stiffnesses differ by
    # h⁻², and the unscaled shift-invert loses digits to it
    Kii = K[i][:, i].tocsc()
    d = 1.0 / np.sqrt(np.maximum(np.abs(Kii.diagonal()), 1e-300))
    Dg = sp.diags(d)
    Mii = M[i][:, i]
    Kt, Mt = (Dg @ Kii @ Dg).tocsc(), (Dg @ Mii @ Dg).tocsc()
    Kib = K[i][:, b].toarray()
    try:
        solve = spla.factorized(Kt)
    except RuntimeError as e:
        raise ValueError("craig_bampton.stiffness: the interior (boundary held) is singular; "
                         "hold the structure by its supports or add boundary degrees of "
                         "freedom") from e
    Psi = -d[:, None] * np.column_stack([solve(d * Kib[:, j]) for j in range(len(b))])
    if n_modes:
        lam, Phi = spla.eigsh(Kt, k=n_modes, M=Mt, sigma=0.0, which="LM")
        order = np.argsort(lam)
        lam, Phi = lam[order], d[:, None] * Phi[:, order]
        Phi /= np.sqrt(np.einsum("ij,ij->j", Phi, Mii @ Phi))
    else:
        lam, Phi = np.zeros(0), np.zeros((len(i), 0))

    def reduce(A):
        Abb, Abi, Aii = A[b][:, b].toarray(), A[b][:, i], A[i][:, i]
        AiiPsi = Aii @ Psi
        top = Abb + Abi @ Psi + (Abi @ Psi).T + Psi.T @ AiiPsi
        side = (Abi @ Phi) + AiiPsi.T @ Phi                   # (n_b, m)
        return np.block([[top, side], [side.T, Phi.T @ (Aii @ Phi)]])

    Mr, Kr = reduce(M), reduce(K)
    Kr[len(b):, :len(b)] = Kr[:len(b), len(b):] = 0.0         # exactly zero by construction
    Kr[len(b):, len(b):] = np.diag(lam)
    Mr, Kr = 0.5 * (Mr + Mr.T), 0.5 * (Kr + Kr.T)
    if damping is not None:
        C = as_sparse("craig_bampton", "damping", damping)
        if C.shape != M.shape:
            raise ValueError(f"craig_bampton.damping must have shape {M.shape}, got {C.shape}")
        Cr = reduce(C)
        st = structure_from_matrices(Mr, Kr, damping=0.5 * (Cr + Cr.T))
    else:
        st = structure_from_matrices(Mr, Kr, rayleigh=rayleigh, modal_damping=modal_damping)
    nb = len(b)
    rows = np.zeros((nb + len(o), nb + n_modes))
    rows[:nb, :nb] = np.eye(nb)
    at = {int(j): k for k, j in enumerate(i)}
    for r, j in enumerate(o):
        rows[nb + r, :nb] = Psi[at[j]]
        rows[nb + r, nb:] = Phi[at[j]]
    kept = b + o
    out_names = tuple(names[j] for j in kept) if names is not None else tuple(
        f"x{j + 1}" for j in kept)
    return LinearStructure(mass=st.mass, damping=st.damping, stiffness=st.stiffness,
                           dof_map=rows, dof_names=out_names)
