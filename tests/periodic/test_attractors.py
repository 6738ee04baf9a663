"""Attractor maps: many initial states marched at once, the coexisting responses
with their shares and statistics, non-periodic responses flagged and measured; against
event-exact and exact piecewise-linear references."""

import numpy as np
import pytest
import reference_nlvib03 as ref03
import references as R
from builders import nlvib03

import absorber_jax as aj
from absorber_jax._periodic.attractors import samples_per_period


def test_table1_at_55_finds_the_period_5_orbit_and_the_floating_period_1_orbit():
    """Table 1 at 55 rad/s: the attractor map finds both coexisting responses: the
    period-5 impacting orbit (x1 amplitude against an event-exact march, 1e-3; impacts per
    period equal to the event-exact march's wall hits) and the floating period-1 orbit (the
    primary alone, closed form, 1e-5; no impact), with shares adding to 1."""
    system, forcing = aj.presets.impact("kelvin_voigt", omega=55.0)
    m = aj.attractors(system, forcing, samples=16, n_max=6, max_periods=1200)
    found = {a.period_multiple: a for a in m.attractors}
    print([a.summary() for a in m.attractors])
    assert set(found) == {1, 5}
    assert abs(sum(a.share for a in m.attractors) - 1.0) < 1e-12
    assert np.all(m.label >= 0)
    # period 5: event-exact (nonsmooth) march from rest, the last 5 periods of 400
    T = 2 * np.pi / 55.0
    tt = np.linspace(395 * T, 400 * T, 20001)
    hits = []
    x1, _ = R.impact_kelvin_voigt(1.0, 1e3, 0.1, 0.4, 1e-3, 400.0, 20.0, 2.0, 55.0,
                                  np.concatenate([[0.0], tt]), impacts=hits)
    amp5 = 0.5 * np.ptp(x1[1:])
    p5, p1 = found[5], found[1]
    assert abs(p5.amplitude - amp5) < 1e-3 * amp5
    assert p5.periodic and p5.converged and p5.stable
    hits = np.asarray(hits)
    per5 = np.sum((hits >= 395 * T) & (hits < 400 * T)) / 5
    print(f"impacts per period: {p5.impacts} (event-exact {per5}), floating {p1.impacts}")
    assert per5 > 0 and p5.impacts == pytest.approx(per5, abs=1e-12)
    assert p1.impacts == 0.0
    # its stroboscopic samples take 5 distinct values, repeating
    sec = m.section[p5.members[0]]
    assert np.max(np.abs(sec[5:] - sec[:-5])) < 1e-6 * p5.amplitude
    assert np.min(np.abs(sec[1:5] - sec[0])) > 1e-2 * p5.amplitude
    # period 1: the absorber floats, the primary moves alone
    lin = 2.0 / abs(1e3 - 55.0**2 + 5.5j)
    assert abs(p1.amplitude - lin) < 1e-5 * lin and p1.periodic
    assert p5.peak >= p5.amplitude * (1 - 1e-9) and p1.peak >= p1.amplitude * (1 - 1e-9)
    # the period-5 orbit's largest Lyapunov exponent (median over its lanes, 30 periods of
    # tangent growth) against its Floquet multipliers: ln|mu|max / 5T (measured 1 %)
    floquet = np.log(np.max(np.abs(p5.multipliers))) / (5 * T)
    print(f"Lyapunov {p5.lyapunov:.5f} / s, Floquet {floquet:.5f} / s")
    assert floquet < 0 and abs(p5.lyapunov - floquet) < 0.05 * abs(floquet)
    assert p5.kind == p1.kind == "periodic"


def test_non_periodic_response_is_flagged_and_measured():
    """NLvib 03 at Ω = 0.6, inside the Neimark–Sacker window: no periodic orbit is stable.
    The response is flagged (not periodic, status NOT_PERIODIC, a wide Poincaré section);
    its stroboscopic statistics equal those of the exact piecewise-linear flow iterated from
    the same initial state (1000 periods after 400), and its largest Lyapunov exponent equals
    a Benettin estimate on the exact map (its exact Jacobian, renormalised each period) from
    the window's start, within the scatter of such estimates over a window of its length.
    It is positive (0.013 / s, 0.14 per period, ~130 / (window T)): the torus born at the
    Neimark–Sacker point has broken into a weakly chaotic attractor, and the map says so."""
    sysm, W = nlvib03(), 0.6
    m = aj.attractors(sysm, aj.Harmonic(amplitude=0.1, omega=W), samples=2, n_max=8,
                      max_periods=400, window=1000)
    assert len(m.attractors) == 1
    a = m.attractors[0]
    assert not a.periodic and a.share == 1.0 and a.spread > 0.1
    assert np.all(np.asarray(m.steady.status) == aj.Status.NOT_PERIODIC)
    for k in range(2):
        x, sec = np.asarray(m.initial_states[k]), []
        for _ in range(1400):
            x = ref03.period_map(x, W)
            sec.append(x[1])
        ref = np.array(sec[400:])
        ours = m.section[k]
        span = np.ptp(ref)
        print(f"lane {k}: RMS {np.sqrt(np.mean(ours**2)):.5f} vs {np.sqrt(np.mean(ref**2)):.5f}, "
              f"range [{ours.min():.4f}, {ours.max():.4f}] vs [{ref.min():.4f}, {ref.max():.4f}]")
        assert abs(np.sqrt(np.mean(ours**2)) - np.sqrt(np.mean(ref**2))) < 1e-2 * span
        assert abs(ours.mean() - ref.mean()) < 1e-2 * span
        # the section's extent: its 2 % and 98 % quantiles (measured within 0.8 % of the
        # span of the exact map's, whose own 1000-period windows agree to 0.4 %), and its
        # extremes, which are single samples of a chaotic sequence: the exact map's
        # 1000-period windows differ by up to 4 % of the span in their maximum (0.057 ..
        # 0.074 over periods 400 .. 3400), so the extremes are held to 10 %
        for q in (2, 98):
            assert abs(np.percentile(ours, q) - np.percentile(ref, q)) < 2e-2 * span
        assert abs(ours.min() - ref.min()) < 0.1 * span
        assert abs(ours.max() - ref.max()) < 0.1 * span
    # the designer's number: the largest |q2| over the window, finite and above the RMS
    assert np.all(np.isfinite(m.peak)) and np.all(m.peak > m.rms)
    # the largest Lyapunov exponent of each lane against Benettin's on the exact map: a
    # 750-period average (the library's window) of a chaotic orbit is a random draw, so the
    # reference is the exact map's long-run average (5750 periods) and the tolerance three
    # standard deviations of its own 750-period windows (measured 0.0017 / s, 15 % of the
    # mean: the windows range 0.0092 .. 0.0149 / s)
    x = np.asarray(m.steady.state[0], dtype=float)
    v = np.ones_like(x) / np.sqrt(x.size)
    logs = []
    for _ in range(6000):
        shot = ref03.shoot(x, W)                 # the map and its exact Jacobian
        dv = shot["mon"] @ v
        logs.append(np.log(np.linalg.norm(dv)))
        x, v = shot["xT"], dv / np.linalg.norm(dv)
    logs = np.asarray(logs[250:]) * W / (2 * np.pi)
    lam = logs.mean()
    spread = np.std([logs[i:i + 750].mean() for i in range(0, logs.size - 749, 750)])
    print(f"largest Lyapunov exponents {m.lyapunov} / s (exact map, Benettin {lam:.5f} "
          f"+- {spread:.5f} over 750-period windows)")
    assert lam > 5 * spread                              # positive beyond doubt: chaotic
    assert np.all(np.abs(np.asarray(m.lyapunov) - lam) < 3 * spread)
    assert a.kind == "chaotic"


def test_bad_input_is_named():
    system, forcing = aj.presets.impact("kelvin_voigt", omega=55.0)
    with pytest.raises(ValueError, match="samples"):
        aj.attractors(system, forcing, samples=0)
    with pytest.raises(ValueError, match="initial_states"):
        aj.attractors(system, forcing, initial_states=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="spread"):
        aj.attractors(system, forcing, spread=-1.0)
    with pytest.raises(ValueError, match="Marching.n_max"):
        aj.attractors(system, forcing, n_max=0)
    with pytest.raises(ValueError, match=r"window must be an integer >= 7 \(n_max \+ 1\)"):
        aj.attractors(system, forcing, n_max=6, window=6)
    with pytest.raises(ValueError, match="omegas"):
        aj.bifurcation_diagram(system, forcing, [-1.0])
    with pytest.raises(ValueError, match="resolution must be an integer >= 2"):
        aj.attractors(system, forcing, resolution=1)
    with pytest.raises(ValueError, match="give_up must be None or a positive integer"):
        aj.attractors(system, forcing, give_up=0)


def test_impacts_of_a_hard_contact_are_counted_against_an_event_exact_reference():
    """A hard Kelvin–Voigt contact (1e6 N/m, contact time ~3 ms against a 157 ms period) at
    40 rad/s, where no periodic orbit is stable: each lane's impacts over a window of 2
    periods equal the wall hits of an event-exact march from the same state (the response is
    chaotic: the smoothed and the exact contact drift apart after ~2 periods; sampled at a
    plain 64 per period, the count over 40 periods would be 30 % low)."""
    system = aj.ImpactAbsorber(M=1.0, k=1e3, c=0.1, m=0.4, gap=1e-3,
                               contact=aj.KelvinVoigt(stiffness=1e6, damping=20.0, adhesive=True))
    w = 40.0
    assert samples_per_period(system, w) >= 256
    m = aj.attractors(system, aj.Harmonic(amplitude=2.0, omega=w), samples=3, n_max=1,
                      max_periods=200, window=2)
    T = 2 * np.pi / w
    for k in range(3):
        hits = []
        R.impact_kelvin_voigt(1.0, 1e3, 0.1, 0.4, 1e-3, 1e6, 20.0, 2.0, w,
                              np.array([0.0, 2 * T]), y0=tuple(m.steady.state[k]),
                              impacts=hits)
        print(f"lane {k}: {m.impacts[k] * 2:.0f} impacts in 2 periods (event-exact {len(hits)})")
        assert len(hits) >= 4 and m.impacts[k] * 2 == len(hits)


def test_marching_gives_up_only_on_responses_that_cannot_settle_within_the_budget():
    """``Marching(give_up=100)`` on a lightly damped linear oscillator (1 DOF, ω_n = 1,
    forced at 1.3 rad/s): the transient decays by ρ = exp(-ζ ω_n T) per period.  With
    ζ = 3.1e-3 (ρ = 0.985, ~920 periods to 1e-6) the march still runs to convergence,
    period for period as without give_up, on the closed-form amplitude; with ζ = 2e-4
    (ρ = 0.999, 0.999^2000 = 0.14: no chance within 2000 periods) it stops after ~100
    periods with the status the whole budget gives."""
    w = 1.3
    for zeta, settles in ((3.1e-3, True), (2e-4, False)):
        st = aj.structure_from_matrices(np.eye(1), np.eye(1), damping=2 * zeta * np.eye(1))
        system = aj.StructuralSystem(st, [], load="x1", observe="x1")
        forcing = aj.Harmonic(amplitude=1.0, omega=w)
        full, quick = (aj.steady_state(system, forcing, method=aj.Marching(
            max_periods=2000, tol=1e-6, give_up=g)) for g in (None, 100))
        assert int(quick.status) == int(full.status)
        if settles:
            assert int(full.status) == aj.Status.SUCCESS
            assert int(quick.iterations) == int(full.iterations) > 400
            exact = 1.0 / abs(1.0 - w**2 + 2j * zeta * w)
            assert abs(float(quick.amplitude) / exact - 1) < 1e-6
        else:
            assert int(full.status) == aj.Status.NOT_PERIODIC
            assert int(full.iterations) == 2000 and int(quick.iterations) <= 200


def test_flow_along_is_the_flow_derivative_along_one_direction():
    """``flow_along`` (state and one tangent in one integration, the Lyapunov exponent's
    integrator) against the flow's full Jacobian (matrix sensitivity equations) applied to the
    same direction, and its state against the plain flow: the Table 1 absorber over one
    period from an impacting state."""
    import jax
    import jax.numpy as jnp

    from absorber_jax._integration.flow import (
        accurate_tangents,
        flow_along,
        integrate_flow,
        make_config,
    )

    system, forcing = aj.presets.impact("kelvin_voigt", omega=40.0)
    cfg = make_config(system, forcing, rtol=1e-10, atol=1e-10)
    dyn = (system, forcing)
    T = 2 * np.pi / 40.0
    x = jnp.array([0.3, -0.2, 1.5, 0.4])
    v = jnp.array([0.5, -1.0, 0.25, 2.0])
    ys, vs, st = flow_along(dyn, x, v, T, jnp.array([0.5 * T, T]), cfg)
    assert int(st) == aj.Status.SUCCESS
    J = jax.jacfwd(lambda z: integrate_flow(dyn, z, T, None, cfg=accurate_tangents(cfg))[0][-1])(x)
    ref = np.asarray(J @ v)
    assert np.max(np.abs(np.asarray(vs[-1]) - ref)) < 1e-6 * np.max(np.abs(ref))
    plain = np.asarray(integrate_flow(dyn, x, T, None, cfg=cfg)[0][-1])
    assert np.max(np.abs(np.asarray(ys[-1]) - plain)) < 1e-7 * np.max(np.abs(plain))


def test_a_periodic_label_never_goes_with_a_chaotic_lyapunov_exponent():
    # the hard rigid-impact scene near the resonance of primary and ball held together
    # (sqrt(k / (M + m)) = 28.9 rad/s): the primary's stroboscopic samples repeat to 1e-3
    # of its amplitude while the chattering ball's motion diverges (λ ≈ 20 /s); such a lane
    # is chaotic, not periodic, in the map, its attractors and the bifurcation diagram's
    # colours alike
    from absorber_jax._periodic.attractors import CHAOS_MARGIN

    system = aj.ImpactAbsorber(M=1.0, k=1e3, c=0.5, m=0.2, gap=2e-3,
                               contact=aj.Restitution(0.947))
    forcing = aj.Harmonic(amplitude=3.0, omega=28.8)
    am = aj.attractors(system, forcing, samples=8)
    chaos = CHAOS_MARGIN * 28.8 / (2 * np.pi * 40)
    lyap, periods = np.asarray(am.lyapunov), am.periods()
    assert np.all(lyap > chaos)            # every lane here diverges from its neighbours
    assert np.all(periods == 0), periods
    for a in am.attractors:
        assert a.kind == "chaotic" and not a.periodic and a.period_multiple == 0
