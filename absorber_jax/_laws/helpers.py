"""The paper's contact helpers (section 2.2–2.3), with corrections.

- ``hertz_stiffness``: ``kHz = (4/3) E* sqrt(R)`` from the materials.  The paper writes
  the contact radius ``a`` where the sphere radius ``R`` belongs (its ``a`` depends on the
  load, which would make the "stiffness" load-dependent); we use ``R``.
- ``hunt_crossley_damping``: the paper's ``c1 = 3 kHz (1 - e²)/(4 v0)`` (Lankarani &
  Nikravesh 1990).  It is accurate for restitution near 1 only; see
  ``hunt_crossley_restitution`` and the README for the measured restitution it yields.
- ``linear_contact_time``, ``hertz_contact_time``: the paper's ``T_Linear`` and
  ``T_Hertz`` (its ``K* = (m+M)/(mM)`` is ``1/meff``); both checked against simulated single
  impacts in the tests.
- ``equivalent_hertz_stiffness``: the ``kHz`` whose contact time at impact speed ``v0``
  equals the linear law's.
"""

from __future__ import annotations

import math

from .._core.checks import check_scalar, positive

HERTZ_TIME_CONSTANT = 2.9432  # ∫_0^1 2 dx / sqrt(1 - x^{5/2}), Johnson (1985) eq. 11.24


def effective_mass(m, M):
    """``m M / (m + M)`` [kg]."""
    positive("effective_mass", "m", m)
    positive("effective_mass", "M", M)
    return m * M / (m + M)


def hertz_stiffness(E1, nu1, E2, nu2, R):
    r"""Hertz contact stiffness $k_{Hz} = \tfrac43 E^*\sqrt{R}$ [N/m^{3/2}] of a sphere of
    radius ``R`` [m] on a flat, $1/E^* = (1-\nu_1^2)/E_1 + (1-\nu_2^2)/E_2$ (E in Pa).

    ```python
    hertz_stiffness(210e9, 0.3, 210e9, 0.3, 0.01)   # steel ball, R = 1 cm: 1.54e10
    ```
    """
    positive("hertz_stiffness", "E1", E1)
    positive("hertz_stiffness", "E2", E2)
    check_scalar("hertz_stiffness", "nu1", nu1, lo=-1.0, hi=0.5, lo_open=True)
    check_scalar("hertz_stiffness", "nu2", nu2, lo=-1.0, hi=0.5, lo_open=True)
    positive("hertz_stiffness", "R", R)
    e_star = 1.0 / ((1 - nu1**2) / E1 + (1 - nu2**2) / E2)
    return 4.0 / 3.0 * e_star * math.sqrt(R)


def hunt_crossley_damping(stiffness, restitution, impact_velocity):
    r"""The paper's Hunt–Crossley damping $c_1 = 3k_{Hz}(1-e^2)/(4\dot y_0)$ [N s/m^{5/2}].

    ``restitution`` in (0, 1], ``impact_velocity`` [m/s] > 0.

    ```python
    hunt_crossley_damping(3260.0, 0.8, 1.0)   # 880.2
    ```
    """
    positive("hunt_crossley_damping", "stiffness", stiffness)
    check_scalar("hunt_crossley_damping", "restitution", restitution, lo=0.0, hi=1.0, lo_open=True)
    positive("hunt_crossley_damping", "impact_velocity", impact_velocity)
    return 3.0 * stiffness * (1.0 - restitution**2) / (4.0 * impact_velocity)


def linear_contact_time(k1, c1, m, M):
    r"""Paper's $T_{Linear} = 2\pi mM / (\sqrt{m+M}\sqrt{4mMk_1 - c_1^2(m+M)})$ [s]
    (= ``π/ω_d``).  Raises if the contact is overdamped (no rebound)."""
    positive("linear_contact_time", "k1", k1)
    check_scalar("linear_contact_time", "c1", c1, lo=0.0)
    disc = 4 * m * M * k1 - c1**2 * (m + M)
    if disc <= 0:
        raise ValueError("linear_contact_time: c1 must be below the critical damping "
                         f"2 sqrt(k1 meff) = {2 * math.sqrt(k1 * m * M / (m + M)):g}, got {c1:g}")
    return 2 * math.pi * m * M / (math.sqrt(m + M) * math.sqrt(disc))


def linear_restitution(k1, c1, m, M):
    """Restitution of the adhesive linear law, ``exp(-ζπ/sqrt(1-ζ²))``."""
    meff = effective_mass(m, M)
    zeta = c1 / (2 * math.sqrt(k1 * meff))
    if zeta >= 1:
        raise ValueError(f"linear_restitution: damping ratio must be < 1, got {zeta:g}")
    return math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))


def hertz_contact_time(stiffness, m, M, impact_velocity):
    r"""Paper's $T_{Hertz} = 2.9432\,(5 m_{eff}/(4 k_{Hz}))^{2/5}\,\dot y_0^{-1/5}$ [s]
    (undamped Hertz impact)."""
    positive("hertz_contact_time", "stiffness", stiffness)
    positive("hertz_contact_time", "impact_velocity", impact_velocity)
    meff = effective_mass(m, M)
    return HERTZ_TIME_CONSTANT * (5 * meff / (4 * stiffness)) ** 0.4 * impact_velocity**-0.2


def equivalent_hertz_stiffness(k1, c1, m, M, impact_velocity):
    """``kHz`` [N/m^{3/2}] whose Hertz contact time at ``impact_velocity`` equals the linear
    law's ``T_Linear(k1, c1)`` (the paper's recipe)."""
    T = linear_contact_time(k1, c1, m, M)
    meff = effective_mass(m, M)
    return 1.25 * meff * (HERTZ_TIME_CONSTANT / (T * impact_velocity**0.2)) ** 2.5
