"""Each law against its formula at sample points, with the sign conventions at both walls
and in both sliding directions."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import absorber_jax as aj

DELTAS = np.array([1e-5, 1e-4, 2e-3])
RATES = np.array([-0.3, 0.0, 0.2])


@pytest.mark.parametrize(
    "law, formula",
    [
        (aj.KelvinVoigt(stiffness=400.0, damping=20.0,
                        adhesive=True), lambda d, r: 400 * d + 20 * r),
        (aj.Hertz(stiffness=3260.0, damping=20.0,
                  adhesive=True), lambda d, r: 3260 * d**1.5 + 20 * r),
        (aj.HuntCrossley(stiffness=3260.0, damping=469.5, adhesive=True),
         lambda d, r: 3260 * d**1.5 + 469.5 * d**1.5 * r),
    ],
)
def test_contact_law_formula_and_walls(law, formula):
    for d in DELTAS:
        for r in RATES:
            np.testing.assert_allclose(law.force(d, r), formula(d, r), rtol=1e-12)
    # placed at the walls of a 1 mm clearance, deep in contact (smoothing negligible)
    system = aj.ImpactAbsorber(M=1.0, k=1e3, c=0.1, m=0.4, gap=1e-3, contact=law)
    d, r = 2e-3, 0.2
    f_right, _ = system.coupling(1e-3 + d, r, jnp.zeros(0))  # absorber past the right wall
    f_left, _ = system.coupling(-1e-3 - d, -r, jnp.zeros(0))  # past the left wall, moving out
    np.testing.assert_allclose(f_right, formula(d, r), rtol=1e-9)  # pushes the primary right
    np.testing.assert_allclose(f_left, -formula(d, r), rtol=1e-9)  # pushes the primary left
    # free flight inside the clearance: no force (up to the smoothing tail)
    f_in, _ = system.coupling(0.0, 0.3, jnp.zeros(0))
    assert abs(float(f_in)) < 1e-12


@pytest.mark.parametrize("cls", [aj.KelvinVoigt, aj.Hertz, aj.HuntCrossley])
def test_non_adhesive_never_pulls(cls):
    law = cls(stiffness=400.0, damping=50.0, adhesive=False, eps=1e-7)
    adh = cls(stiffness=400.0, damping=50.0, eps=1e-7, adhesive=True)
    d = jnp.linspace(0, 1e-3, 50)[:, None]
    r = jnp.linspace(-20.0, 20.0, 41)[None, :]
    f = law.force(d, r)
    scale = float(law.stiffness * law.eps**law.exponent)
    assert float(f.min()) >= -0.3 * scale  # swish clipping: never below -0.28 scale
    assert float(adh.force(d, r).min()) < -1e3 * scale  # the paper's law does pull
    big = adh.force(d, r) > 100 * scale
    np.testing.assert_allclose(f[big], adh.force(d, r)[big], rtol=1e-6)


def test_zero_gap_is_exactly_linear():
    law = aj.KelvinVoigt(stiffness=400.0, damping=20.0, eps=1e-4, adhesive=True)
    system = aj.ImpactAbsorber(M=1.0, k=1e3, c=0.1, m=0.4, gap=0.0, contact=law)
    for u in [-3e-4, -1e-6, 0.0, 2e-5, 1e-3]:
        for w in [-0.2, 0.1]:
            f, _ = system.coupling(u, w, jnp.zeros(0))
            np.testing.assert_allclose(f, 400 * u + 20 * w, rtol=1e-13, atol=1e-16)


def test_coulomb_and_stribeck_formula_both_directions():
    N = 7.0
    c = aj.Coulomb(mu=0.5, eps=1e-6)
    s = aj.Stribeck(mu_c=0.5, mu_s=0.6, v_s=1e-2, eps=1e-6)
    for v in [-0.5, -0.01, -1e-3, 1e-3, 0.01, 0.5]:
        np.testing.assert_allclose(c.force(v, None, N), 0.5 * N * np.sign(v), rtol=1e-12)
        expect = N * (0.5 + 0.1 * np.exp(-((v / 1e-2) ** 2))) * np.sign(v)
        np.testing.assert_allclose(s.force(v, None, N), expect, rtol=1e-12)
    # the Stribeck law as printed (v_s = 1e4) is Coulomb with mu_s at any realistic speed
    printed = aj.Stribeck(mu_c=0.5, mu_s=0.6, v_s=1e4, eps=1e-6)
    np.testing.assert_allclose(printed.force(3.0, None, N), 0.6 * N, rtol=1e-7)


def test_friction_sign_convention_in_system():
    """Fnl > 0 when the primary slides forwards relative to the absorber (X' > 0): it drags
    the absorber along (positive acceleration) and brakes the primary."""
    system = aj.FrictionAbsorber(m1=1.0, k1=0.0, c1=0.0, m2=2.0, k2=0.0, c2=0.0,
                                 normal_force=4.0, friction=aj.Coulomb(mu=0.5, eps=1e-6))
    forcing = aj.Harmonic(amplitude=0.0, omega=1.0)
    for v1, v2 in [(1.0, 0.0), (0.0, 1.0)]:
        s = system.to_internal(jnp.array([0.0, v1, 0.0, v2]))
        a1, a2, _, _ = system.accelerations(0.0, s, forcing)
        X_dot = v1 - v2
        np.testing.assert_allclose(a2, np.sign(X_dot) * 0.5 * 4.0 / 2.0, rtol=1e-12)
        np.testing.assert_allclose(a1, -np.sign(X_dot) * 0.5 * 4.0 / 1.0, rtol=1e-12)
        # momentum: the friction pair exerts equal and opposite forces
        np.testing.assert_allclose(1.0 * a1 + 2.0 * a2, 0.0, atol=1e-12)


def test_dahl_and_lugre_formula():
    N, v, z = 10.0, 0.3, jnp.array([2e-4])
    dahl = aj.Dahl(mu_c=0.5, sigma0=1e4, eps=1e-8)
    np.testing.assert_allclose(dahl.force(v, z, N), 1e4 * 2e-4)
    np.testing.assert_allclose(dahl.state_rate(v, z, N)[0], v - 1e4 * abs(v) * 2e-4 / 5.0)
    lug = aj.LuGre(mu_c=0.5, mu_s=0.6, v_s=0.1, sigma0=1e4, sigma1=1e2, sigma2=3.0, eps=1e-8)
    g = 5.0 + 1.0 * np.exp(-((v / 0.1) ** 2))
    zdot = v - 1e4 * abs(v) * 2e-4 / g
    np.testing.assert_allclose(lug.state_rate(v, z, N)[0], zdot, rtol=1e-12)
    np.testing.assert_allclose(lug.force(v, z, N), 1e4 * 2e-4 + 1e2 * zdot + 3.0 * v, rtol=1e-12)
    for law in (dahl, lug):  # both sliding directions: odd in (v, z)
        np.testing.assert_allclose(law.force(-v, -z, N), -law.force(v, z, N), rtol=1e-12)


def test_scene_state_holds_only_what_its_law_needs():
    for name in aj.presets.IMPACT_SCENES:
        assert aj.presets.impact(name)[0].num_states == 4
    for name in ("coulomb", "stribeck"):
        assert aj.presets.friction(name)[0].num_states == 4
    for name in ("dahl", "lugre"):
        assert aj.presets.friction(name)[0].num_states == 5


def test_laws_are_differentiable_at_contact_onset():
    law = aj.HuntCrossley(stiffness=3260.0, damping=469.5, eps=1e-6, adhesive=True)
    g = jax.grad(lambda x: law.wall_force(x, 0.1)[0])
    for x in [-1e-5, 0.0, 1e-6, 1e-3]:
        assert np.isfinite(float(g(x)))
