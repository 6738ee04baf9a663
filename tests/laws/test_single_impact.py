"""Single impact of two free masses against the closed-form contact times and restitutions
(Mechanics page of the documentation, "Contact times, restitution and the helpers"), and the
paper's helper constants checked against simulation."""

import jax.numpy as jnp
import numpy as np
import pytest

import absorber_jax as aj

M, m, GAP = 1.0, 0.4, 1e-3


def single_impact(law, v0, T=0.3):
    """Absorber 0.1 mm from the right wall moving at v0 towards it; both masses free.
    Returns (contact duration, restitution) read from the simulated trajectory."""
    system = aj.ImpactAbsorber(M=M, k=0.0, c=0.0, m=m, gap=GAP, contact=law)
    ts = np.linspace(0.0, T, 100001)
    tr = aj.simulate(
        system,
        aj.Harmonic(amplitude=0.0, omega=1.0),
        T,
        ts=ts,
        y0=jnp.array([0.0, 0.0, GAP - 1e-4, v0]),
        rtol=1e-12,
        atol=1e-15,
    )
    y = np.asarray(tr.relative)
    w = np.asarray(tr.v2 - tr.v1)
    inside = y > GAP
    i0 = int(np.argmax(inside))
    i1 = i0 + int(np.argmax(~inside[i0:]))
    assert i0 > 0 and i1 > i0, "no complete impact in the window"

    def crossing(i):
        return ts[i - 1] + (GAP - y[i - 1]) / (y[i] - y[i - 1]) * (ts[i] - ts[i - 1])

    # momentum is conserved through the impact (no external force)
    p = M * np.asarray(tr.v1) + m * np.asarray(tr.v2)
    np.testing.assert_allclose(p, m * v0, rtol=1e-9)
    return crossing(i1) - crossing(i0), -w[i1 + 2] / v0


@pytest.mark.parametrize("c1", [2.0, 20.0])
def test_kelvin_voigt_contact_time_and_restitution(c1):
    law = aj.KelvinVoigt(stiffness=400.0, damping=c1, eps=1e-10, adhesive=True)
    t_c, e = single_impact(law, 0.1)
    meff = m * M / (m + M)
    wd = np.sqrt(400.0 / meff - (c1 / (2 * meff)) ** 2)
    zeta = c1 / (2 * np.sqrt(400.0 * meff))
    np.testing.assert_allclose(t_c, np.pi / wd, rtol=1e-6)
    np.testing.assert_allclose(
        e, np.exp(-zeta * np.pi / np.sqrt(1 - zeta**2)), rtol=1e-5, atol=1e-7
    )
    # the paper's T_Linear is the same closed form
    np.testing.assert_allclose(aj.linear_contact_time(400.0, c1, m, M), np.pi / wd, rtol=1e-12)


@pytest.mark.parametrize("v0", [0.05, 0.5])
def test_hertz_contact_time_and_elastic_rebound(v0):
    law = aj.Hertz(stiffness=3260.0, damping=0.0, eps=1e-10, adhesive=True)
    t_c, e = single_impact(law, v0)
    meff = m * M / (m + M)
    expect = 2.9432 * (5 * meff / (4 * 3260.0)) ** 0.4 * v0**-0.2
    np.testing.assert_allclose(t_c, expect, rtol=1e-4)  # 2.9432 is given to 5 digits
    np.testing.assert_allclose(e, 1.0, atol=1e-6)
    np.testing.assert_allclose(aj.hertz_contact_time(3260.0, m, M, v0), expect, rtol=1e-12)


def test_equivalent_hertz_stiffness_matches_linear_contact_time():
    v0 = 0.2
    k_hz = aj.equivalent_hertz_stiffness(400.0, 0.0, m, M, v0)
    t_lin, _ = single_impact(aj.KelvinVoigt(stiffness=400.0, damping=0.0, eps=1e-10,
                                            adhesive=True), v0)
    t_hz, _ = single_impact(aj.Hertz(stiffness=k_hz, damping=0.0, eps=1e-10, adhesive=True), v0)
    np.testing.assert_allclose(t_hz, t_lin, rtol=2e-4)


def test_paper_hunt_crossley_damping_only_holds_near_elastic_impacts():
    """c1 = 3 kHz (1 - e²)/(4 v0) (the paper's) yields the requested restitution only for e
    near 1: measured 0.990 for 0.99, 0.913 for 0.9, 0.725 for 0.5."""
    v0 = 0.1
    measured = {}
    for e in (0.99, 0.9, 0.5):
        c1 = aj.hunt_crossley_damping(3260.0, e, v0)
        law = aj.HuntCrossley(stiffness=3260.0, damping=c1, eps=1e-10, adhesive=False)
        measured[e] = single_impact(law, v0)[1]
    assert abs(measured[0.99] - 0.99) < 2e-3
    assert abs(measured[0.9] - 0.9) < 0.02
    assert measured[0.5] - 0.5 > 0.2  # far off: the formula is a near-elastic approximation


def test_hertz_stiffness_from_materials():
    # steel sphere R = 10 mm on steel: (4/3) E* sqrt(R), E* = E / (2 (1 - ν²))
    e_star = 210e9 / (2 * (1 - 0.3**2))
    np.testing.assert_allclose(
        aj.hertz_stiffness(210e9, 0.3, 210e9, 0.3, 0.01), 4 / 3 * e_star * 0.1, rtol=1e-12
    )


@pytest.mark.parametrize("adhesive", [True, False])
@pytest.mark.parametrize("e", [0.8, 0.4])
def test_restitution_constructor_gives_the_simulated_restitution(e, adhesive):
    """KelvinVoigt.from_restitution against a simulated single impact of the two free
    masses: the adhesive law leaves the wall at zero penetration, the non-adhesive one where
    its force reaches zero (earlier, so it needs more damping for the same e)."""
    law = aj.KelvinVoigt.from_restitution(400.0, e, m, M, eps=1e-10, adhesive=adhesive)
    _, e_sim = single_impact(law, 0.1)
    print(f"e = {e}, adhesive={adhesive}: simulated {e_sim:.8f}")
    np.testing.assert_allclose(e_sim, e, rtol=1e-4)
    other = aj.KelvinVoigt.from_restitution(400.0, e, m, M, adhesive=not adhesive)
    assert (float(other.damping) > float(law.damping)) == adhesive
