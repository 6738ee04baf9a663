"""Rigid impacts on an undamped primary against the closed-form symmetric two-impact orbits
of Masri & Caughey (tests/reference_masri_caughey.py): the closed form checked against the
event-exact simulation of tests/reference_impacts.py, then ``steady_state`` from a perturbed
closed-form state: the orbit, impacts per period, amplitude, Floquet multipliers (central
differences of the event-exact period map) and the stability label, on stable and unstable
orbits of both roots."""

import numpy as np
import pytest
from reference_impacts import RigidImpactAbsorber
from reference_masri_caughey import MasriCaughey

import absorber_jax as aj
from absorber_jax._periodic.orbit import SAMPLES_PER_PERIOD

M, K, F0 = 1.0, 1e3, 3.0
W0 = np.sqrt(K / M)

# (m/M, e, gap, W/w0, root, stable): ``root`` indexes the valid orbits in order of x0
# (the impact position on the wall u = +d); ``stable`` as the reference's multipliers say
# (largest |mu| in the comment), which keeps both kinds in the set
CASES = [
    (0.05, 0.5, 0.03, 1.1, 0, False),   # 51.7
    (0.05, 0.5, 0.03, 1.1, 1, True),    # 0.936 (complex pair)
    (0.1, 0.5, 0.03, 0.8, 0, False),    # 1.70
    (0.1, 0.5, 0.03, 0.8, 1, True),     # 0.699
    (0.1, 0.7, 0.01, 1.2, 0, False),    # 343; its peak lies within T/256 of an impact
    (0.1, 0.7, 0.01, 1.2, 1, True),     # 0.963
    (0.2, 0.9, 0.03, 0.9, 0, False),    # 2.29 and 1.33
    (0.2, 0.9, 0.03, 0.9, 1, False),    # 24.3
    (0.2, 0.7, 0.01, 1.1, 0, True),     # 0.920; the other root lets the ball through a wall
    (0.1, 0.9, 0.003, 1.2, 0, False),   # 13.7
]
IDS = [f"mu{c[0]}-e{c[1]}-d{c[2]}-r{c[3]}-root{c[4]}" for c in CASES]


def scene(mu, e, d, r):
    W = r * W0
    mc = MasriCaughey(M, K, mu * M, d, e, F0, W)
    ref = RigidImpactAbsorber(M, K, 0.0, mu * M, d, e, F0, W)
    return mc, ref, W, np.array([d, d * W, d, d * W])


def reference_multipliers(ref, y0, T, scale):
    """Eigenvalues of the monodromy matrix of the event-exact period map (central
    differences, steps 1e-7 of the state's scale)."""
    J = np.zeros((4, 4))
    for i in range(4):
        h = np.zeros(4)
        h[i] = 1e-7 * scale[i]
        J[:, i] = (ref.run(y0 + h, 0.0, T)[0][-1] - ref.run(y0 - h, 0.0, T)[0][-1]) / (2 * h[i])
    return np.linalg.eigvals(J)


def sampled_amplitude(x):
    """Half peak-to-peak of the periodic samples ``x``, each extreme refined by the parabola
    through it and its two neighbours (the estimate the library makes from its samples)."""

    def peak(y):
        i = int(np.argmax(y))
        a, b, c = y[i - 1], y[i], y[(i + 1) % len(y)]
        return b - 0.125 * (a - c) ** 2 / (a - 2 * b + c)

    return 0.5 * (peak(x) + peak(-x))


@pytest.mark.parametrize("mu, e, d, r, root, stable", CASES, ids=IDS)
def test_closed_form_orbit_is_periodic_for_the_event_exact_reference(mu, e, d, r, root, stable):
    mc, ref, W, scale = scene(mu, e, d, r)
    orbits = mc.valid_orbits()
    orb = orbits[root]
    T = mc.T
    # the five linear equations and the closure hold to rounding
    res = mc.residuals(orb.x0, orb.v_minus, orb.v_plus, orb.V, orb.C, orb.S)
    units = np.array([M * d * W, d * W, d, d, d * W, mc.X**2])
    assert np.max(np.abs(res) / units) < 1e-12
    assert orb.approach > 0 and orb.max_excursion < 1.0
    # one period of the event-exact simulation from the closed-form state
    ts = np.linspace(0.0, T, 65)
    ys, events = ref.run(orb.state, 0.0, T, ts)
    assert np.max(np.abs(ys[-1] - orb.state) / scale) < 1e-10
    assert [k for _, k in events] == ["impact", "impact"]
    t_pred = np.sort([orb.t_impact % T, (orb.t_impact + T / 2) % T])
    np.testing.assert_allclose([t for t, _ in events], t_pred, rtol=0, atol=1e-12 * T)
    # the analytic trajectory along the way (samples at the impacts are skipped: the
    # reference gives the state before, the closed form after)
    keep = np.min(np.abs(ts[:, None] - np.array([t for t, _ in events])[None]), axis=1) > 1e-9
    assert np.max(np.abs(mc.trajectory(orb, ts[keep]) - ys[keep]) / scale) < 1e-10
    # the amplitude: no sample of a fine grid exceeds it, the best comes within rounding
    x1 = mc.trajectory(orb, np.linspace(0.0, T, 20001))[:, 0]
    assert np.max(np.abs(x1)) <= orb.amplitude * (1 + 1e-14)
    assert np.max(np.abs(x1)) >= orb.amplitude * (1 - 1e-6)
    # the case's stability label as the reference's multipliers give it
    mu_ref = np.abs(reference_multipliers(ref, orb.state, T, scale))
    assert bool(np.max(mu_ref) < 1.0) == stable


# tight tolerances (the default shooting tol 1e-6 and integrator rtol 1e-9 would bound
# the state's error near 1e-7); no retry: a failed Newton solve must show as a failure,
# not as an orbit marched from rest
TIGHT = dict(method=aj.Shooting(tol=1e-12, retry=False),
             integrator=aj.Integrator(rtol=1e-12, atol=1e-12))


@pytest.mark.parametrize("mu, e, d, r, root, stable", CASES, ids=IDS)
def test_steady_state_matches_the_masri_caughey_orbit(mu, e, d, r, root, stable):
    mc, ref, W, scale = scene(mu, e, d, r)
    orb = mc.valid_orbits()[root]
    T = mc.T
    system = aj.ImpactAbsorber(M=M, k=K, c=0.0, m=mu * M, gap=d, contact=aj.Restitution(e))
    # the exact state as the guess would be accepted as it stands (no Newton step): start
    # 1e-4 of the scale away (1e-2 sends the most unstable orbit, |mu| = 343, to its
    # stable twin)
    guess = orb.state + 1e-4 * scale * np.array([1.0, -1.0, -1.0, 1.0])
    ss = aj.steady_state(system, aj.Harmonic(amplitude=F0, omega=W), guess=guess, **TIGHT)
    assert int(ss.status) == 0
    assert int(ss.iterations) >= 1
    assert int(ss.period_multiple) == 1
    assert float(ss.impacts) == 2.0
    # the orbit: measured ~1e-12 of the scale
    y = np.asarray(ss.state)
    assert np.max(np.abs(y - orb.state) / scale) < 1e-8
    # the amplitude is the parabola-refined maximum of SAMPLES_PER_PERIOD uniform samples:
    # it equals the same estimate from the closed form's samples (measured <= 4e-12
    # relative), and the true max |x1| within the estimate's own error: 3e-9 to 3.3e-7 on
    # these cases, 4.6e-6 where the peak lies within a sample of an impact (a kink in x1)
    ts = np.arange(SAMPLES_PER_PERIOD) * (T / SAMPLES_PER_PERIOD)
    est = sampled_amplitude(mc.trajectory(orb, ts)[:, 0])
    amp = float(ss.amplitude)
    np.testing.assert_allclose(amp, est, rtol=1e-9)
    floor = abs(est / orb.amplitude - 1)
    assert abs(amp / orb.amplitude - 1) < max(1e-6, 3 * floor), (amp, orb.amplitude, floor)
    # Floquet multipliers and the stability label (measured: |mu| to 5e-7 relative)
    mu_ref = np.sort(np.abs(reference_multipliers(ref, orb.state, T, scale)))
    mu_lib = np.sort(np.abs(np.asarray(ss.multipliers)))
    np.testing.assert_allclose(mu_lib, mu_ref, rtol=1e-5, atol=1e-6)
    assert bool(ss.stable) == bool(mu_ref[-1] < 1.0) == stable


def test_reference_finds_no_orbit_or_rejects_unphysical_roots():
    # no real root of the closure (the linear part cannot meet |(C, S)| = |X|)
    assert MasriCaughey(M, K, 0.2 * M, 0.03, 0.5, F0, 1.3 * W0).orbits() == ()
    # two roots, one physical: the other's ball crosses a wall between the impacts
    orbits = MasriCaughey(M, K, 0.2 * M, 0.01, 0.7, F0, 1.1 * W0).orbits()
    assert len(orbits) == 2 and [o.valid for o in orbits].count(True) == 1
    bad = next(o for o in orbits if not o.valid)
    assert bad.max_excursion > 1.0 or bad.approach <= 0.0
    with pytest.raises(ValueError, match="resonance"):
        MasriCaughey(M, K, 0.1, 0.01, 0.7, F0, W0)
