"""Steady states and frequency sweeps against exact and independent references."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import references as R

import absorber_jax as aj


def closed_form_x1(M, k, c, m, kc, cc, F0, omegas):
    """|X1| of the linear two-mass system (primary M, k, c; absorber m on kc, cc)."""
    out = []
    for w in omegas:
        Z = np.array([[k + kc - w**2 * M + 1j * w * (c + cc), -kc - 1j * w * cc],
                      [-kc - 1j * w * cc, kc - w**2 * m + 1j * w * cc]])
        out.append(abs(np.linalg.solve(Z, [F0, 0.0])[0]))
    return np.array(out)


def test_zero_gap_impact_scene_matches_closed_form_frf():
    system, _ = aj.presets.impact("kelvin_voigt", gap=0.0)
    om = np.linspace(20.0, 80.0, 52)
    frf = aj.frequency_response(system, om, amplitude=2.0)
    assert np.all(frf.status == 0)
    exact = closed_form_x1(1.0, 1e3, 0.1, 0.4, 400.0, 20.0, 2.0, om)
    np.testing.assert_allclose(frf.harmonic, exact, rtol=1e-6)
    np.testing.assert_allclose(frf.amplitude, exact, rtol=1e-6)  # linear: harmonic = peak
    assert np.all(frf.stable) and np.all(frf.period_multiple == 1)


def test_zero_normal_force_friction_scene_matches_closed_form_frf():
    system = aj.FrictionAbsorber(m1=1.0, k1=1e4, c1=5.0, m2=0.2, k2=1.8e3, c2=2.0,
                                 normal_force=0.0, friction=aj.Coulomb(mu=0.5))
    om = np.linspace(60.0, 140.0, 50)
    frf = aj.frequency_response(system, om, amplitude=3.0)
    assert np.all(frf.status == 0)
    exact = closed_form_x1(1.0, 1e4, 5.0, 0.2, 1.8e3, 2.0, 3.0, om)
    np.testing.assert_allclose(frf.amplitude, exact, rtol=1e-6)
    # the Floquet multipliers of a linear system are exp(λ T) of its eigenvalues
    i = 10
    T = 2 * np.pi / om[i]
    Mm = np.diag([1.0, 0.2])
    K = np.array([[1.18e4, -1.8e3], [-1.8e3, 1.8e3]])
    C = np.array([[7.0, -2.0], [-2.0, 2.0]])
    A = np.block([[np.zeros((2, 2)), np.eye(2)],
                  [-np.linalg.solve(Mm, K), -np.linalg.solve(Mm, C)]])
    expect = np.sort(np.abs(np.exp(np.linalg.eigvals(A) * T)))
    np.testing.assert_allclose(np.sort(np.abs(frf.multipliers[i])), expect, rtol=1e-6)


@pytest.mark.parametrize("name, omega", [("kelvin_voigt", 40.0), ("kelvin_voigt", 47.4),
                                         ("hunt_crossley", 40.0), ("lugre", 40.0)])
def test_shooting_and_marching_agree_where_unique_and_stable(name, omega):
    if name in aj.presets.IMPACT_SCENES:
        system, forcing = aj.presets.impact(name, omega=omega)
    else:
        system, forcing = aj.presets.friction(name, ramp_time=None, amplitude=10.0, omega=omega)
        system = aj.replace_params(system, {"c1": 2.0})  # damped: a unique attracting orbit
    sh = aj.steady_state(system, forcing, method="shooting")
    ma = aj.steady_state(system, forcing, method="marching")
    assert int(sh.status) == 0 and int(ma.status) == 0
    assert bool(sh.stable) and bool(ma.stable)
    assert int(ma.period_multiple) == 1
    np.testing.assert_allclose(float(ma.amplitude), float(sh.amplitude), rtol=1e-4)
    np.testing.assert_allclose(float(ma.absorber_amplitude), float(sh.absorber_amplitude),
                               rtol=1e-4)


def test_55_rad_s_has_coexisting_responses_one_period_5():
    """Evidence: an event-exact (nonsmooth) march from rest settles on a period-5 impacting
    orbit (Poincaré samples recur after 5 periods to 1e-10, not after 1–4 or 6); shooting from
    the linear guess finds a stable non-impacting period-1 orbit."""
    system, forcing = aj.presets.impact("kelvin_voigt", omega=55.0)
    T = 2 * np.pi / 55.0
    P = 400
    x1_ref, _ = R.impact_kelvin_voigt(1.0, 1e3, 0.1, 0.4, 1e-3, 400.0, 20.0, 2.0, 55.0,
                                      np.arange(P + 1) * T)
    rec = [np.max(np.abs(x1_ref[-10:] - x1_ref[-10 - n: P + 1 - n])) for n in range(1, 7)]
    assert rec[4] < 1e-9 and min(rec[:4] + rec[5:]) > 1e-5, rec
    tt = np.linspace((P - 5) * T, P * T, 20001)
    x1d, x2d = R.impact_kelvin_voigt(1.0, 1e3, 0.1, 0.4, 1e-3, 400.0, 20.0, 2.0, 55.0,
                                     np.concatenate([[0.0], tt]))
    amp_ref = 0.5 * np.ptp(x1d[1:])

    ma = aj.steady_state(system, forcing, method="marching")
    assert int(ma.status) == 0 and int(ma.period_multiple) == 5 and bool(ma.stable)
    np.testing.assert_allclose(float(ma.amplitude), amp_ref, rtol=1e-3)
    assert float(ma.absorber_amplitude) > 1e-3  # impacting: beyond the clearance

    sh = aj.steady_state(system, forcing, method="shooting")
    assert int(sh.status) == 0 and int(sh.period_multiple) == 1 and bool(sh.stable)
    assert float(sh.absorber_amplitude) < 1e-3  # floats without touching the walls
    # the primary alone (absorber floating): F0 / |k - M ω² + i c ω|
    np.testing.assert_allclose(float(sh.amplitude), 2.0 / abs(1e3 - 55.0**2 + 5.5j), rtol=1e-5)
    # floating family: a double Floquet multiplier at 1
    mu = np.sort(np.abs(np.asarray(sh.multipliers)))
    np.testing.assert_allclose(mu[-2:], 1.0, atol=1e-3)  # Jordan block: split by ~sqrt(err)
    assert abs(float(ma.amplitude) - float(sh.amplitude)) > 0.1e-3  # really two responses


@pytest.mark.parametrize("omega", [70.0, 130.0])
def test_den_hartog_coulomb_forced_response(omega):
    m, k, mu, N, P = 1.0, 1e4, 0.5, 4.0, 10.0  # F/P = 0.2: continuous sliding
    system = aj.FrictionAbsorber(m1=m, k1=k, c1=0.0, m2=1e7, k2=0.0, c2=0.0, normal_force=N,
                                 friction=aj.Coulomb(mu=mu, eps=1e-5))
    ss = aj.steady_state(system, aj.Harmonic(amplitude=P, omega=omega))
    assert int(ss.status) == 0
    exact = R.den_hartog_amplitude(m, k, mu * N, P, omega)
    np.testing.assert_allclose(float(ss.amplitude), exact, rtol=2e-4)
    # and friction really matters here: the frictionless amplitude differs by > 1 %
    assert abs(exact - P / abs(k - m * omega**2)) / exact > 0.01


def test_failed_points_are_flagged_and_others_kept(monkeypatch):
    from absorber_jax._periodic import sweep as _sweep

    system, _ = aj.presets.impact("kelvin_voigt")
    om = np.linspace(40.0, 70.0, 8)
    # split as a large chunk's points are: a first pass of 2 Newton steps, the lanes still
    # iterating resumed from their last iterate (4-5 steps measured at 40-52 rad/s)
    monkeypatch.setattr(_sweep, "SMALL_CHUNK", 0)
    monkeypatch.setattr(_sweep, "FIRST_PASS_NEWTON", 2)
    full = aj.frequency_response(system, om, amplitude=2.0)
    assert np.all(full.status == 0)
    assert np.any(full.iterations > 2)                               # resumed lanes
    monkeypatch.undo()
    # a tiny step budget: the long low-frequency periods exhaust it, high ones do not
    tight = aj.frequency_response(system, om, amplitude=2.0, max_steps=120, retry=False)
    failed = tight.status != 0
    assert failed.any() and (~failed).any()
    assert set(tight.status[failed]) <= {aj.Status.MAX_STEPS, aj.Status.NO_CONVERGENCE}
    assert aj.Status.MAX_STEPS in set(tight.status[failed])
    np.testing.assert_allclose(tight.amplitude[~failed], full.amplitude[~failed], rtol=1e-6)
    # a one-step Newton budget fails where the guess is poor, not where it is exact
    one = aj.frequency_response(system, om, amplitude=2.0, newton_steps=1, retry=False)
    assert (one.status == aj.Status.NO_CONVERGENCE).any()
    ok = one.status == 0
    np.testing.assert_allclose(one.amplitude[ok], full.amplitude[ok], rtol=1e-6)
    # with the retry (the default) those points are marched onto the orbit instead
    rescued = aj.frequency_response(system, om, amplitude=2.0, newton_steps=1)
    assert np.all(rescued.status == 0)
    assert np.all(rescued.iterations[~ok] > 1)  # they were marched
    # (the marched orbits, independent of the resumed Newton lanes of `full`)
    np.testing.assert_allclose(rescued.amplitude, full.amplitude, rtol=1e-4)
    assert all("converge" in t or "max_steps" in t for _, t in tight.failures() + one.failures())


def test_impacts_per_period_equal_the_event_exact_wall_hits():
    """Table 1 from 40 to 70 rad/s (the sweep of the test above: one compilation): the
    impacts per period of each orbit equal the wall hits of the event-exact piecewise-linear
    flow from the orbit's state over 10 periods; 2 on the impacting orbits, none where the
    absorber floats."""
    system, _ = aj.presets.impact("kelvin_voigt")
    om = np.linspace(40.0, 70.0, 8)
    fr = aj.frequency_response(system, om, amplitude=2.0)
    assert np.all(fr.status == 0)
    for i, w in enumerate(om):
        hits = []
        R.impact_kelvin_voigt(1.0, 1e3, 0.1, 0.4, 1e-3, 400.0, 20.0, 2.0, w,
                              np.array([0.0, 20 * np.pi / w]), y0=tuple(fr.states[i]),
                              impacts=hits)
        assert fr.impacts[i] == len(hits) / 10, (w, fr.impacts[i], len(hits))
    assert set(fr.impacts) == {0.0, 2.0}


def test_design_grid_and_sequential_sweeps():
    system, _ = aj.presets.impact("kelvin_voigt", gap=0.0)
    om = np.linspace(30.0, 70.0, 6)
    k1 = np.array([200.0, 400.0, 800.0])
    grid = aj.frequency_response(system, om, amplitude=2.0, params={"k1": k1})
    assert grid.amplitude.shape == (3, 6)
    for i, kk in enumerate(k1):
        exact = closed_form_x1(1.0, 1e3, 0.1, 0.4, kk, 20.0, 2.0, om)
        np.testing.assert_allclose(grid.amplitude[i], exact, rtol=1e-6)
    up, down = aj.frequency_response(system, om, amplitude=2.0, direction="both")
    exact = closed_form_x1(1.0, 1e3, 0.1, 0.4, 400.0, 20.0, 2.0, om)
    np.testing.assert_allclose(up.amplitude, exact, rtol=1e-6)
    np.testing.assert_allclose(down.amplitude, exact, rtol=1e-6)
    assert up.direction == "up" and down.direction == "down"


def test_sweep_bad_input():
    system, _ = aj.presets.impact("kelvin_voigt")
    with pytest.raises(ValueError, match="omegas must hold at least 1"):
        aj.frequency_response(system, [], amplitude=2.0)
    with pytest.raises(ValueError, match="omegas must be strictly increasing"):
        aj.frequency_response(system, [50.0, 40.0], amplitude=2.0)
    with pytest.raises(ValueError, match=r"omegas must be > 0"):
        aj.frequency_response(system, [0.0, 40.0], amplitude=2.0)
    with pytest.raises(ValueError, match=r"ImpactAbsorber\.m must be in \(0"):
        aj.frequency_response(system, [40.0], amplitude=2.0, params={"m": [0.4, -1.0]})
    with pytest.raises(ValueError, match="has no parameter 'mass'"):
        aj.frequency_response(system, [40.0], amplitude=2.0, params={"mass": [1.0]})
    with pytest.raises(ValueError, match="forcing must be a Harmonic"):
        aj.steady_state(*aj.presets.friction("coulomb"))


def test_sweep_runs_sharded_over_two_cpu_devices():
    code = textwrap.dedent("""
        import jax, numpy as np, pytest, absorber_jax as aj
        assert aj.use_cpu_cores(2) == 2
        assert jax.local_device_count() == 2, jax.devices()
        assert aj.use_cpu_cores(2) == 2     # started already, with as many: nothing to do
        with pytest.raises(RuntimeError, match="before any JAX computation"):
            aj.use_cpu_cores(3)
        system, _ = aj.presets.impact("kelvin_voigt", gap=0.0)
        om = np.linspace(30.0, 70.0, 6)
        frf = aj.frequency_response(system, om, amplitude=2.0, chunk_size=4)
        # the chained chord sweep too: 3 lanes of 2 neighbours, padded to 4, 2 per device
        chord = aj.frequency_response(system, om, amplitude=2.0, chunk_size=3, root="chord")
        import json
        print(json.dumps([frf.amplitude.tolist(), frf.status.tolist(),
                          chord.amplitude.tolist(), chord.status.tolist()]))
    """)
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    amps, status, chord_amps, chord_status = json.loads(out.stdout.strip().splitlines()[-1])
    om = np.linspace(30.0, 70.0, 6)
    exact = closed_form_x1(1.0, 1e3, 0.1, 0.4, 400.0, 20.0, 2.0, om)
    np.testing.assert_allclose(amps, exact, rtol=1e-6)
    np.testing.assert_allclose(chord_amps, exact, rtol=1e-6)
    assert status == [0] * 6 and chord_status == [0] * 6


def test_devices_work_through_jobs_in_order_and_raise_what_a_job_raised():
    from absorber_jax._core.devices import on_devices

    ticks = []
    # jobs of unequal cost, more jobs than devices: each result lands at its job's place
    out = on_devices(lambda j, d: np.full(3, j) ** 2, list(range(7)), 2,
                     progress=ticks.append)
    assert [int(o[0]) for o in out] == [j * j for j in range(7)]
    assert sorted(ticks) == list(range(7))          # each finished job reported, by index

    def bad(j, d):
        if j == 3:
            raise FloatingPointError("job 3")
        return np.zeros(1)

    with pytest.raises(FloatingPointError, match="job 3"):
        on_devices(bad, list(range(6)), 2)
    with pytest.raises(ValueError, match="n must be a positive integer"):
        aj.use_cpu_cores(0)


def test_root_finders_return_their_best_iterate_at_a_noise_floor():
    """A period map integrated adaptively is noisy at the integration tolerance, and Newton
    wanders at that floor; the shooting root finders (Newton, chord, Broyden) return the
    iterate with the smallest residual they evaluated.  Here a residual with a deterministic
    jitter of 1e-6 (a stand-in for that noise; its derivative hidden, as a period map's
    jumps are from forward mode): every evaluation is recorded, and the iterate returned
    has the smallest residual of all, while the last iterates' are above 1e-6."""
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    from absorber_jax._periodic.shooting import _broyden, _root_solver

    seen = []

    def record(y, f):
        seen.append((np.asarray(y).copy(), float(np.max(np.abs(f)))))

    def residual(y, args):
        smooth = jnp.array([y[0] ** 3 + y[1] - 1.0, y[1] - 0.5 * y[0]])
        f = smooth + jax.lax.stop_gradient(1e-6 * jnp.sin(1e7 * y + jnp.array([0.3, 1.1])))
        jax.debug.callback(record, y, f, ordered=True)
        return f

    def check(x, name, wanders=True):
        x = np.asarray(x)
        sizes = [r for _, r in seen]
        mine = [r for y, r in seen if np.array_equal(y, x)]
        assert mine and mine[0] == min(sizes), name
        # (Newton and the chord wander at the floor: the last iterate is not the best)
        assert min(sizes) < 1e-6 and (not wanders or max(sizes[-5:]) > 1e-6), name

    # (the root is near (0.771, 0.385); the chord keeps its first Jacobian: a closer start)
    for name, y0 in (("newton", jnp.array([2.0, 1.0])), ("chord", jnp.array([0.8, 0.4]))):
        seen.clear()
        sol = optx.root_find(residual, _root_solver(name, 1e-9), y0, None, max_steps=30,
                             throw=False)
        check(sol.value, name)
    y0 = jnp.array([0.8, 0.4])
    H0 = jnp.linalg.inv(jax.jacfwd(lambda y: residual(y, None))(y0))
    seen.clear()
    x, k = _broyden(residual, y0, H0, None, 0.0, 30)
    assert int(k) == 30
    check(x, "broyden", wanders=False)


def test_a_flight_whose_apex_falls_on_a_sample_at_the_wall_is_an_apex_not_a_hold():
    # penetration -a (t - t5)²/2 sampled with its apex (zero, at rest) on sample 5: a grazing
    # flight; three samples at rest on the wall in a row are a hold
    from absorber_jax._periodic.orbit import free_flight_apexes

    dt, a = 0.01, 2.0
    t = np.arange(11) * dt
    pen = (-0.5 * a * (t - t[5]) ** 2)[:, None]
    rate = (-a * (t - t[5]))[:, None]
    acc = np.full_like(pen, -a)
    turn, heights, times = free_flight_apexes(pen, rate, acc, dt, 1.0, 1.0)
    k = np.flatnonzero(turn[:, 0])
    assert k.size == 1 and k[0] in (4, 5)
    assert abs(heights[k[0], 0]) < 1e-15 and abs(times[k[0], 0] - t[5]) < 1e-12
    held = pen.copy()
    held[4:7], rate2 = 0.0, rate.copy()
    rate2[4:7] = 0.0
    turn, _, _ = free_flight_apexes(held, rate2, acc, dt, 1.0, 1.0)
    assert not turn[3:7, 0].any()
