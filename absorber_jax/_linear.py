"""Linear two-mass models: exact harmonic responses used as shooting guesses.

For ``M q'' + C q' + K q = f F0 sin(ωt)`` the steady response is ``q(t) = Im(Q e^{iωt})``
with ``Q = (K - ω² M + iω C)^{-1} f F0``.
"""

from __future__ import annotations

import jax.numpy as jnp

from ._system import FrictionAbsorber, ImpactAbsorber


def harmonic_response(Mm, Cm, Km, f, F0, omega):
    """Complex amplitudes ``Q`` of ``M q'' + C q' + K q = f F0 sin(ωt)``."""
    Z = Km - omega**2 * Mm + 1j * omega * Cm
    return jnp.linalg.solve(Z.astype(jnp.complex128), (f * F0).astype(jnp.complex128))


def _state_at_zero(Q, omega):
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
    """A starting orbit for shooting from the linear limits of the scene (internal state).

    Impact absorber: the primary alone with the absorber floating at rest in the middle of
    the cavity if that motion stays inside the clearance, else the tuned-mass damper with
    the contact law's stiffness and damping acting at zero gap.  Friction absorber: the two
    masses stuck together if the friction force needed stays below the friction capacity,
    else the absorber sliding freely (N = 0)."""
    F0, w = forcing.amplitude, forcing.omega
    one = jnp.ones(())
    if isinstance(system, ImpactAbsorber):
        M, k, c, m = system.M, system.k, system.c, system.m
        X1 = F0 / (k - w**2 * M + 1j * w * c)
        free = _internal(jnp.stack([jnp.imag(X1), 0.0 * one]),
                         jnp.stack([w * jnp.real(X1), 0.0 * one]))
        # contact secant stiffness at a penetration of the gap's size (1 mm if no gap)
        law = system.contact
        d = jnp.maximum(system.gap, 1e-3)
        k_c = law.elastic_force(d) / d
        c_c = law.viscous_force(d, 1.0)
        Q = harmonic_response(*two_mass_matrices(M, m, k, c, k_c, c_c), jnp.array([1.0, 0.0]),
                              F0, w)
        tmd = _internal(*_state_at_zero(Q, w))
        floats = jnp.abs(X1) < system.gap
        return _finite_or_zero(jnp.where(floats, free, tmd))
    if isinstance(system, FrictionAbsorber):
        m1, m2 = system.m1, system.m2
        Xs = F0 / (system.k1 - w**2 * (m1 + m2) + 1j * w * system.c1)
        stuck = _internal(jnp.stack([jnp.imag(Xs)] * 2), jnp.stack([w * jnp.real(Xs)] * 2))
        need = m2 * w**2 * jnp.abs(Xs)  # friction force that keeps the absorber stuck
        law = system.friction
        cap = system.normal_force * (law.mu if hasattr(law, "mu") else law.mu_c)
        Q = harmonic_response(*two_mass_matrices(m1, m2, system.k1, system.c1, system.k2,
                                                 system.c2), jnp.array([1.0, 0.0]), F0, w)
        free = _internal(*_state_at_zero(Q, w))
        base = jnp.where(need <= cap, stuck, free)
        z0 = jnp.zeros((system.num_law_states,), base.dtype)
        return _finite_or_zero(jnp.concatenate([base, z0]))
    raise ValueError(f"no linear guess for {type(system).__name__}")


def _finite_or_zero(s):
    """An undamped linear limit at its resonance has no steady state: start from rest."""
    return jnp.where(jnp.all(jnp.isfinite(s)), s, jnp.zeros_like(s))
