"""Linear two-mass models: exact harmonic responses used as shooting guesses.

For ``M q'' + C q' + K q = f F0 sin(ωt)`` the steady response is ``q(t) = Im(Q e^{iωt})``
with ``Q = (K - ω² M + iω C)^{-1} f F0``.
"""

from __future__ import annotations

import jax.numpy as jnp


def harmonic_response(Mm, Cm, Km, f, F0, omega):
    """Complex amplitudes ``Q`` of ``M q'' + C q' + K q = f F0 sin(ωt)``."""
    Z = Km - omega**2 * Mm + 1j * omega * Cm
    return jnp.linalg.solve(Z.astype(jnp.complex128), (f * F0).astype(jnp.complex128))


def state_at_zero(Q, omega):
    """``(q(0), q'(0))`` of ``q(t) = Im(Q e^{iωt})``."""
    return jnp.imag(Q), omega * jnp.real(Q)


def two_mass_matrices(M, m, k, c, k_c, c_c):
    """Primary ``M, k, c`` to ground and absorber ``m`` tied to it by ``k_c, c_c``."""
    Mm = jnp.diag(jnp.stack([M, m]))
    Cm = jnp.array([[c + c_c, -c_c], [-c_c, c_c]])
    Km = jnp.array([[k + k_c, -k_c], [-k_c, k_c]])
    return Mm, Cm, Km


def _internal(q, qd):
    """Internal state ``[x1, v1, u, w]`` from absolute positions and velocities."""
    return jnp.stack([q[0], qd[0], q[1] - q[0], qd[1] - qd[0]])


def linear_guess(system, forcing):
    """A starting orbit for shooting from the linear limits of the scene (internal state):
    the system's own
    [`AbstractAbsorberSystem.linear_guess`][absorber_jax.AbstractAbsorberSystem.linear_guess]."""
    return system.linear_guess(forcing)


def finite_or_zero(s):
    """An undamped linear limit at its resonance has no steady state: start from rest."""
    return jnp.where(jnp.all(jnp.isfinite(s)), s, jnp.zeros_like(s))
