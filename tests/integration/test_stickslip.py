"""The exact (event-driven) stick–slip mode of Coulomb and Stribeck friction: against the
independent scipy event-exact references, exact linear results while stuck, Den Hartog,
homogeneity, finite differences, and the smoothed laws converging to it."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import references as R
import scipy.linalg as sl

import absorber_jax as aj
from absorber_jax._periodic.steady import make_config, period_map, state_scale

# the stick–slip scene: a 0.1 kg absorber on k2 = 1e3, stick–slip at 70 rad/s under 20 N
BASE = dict(m1=1.0, k1=1e4, c1=2.0, m2=0.1, k2=1e3, c2=0.0)
COULOMB = dict(mu=0.5)
STRIBECK = dict(mu_c=0.4, mu_s=0.5, v_s=0.05)


def scene(N=4.0, law=None):
    return aj.FrictionAbsorber(**BASE, normal_force=N, friction=law or aj.Coulomb(**COULOMB))


FORCING = aj.Harmonic(amplitude=20.0, omega=70.0)


def test_memoryless_laws_default_to_exact_and_eps_asks_for_smoothing():
    assert aj.Coulomb(mu=0.5).exact and aj.Stribeck(0.5, 0.6, 1e-2).exact
    assert not aj.Coulomb(mu=0.5, eps=1e-4).exact
    assert not aj.Stribeck(0.5, 0.6, 1e-2, eps=1e-4).exact
    with pytest.raises(ValueError, match="exact must be True or False"):
        aj.Coulomb(mu=0.5, exact="yes")


@pytest.mark.parametrize("law", ["coulomb", "stribeck"])
def test_exact_mode_matches_event_exact_scipy_reference(law):
    if law == "coulomb":
        system = scene(law=aj.Coulomb(**COULOMB))
        ref = R.friction_coulomb(*BASE.values(), 0.5, 4.0, 20.0, 70.0, np.linspace(0, 1, 2001))
    else:
        system = scene(law=aj.Stribeck(**STRIBECK))
        ref = R.friction_stick_slip(*BASE.values(), 0.4, 0.5, 0.05, 4.0, 20.0, 70.0,
                                    np.linspace(0, 1, 2001))
    tr = aj.simulate(system, FORCING, 1.0, ts=np.linspace(0, 1, 2001), rtol=1e-11, atol=1e-13)
    x1r, x2r = ref
    assert int(tr.status) == 0
    scale = np.max(np.abs(x1r))
    assert np.max(np.abs(np.asarray(tr.x1) - x1r)) / scale < 1e-8
    assert np.max(np.abs(np.asarray(tr.x2) - x2r)) / scale < 1e-8
    # it really sticks and slips: both regimes fill a good part of the second
    sliding = np.asarray(tr.sliding)
    assert 0.2 < sliding.mean() < 0.95


def test_smoothed_laws_converge_to_exact_mode_at_a_fitted_rate():
    ts = np.linspace(0, 0.3, 601)
    exact = aj.simulate(scene(), FORCING, 0.3, ts=ts, rtol=1e-11, atol=1e-13)
    scale = np.max(np.abs(np.asarray(exact.x1)))
    eps = np.array([1e-2, 3e-3, 1e-3, 3e-4])
    err = []
    for e in eps:
        tr = aj.simulate(scene(law=aj.Coulomb(mu=0.5, eps=float(e))), FORCING, 0.3, ts=ts,
                         rtol=1e-10, atol=1e-12)
        err.append(np.max(np.abs(np.asarray(tr.x1 - exact.x1))) / scale)
    err = np.array(err)
    rate = np.polyfit(np.log(eps), np.log(err), 1)[0]
    assert np.all(np.diff(err) < 0), err
    assert 0.6 < rate < 1.4, (rate, err)  # tanh smoothing: first order in eps


def test_70_rad_s_case_converges_stable_with_quadratic_newton():
    # Tsit5 shooting on the smoothed law with state-controlled steps diverges (|μ| 1e66) and
    # marching calls the orbit unstable; Kvaerno5 finds 4.3366 mm, |μ|max = 0.86
    ss = aj.steady_state(scene(), FORCING)
    assert int(ss.status) == 0
    assert bool(ss.stable)
    np.testing.assert_allclose(float(ss.amplitude), 4.3366e-3, atol=1e-7)
    assert int(ss.iterations) <= 8  # quadratic convergence (6 measured)
    mu = np.sort(np.abs(np.asarray(ss.multipliers)))
    np.testing.assert_allclose(mu[-1], 0.86, atol=0.01)


# (slow: shooting = marching in stick-slip is also asserted, Coulomb, by
# test_failed_shooting_is_retried_by_marching_then_polished)
@pytest.mark.parametrize("law", [pytest.param("coulomb", marks=pytest.mark.slow),
                                 pytest.param("stribeck", marks=pytest.mark.slow)])
def test_shooting_and_marching_agree_in_stick_slip(law):
    system = scene(law=aj.Coulomb(**COULOMB) if law == "coulomb" else aj.Stribeck(**STRIBECK))
    key = lambda m: np.sort_complex(np.round(np.asarray(m), 8))
    sh = aj.steady_state(system, FORCING)  # from the linear guess
    ma = aj.steady_state(system, FORCING, method="marching")  # from rest
    # each method started on the other's orbit stays there, with the same multipliers
    for a, b in ((sh, aj.steady_state(system, FORCING, method="marching", guess=sh.state)),
                 (ma, aj.steady_state(system, FORCING, guess=ma.state))):
        assert int(a.status) == 0 and int(b.status) == 0
        np.testing.assert_allclose(float(b.amplitude), float(a.amplitude), rtol=1e-6)
        np.testing.assert_allclose(key(b.multipliers), key(a.multipliers), atol=1e-6)
        assert bool(a.stable) and bool(b.stable)
    if law == "coulomb":  # one response
        np.testing.assert_allclose(float(ma.amplitude), float(sh.amplitude), rtol=1e-6)
    else:  # velocity weakening: a second stable orbit, reached from rest (4.505 mm)
        assert float(ma.amplitude) - float(sh.amplitude) > 1e-4


def test_fully_stuck_orbit_has_the_stuck_linear_systems_multipliers():
    system = scene(N=100.0)  # the holding force stays far below mu N = 50 N
    ss = aj.steady_state(system, FORCING)
    assert int(ss.status) == 0
    m, k, c = 1.1, 1e4, 2.0
    A = np.array([[0.0, 1.0], [-k / m, -c / m]])
    lam = np.linalg.eigvals(sl.expm(A * float(FORCING.period)))
    mult = np.asarray(ss.multipliers)
    # the stuck system's pair, plus the frozen relative position (1) and velocity (0)
    pair = mult[np.argsort(np.abs(mult - 1.0))[-2:]]
    np.testing.assert_allclose(np.sort_complex(pair), np.sort_complex(lam), atol=1e-6)
    assert np.sum(np.abs(mult - 1.0) < 1e-6) >= 1
    np.testing.assert_allclose(float(ss.amplitude), 20.0 / abs(k - m * 70.0**2 + 70j * c),
                               rtol=1e-6)
    assert bool(ss.stable)


def test_monodromy_matches_finite_differences_through_the_switches():
    system = scene(N=1.0)
    ss = aj.steady_state(system, FORCING)
    assert int(ss.status) == 0
    x = system.to_internal(ss.state) / state_scale(system, FORCING)
    assert abs(float(x[3])) > 0.1  # slipping at t = 0: the period map is smooth there
    cfg = make_config(system, FORCING, "tsit5", 1e-12, 1e-12, 100_000)
    P = jax.jit(lambda y: period_map(system, FORCING, y, 1, cfg)[0])
    J = np.asarray(jax.jacfwd(P)(x))
    h = 1e-6
    Jfd = np.stack([(P(x + h * e) - P(x - h * e)) / (2 * h) for e in np.eye(4)], axis=1)
    assert np.max(np.abs(J - Jfd)) < 1e-6 * np.max(np.abs(Jfd)) + 1e-8


# (N = 4 N, the 70 rad/s case, sticks every cycle; tests/periodic/test_reverse.py checks
# jax.grad there)
@pytest.mark.slow
@pytest.mark.parametrize("N", [2.0])
def test_gradient_wrt_normal_force_matches_central_differences_in_stick_slip(N):
    _, grads, status = aj.value_and_grad(scene(N=N), ["N"], [70.0], amplitude=20.0,
                                         objective="amplitude")
    assert np.all(status == 0)
    amp = lambda n: float(aj.steady_state(scene(N=n), FORCING, tol=1e-10, rtol=1e-12,
                                          atol=1e-12, floquet=False).amplitude)
    h = 1e-4 * N
    fd = (amp(N + h) - amp(N - h)) / (2 * h)
    np.testing.assert_allclose(grads["N"], fd, rtol=1e-4)


@pytest.mark.parametrize("ratio", [0.8, pytest.param(1.5, marks=pytest.mark.slow), 3.0])
def test_den_hartog_at_the_defaults(ratio):
    m, k, mu, N, P = 1.0, 1e4, 0.5, 4.0, 10.0
    system = aj.FrictionAbsorber(m1=m, k1=k, c1=0.0, m2=1e7, k2=0.0, c2=0.0, normal_force=N,
                                 friction=aj.Coulomb(mu=mu))
    omega = ratio * np.sqrt(k / m)
    ss = aj.steady_state(system, aj.Harmonic(amplitude=P, omega=omega))
    assert int(ss.status) == 0
    exact = R.den_hartog_amplitude(m, k, mu * N, P, omega)
    np.testing.assert_allclose(float(ss.amplitude), exact, rtol=1e-4)
    assert abs(exact - P / abs(k - m * omega**2)) / exact > 0.01  # friction matters here


@pytest.mark.parametrize("law", ["coulomb", pytest.param("stribeck", marks=pytest.mark.slow)])
def test_homogeneity_over_six_decades_at_the_defaults(law):
    # scaling F0 and N (and v_s) by s scales the whole response by s
    amps = []
    for s in (1e-3, 1.0, 1e3):
        fr = (aj.Coulomb(**COULOMB) if law == "coulomb" else
              aj.Stribeck(mu_c=0.4, mu_s=0.5, v_s=0.05 * s))
        ss = aj.steady_state(scene(N=4.0 * s, law=fr), aj.Harmonic(amplitude=20.0 * s,
                                                                     omega=70.0))
        assert int(ss.status) == 0
        amps.append(float(ss.amplitude) / s)
        assert bool(ss.stable)
    np.testing.assert_allclose(amps, amps[1], rtol=1e-6)


def test_exact_mode_runs_under_vmap_with_per_point_status():
    omegas = jnp.linspace(60.0, 130.0, 8)
    frf = aj.frequency_response(scene(), omegas, amplitude=20.0)
    assert np.all(frf.status == 0), frf.failures()
    assert np.all(frf.stable)
    # each point equals its own single solve
    one = aj.steady_state(scene(), aj.Harmonic(amplitude=20.0, omega=float(omegas[3])))
    np.testing.assert_allclose(frf.amplitude[3], float(one.amplitude), rtol=1e-8)


def test_failed_shooting_is_retried_by_marching_then_polished():
    # near the optimal normal force Newton from the linear guess wanders (measured: 40 steps,
    # residual 14); the retry marches onto the orbit and polishes it by shooting.  (The
    # sweep's vmapped retry, resume and first pass run on a smooth scene in
    # test_steady.test_failed_points_are_flagged_and_others_kept, and the exact flow under
    # vmap in test_exact_mode_runs_under_vmap_with_per_point_status; an event-driven
    # sweep's retry, marched apart and polished in the sweep's own shooting program, in
    # test_impacts.test_a_rigid_sweep_retries_in_its_own_shooting_programs: a
    # sweep of this scene here would compile two more programs of the exact flow)
    system = aj.FrictionAbsorber(m1=1.0, k1=1e4, c1=2.0, m2=0.2, k2=1.8e3, c2=0.0,
                                 normal_force=6.58, friction=aj.Coulomb(mu=0.5))
    forcing = aj.Harmonic(amplitude=10.0, omega=78.51)
    bare = aj.steady_state(system, forcing, retry=False)
    assert int(bare.status) == int(aj.Status.NO_CONVERGENCE)
    ss = aj.steady_state(system, forcing)
    ma = aj.steady_state(system, forcing, method="marching")
    assert int(ss.status) == 0 and int(ma.status) == 0
    np.testing.assert_allclose(float(ss.amplitude), float(ma.amplitude), rtol=1e-6)
    assert float(ss.residual) < 1e-10 and bool(ss.stable)


def test_smoothed_law_with_explicit_solver_gets_the_monodromy_right():
    # the 70 rad/s case with the tanh-smoothed law (eps = 1e-4 m/s): the automatic choice is
    # Tsit5; with steps controlled on the state only, its monodromy is |μ| = 1e66
    # (shooting diverges) and 2.8e9 (marching calls a stable orbit unstable)
    system = scene(law=aj.Coulomb(mu=0.5, eps=1e-4))
    assert aj.choose_solver(system, FORCING) == "tsit5"
    exact = aj.steady_state(scene(), FORCING)
    for method in ("shooting", "marching"):
        ss = aj.steady_state(system, FORCING, method=method, retry=False)
        assert int(ss.status) == 0 and bool(ss.stable), method
        mu = np.sort(np.abs(np.asarray(ss.multipliers)))
        np.testing.assert_allclose(mu[-1], np.max(np.abs(np.asarray(exact.multipliers))),
                                   atol=2e-3)
        np.testing.assert_allclose(float(ss.amplitude), float(exact.amplitude), rtol=1e-4)
    assert int(aj.steady_state(system, FORCING, retry=False).iterations) <= 8


@pytest.mark.slow
def test_method_objects_equal_their_keyword_spelling():
    by_object = aj.steady_state(scene(), FORCING, method=aj.Shooting(tol=1e-8, newton_steps=20))
    by_name = aj.steady_state(scene(), FORCING, method="shooting", tol=1e-8, newton_steps=20)
    np.testing.assert_array_equal(np.asarray(by_object.state), np.asarray(by_name.state))
    one = aj.solve_point(scene(), FORCING, aj.Marching(),
                         make_config(scene(), FORCING, None, 1e-9, 1e-9, 200_000))
    np.testing.assert_allclose(float(one.amplitude), float(by_name.amplitude), rtol=1e-6)
