r"""Nonlinear modes of damped structures: backbones of amplitude-dependent frequency and
modal damping by the extended periodic motion concept.

A friction- or impact-damped structure has no periodic free motion: its free vibration
decays.  The extended periodic motion concept (M. Krack, *Nonlinear modal analysis of
nonconservative systems: extension of the periodic motion concept*, Computers & Structures
154 (2015) 59) makes it periodic by an artificial negative mass-proportional damping
``-ξ M q̇`` that replaces exactly the energy the structure dissipates over a period:

$$M\ddot q + (C - \xi M)\dot q + K q = \Phi_u^T f(\Phi_u q, \Phi_u\dot q),$$

whose periodic solution of frequency ``ω`` at a prescribed amplitude is the nonlinear mode
there; ``ζ = ξ / (2ω)`` is its modal damping ratio (for a linear, classically damped
structure exactly the modal damping ratio, and ``ω`` the undamped natural frequency).  The
motion is sought by harmonic balance on the structure's coordinates, ``q = a ψ(ωt)``, with
the unknowns ``ψ``'s Fourier coefficients, ``ω`` and ``ξ``, and two more equations:

- amplitude: ``Σ_k ψ_kᴴ M ψ_k = 1`` over the complex harmonics ``k = 0 … H``, so that the
  modal amplitude ``a`` [kg^½ m] is the square root of the motion's modal mass-weighted
  energy measure (``a`` of a linear mode ``q = a φ cos ωt``, ``φᵀMφ = 1``);
- phase: the velocity of the normalising coordinate is zero at ``t = 0``.

The backbone is followed over the amplitudes given, each solve starting from the secant
extrapolation of the two before it.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core import tables
from .._core.checks import require_x64
from .._core.progress import PointProgress
from .._core.status import Status
from .._systems.base import AbstractSystem
from .harmonic import HarmonicBalance, fourier_matrices
from .orbit import dof_field


class NonlinearModes(eqx.Module):
    """A backbone from [`nonlinear_modes`][absorber_jax.nonlinear_modes], one entry per
    modal amplitude.

    ``amplitude``: the modal amplitude ``a`` [kg^½ m]; ``omega``: the frequency [rad/s];
    ``damping_ratio``: the modal damping ratio ``ζ = ξ/(2ω)`` [-]; ``dof_amplitude``: each
    degree of freedom's half peak-to-peak displacement [m] (points × ``dof_names``);
    ``dof_harmonic``: its fundamental's magnitude [m]; ``coefficients``: the real Fourier
    coefficients of the coordinates ``q`` (points × (2H+1) × coordinates: constant, then
    ``cos kωt``, ``sin kωt``); ``status`` (0 = converged), ``residual``, ``iterations``."""

    amplitude: np.ndarray
    omega: np.ndarray
    damping_ratio: np.ndarray
    dof_amplitude: np.ndarray
    dof_harmonic: np.ndarray
    coefficients: np.ndarray
    status: np.ndarray
    residual: np.ndarray
    iterations: np.ndarray
    dof_names: tuple = eqx.field(static=True)

    @property
    def ok(self):
        """Whether each point converged."""
        return self.status == Status.SUCCESS

    def dof(self, name, field="amplitude"):
        """``dof_<field>`` (``amplitude`` or ``harmonic``) of degree of freedom ``name``."""
        return dof_field(self, self.dof_names, name, field)

    def failures(self):
        """``[(index, what failed and what to try)]`` of the points that failed."""
        return tables.failure_list(self.status)

    def _columns(self):
        cols = [("amplitude [kg^0.5 m]", self.amplitude), ("omega [rad/s]", self.omega),
                ("damping_ratio [-]", self.damping_ratio)]
        for i, nm in enumerate(self.dof_names):
            cols.append((f"amplitude[{nm}] [m]", self.dof_amplitude[:, i]))
            cols.append((f"harmonic[{nm}] [m]", self.dof_harmonic[:, i]))
        return cols + [("status", self.status), ("residual", self.residual),
                       ("iterations", self.iterations)]

    def to_csv(self, path):
        """One row per modal amplitude, each header with its unit."""
        tables.write_csv(path, self._columns())

    def to_dataframe(self):
        """The rows of ``to_csv`` as a ``pandas.DataFrame`` (needs pandas)."""
        return tables.dataframe(self._columns(), "NonlinearModes.to_dataframe")


def _linearised_mode(cond, mode):
    """The ``mode``-th underdamped mode (by frequency) of the structure with its elements
    linearised at rest: ``(ψ₀ real, M-normalised; ω₀ [rad/s]; ξ₀ [1/s])``."""
    st = cond.system.structure
    M, C, K = st.mass, st.damping, st.stiffness
    Pu = cond.dof_map
    zero = jnp.zeros(cond.size)
    fx = jax.jacfwd(lambda x: cond.forces(x, zero))(zero)
    fv = jax.jacfwd(lambda v: cond.forces(zero, v))(zero)
    Kl, Cl = K - Pu.T @ fx @ Pu, C - Pu.T @ fv @ Pu
    n = M.shape[0]
    Minv = jnp.linalg.inv(M)
    A = jnp.block([[jnp.zeros((n, n)), jnp.eye(n)], [-Minv @ Kl, -Minv @ Cl]])
    lam, vec = jnp.linalg.eig(A)
    under = (jnp.imag(lam) > 1e-9 * jnp.abs(lam)) & (-jnp.real(lam) < jnp.abs(lam))
    order = jnp.argsort(jnp.where(under, jnp.imag(lam), jnp.inf))
    j = order[mode - 1]
    phi = vec[:n, j]
    k = jnp.argmax(jnp.abs(phi))
    psi = jnp.real(phi * jnp.exp(-1j * jnp.angle(phi[k])))
    psi = psi / jnp.sqrt(psi @ M @ psi)
    return psi, jnp.abs(lam[j]), -2 * jnp.real(lam[j]), jnp.sum(under)


def nonlinear_modes(system, amplitudes, *, mode=1, method=None, progress=False):
    """The backbone of nonlinear mode ``mode`` of ``system`` (frequency and modal damping
    ratio against modal amplitude) by the extended periodic motion concept and harmonic
    balance (see the module above).

    **Arguments**

    - ``system``: a [`StructuralSystem`][absorber_jax.StructuralSystem] whose elements keep
      no states of their own (contacts, smoothed friction contacts, elements of your own);
      its load is not used (free vibration).
    - ``amplitudes``: the modal amplitudes ``a`` [kg^½ m] (positive, increasing; log-spaced
      suits a backbone, e.g. ``np.logspace(-2, 1, 60)``).
    - ``mode``: which mode, counting the underdamped modes of the structure with its
      elements linearised at rest by frequency (1 = lowest).
    - ``method``: a [`HarmonicBalance`][absorber_jax.HarmonicBalance] carrying the
      harmonics, samples and Newton's tolerance (default ``HarmonicBalance()``; its
      ``condense`` is not used: the balance is on the structure's coordinates, so reduce a
      large model first with [`craig_bampton`][absorber_jax.craig_bampton]).
    - ``progress``: show a progress bar (the backbone is one compiled scan: it says when
      it compiles, then counts all points at once).

    Returns [`NonlinearModes`][absorber_jax.NonlinearModes].

    ```python
    nm = aj.nonlinear_modes(system, np.logspace(-2, 1, 60),
                            method=aj.HarmonicBalance(harmonics=15))
    nm.omega, nm.damping_ratio
    ```
    """
    require_x64("nonlinear_modes")
    method = HarmonicBalance() if method is None else method
    if not isinstance(method, HarmonicBalance):
        raise ValueError(f"nonlinear_modes.method must be a HarmonicBalance, got "
                         f"{type(method).__name__}")
    cond = system.condensation() if isinstance(system, AbstractSystem) else None
    if cond is None:
        raise ValueError("nonlinear_modes needs a StructuralSystem whose elements keep no "
                         "states of their own (contacts, smoothed friction contacts)")
    a = np.asarray(amplitudes, dtype=float).reshape(-1)
    if a.size < 1 or np.any(~np.isfinite(a)) or np.any(a <= 0) or np.any(np.diff(a) <= 0):
        raise ValueError("nonlinear_modes.amplitudes must be positive, finite and "
                         f"increasing, got {amplitudes!r}")
    if not isinstance(mode, int) or isinstance(mode, bool) or mode < 1:
        raise ValueError(f"nonlinear_modes.mode must be a positive integer, got {mode!r}")
    n_under = int(_linearised_mode(cond, 1)[3])
    if mode > n_under:
        raise ValueError(f"nonlinear_modes.mode must be in [1, {n_under}] (the underdamped "
                         f"modes of the linearised structure), got {mode}")
    with PointProgress(a.size, "nonlinear modes", progress) as bar:
        out = _backbone(cond, jnp.asarray(a), mode, method)
        bar.update(a.size)
    coeffs, omega, xi, status, res, its, amp, harm = (np.asarray(v) for v in out)
    return NonlinearModes(amplitude=a, omega=omega, damping_ratio=xi / (2 * omega),
                          dof_amplitude=amp, dof_harmonic=harm, coefficients=coeffs,
                          status=status, residual=res, iterations=its,
                          dof_names=system.structure.dof_names)


@eqx.filter_jit
def _backbone(cond, amplitudes, mode, method):
    st = cond.system.structure
    M, C, K, Pu = st.mass, st.damping, st.stiffness, cond.dof_map
    H, N = method.harmonics, method.time_samples
    E, P, D = fourier_matrices(H, N)
    n = M.shape[0]
    psi0, w0, xi0, _ = _linearised_mode(cond, mode)
    inorm = jnp.argmax(jnp.abs(psi0))
    fscale = jnp.max(jnp.abs(K @ psi0))
    k = jnp.arange(1, H + 1)

    def residual(y, a):
        psi = y[:-2].reshape(2 * H + 1, n)
        w, xi = y[-2], y[-1]
        c = a * psi
        dc = D @ c
        x, v = E @ (c @ Pu.T), w * (E @ (dc @ Pu.T))
        f = P @ jax.vmap(cond.forces)(x, v)                            # (2H+1, u)
        R = (w**2 * (D @ dc) @ M.T + w * dc @ (C - xi * M).T + c @ K.T - f @ Pu) / a
        # Σ_k ψ_kᴴ M ψ_k over the complex harmonics: c₀ᵀMc₀ + Σ (a_kᵀMa_k + b_kᵀMb_k)
        norm = jnp.sum((psi @ M) * psi) - 1.0
        phase = jnp.sum(k * psi[2 * k, inorm])
        return jnp.concatenate([R.reshape(-1) / fscale, jnp.stack([norm, phase])])

    y0 = jnp.concatenate([jnp.zeros((2 * H + 1, n)).at[1].set(psi0).reshape(-1),
                          jnp.stack([w0, xi0])])
    loga = jnp.log(amplitudes)

    def step(carry, la):
        y1, y2, l1, l2, ngood = carry
        # secant extrapolation in log a from the last two converged points
        slope = jnp.where(ngood >= 2, (la - l1) / jnp.where(l1 == l2, 1.0, l1 - l2), 0.0)
        guess = y1 + slope * (y1 - y2)
        y, status, res, its = method._newton(lambda v: residual(v, jnp.exp(la)), guess)
        ok = status == Status.SUCCESS
        carry = (jnp.where(ok, y, y1), jnp.where(ok, y1, y2), jnp.where(ok, la, l1),
                 jnp.where(ok, l1, l2), ngood + ok)
        return carry, (y, status, res, its)

    init = (y0, y0, loga[0], loga[0], jnp.asarray(0))
    _, (ys, status, res, its) = jax.lax.scan(step, init, loga)
    coeffs = ys[:, :-2].reshape(-1, 2 * H + 1, n) * amplitudes[:, None, None]
    Es = fourier_matrices(H, 8 * H + 8)[0]
    x = jnp.einsum("sk,pkn,dn->psd", Es, coeffs, st.dof_map)          # (points, s, dofs)
    amp = 0.5 * (jnp.max(x, axis=1) - jnp.min(x, axis=1))
    first = jnp.einsum("pkn,dn->pkd", coeffs[:, 1:3], st.dof_map)
    harm = jnp.sqrt(first[:, 0] ** 2 + first[:, 1] ** 2)
    return coeffs, ys[:, -2], ys[:, -1], status, res, its, amp, harm
