"""Gradient-based design: gradients against finite differences, tuning against exact optima."""

import numpy as np
import pytest
from builders import TIGHT
from scipy.optimize import minimize

import absorber_jax as aj
from absorber_jax._design import tune as _design


def central_fd(system, names, omegas, amplitude, objective, rel=1e-4):
    out = {}
    for k in names:
        p = float(aj.get_param(system, k))
        h = rel * p
        plus = aj.replace_params(system, {k: p + h})
        minus = aj.replace_params(system, {k: p - h})
        # the same parameter list as the gradient call: one compilation serves all
        fp, _, _ = aj.value_and_grad(plus, names, omegas, amplitude=amplitude,
                                     objective=objective, **TIGHT)
        fm, _, _ = aj.value_and_grad(minus, names, omegas, amplitude=amplitude,
                                     objective=objective, **TIGHT)
        out[k] = (fp - fm) / (2 * h)
    return out


def friction_system(law, N=1.0):
    return aj.FrictionAbsorber(m1=1.0, k1=1e4, c1=2.0, m2=0.2, k2=1.8e3, c2=0.0,
                               normal_force=N, friction=law)


CASES = [
    ("impact", aj.presets.impact("kelvin_voigt")[0], ["k1", "c1", "m", "gap"], [40.0], 2.0),
    ("coulomb", friction_system(aj.Coulomb(mu=0.5, eps=1e-3)), ["N", "k2"], [95.0], 10.0),
    ("lugre", friction_system(aj.LuGre(mu_c=0.5, mu_s=0.6, v_s=1e-2, sigma0=1e4, sigma1=1e2)),
     ["N", "k2"], [95.0], 10.0),
]


@pytest.mark.parametrize("label, system, names, omegas, F0", CASES, ids=[c[0] for c in CASES])
def test_gradients_match_central_differences(label, system, names, omegas, F0):
    val, grads, status = aj.value_and_grad(system, names, omegas, amplitude=F0,
                                           objective="amplitude", **TIGHT)
    assert np.all(status == 0) and val > 0
    fd = central_fd(system, names, omegas, F0, "amplitude")
    for k in names:
        assert np.isfinite(grads[k])
        np.testing.assert_allclose(grads[k], fd[k], rtol=1e-4, err_msg=k)


def test_band_objectives_gradients():
    system, _ = aj.presets.impact("kelvin_voigt")
    om = np.linspace(35.0, 45.0, 6)
    for obj in ("peak", "mean_square"):
        _, grads, status = aj.value_and_grad(system, ["k1", "c1"], om, amplitude=2.0,
                                             objective=obj, **TIGHT)
        fd = central_fd(system, ["k1", "c1"], om, 2.0, obj)
        for k in ("k1", "c1"):
            np.testing.assert_allclose(grads[k], fd[k], rtol=1e-4, err_msg=(obj, k))


def test_smooth_max_bias_is_bounded():
    rng = np.random.default_rng(0)
    a = np.abs(rng.normal(size=64)) + 1.0
    s = float(aj.smooth_max(a, 2e-3))
    tau = 2e-3 * a.max()
    assert a.max() - tau * np.log(64) <= s <= a.max()


def closed_form_x1(M, k, m, k1, c1, w):
    Z = np.array([[k + k1 - w**2 * M + 1j * w * c1, -k1 - 1j * w * c1],
                  [-k1 - 1j * w * c1, k1 - w**2 * m + 1j * w * c1]])
    return abs(np.linalg.solve(Z, [1.0, 0.0])[0])


# the grid objective at 1 %; the exact-peak minimax (test_peak.py) runs in CI at 1e-4
@pytest.mark.slow
@pytest.mark.parametrize("mu", [0.05, 0.2])
def test_tmd_tuning_reaches_the_h_infinity_optimum(mu):
    M, k = 1.0, 1e3
    wn = np.sqrt(k / M)
    m = mu * M
    band = (0.6 * wn, 1.4 * wn)
    ws = np.linspace(*band, 6001)

    def peak(f, z):
        k1 = m * (f * wn) ** 2
        return max(closed_form_x1(M, k, m, k1, 2 * z * np.sqrt(k1 * m), w) for w in ws)

    # independent minimax of the closed-form FRF (Nelder–Mead from Den Hartog's values)
    dh = (1 / (1 + mu), np.sqrt(3 * mu / (8 * (1 + mu) ** 3)))
    ref = minimize(lambda p: peak(*p), dh, method="Nelder-Mead",
                   options=dict(xatol=1e-7, fatol=1e-12))
    f_opt, z_opt = ref.x
    # start 5 % off in frequency and with half the damping
    k1_0 = m * (1.05 * f_opt * wn) ** 2
    system = aj.ImpactAbsorber(M=M, k=k, c=0.0, m=m, gap=0.0,
                               contact=aj.KelvinVoigt(stiffness=k1_0,
                                                      damping=z_opt * np.sqrt(k1_0 * m),
                                                      adhesive=True))
    tuned, hist = aj.tune(system, ["k1", "c1"], band, amplitude=1.0, steps=120,
                          objective=aj.objectives.SmoothPeak(n_freq=64), confirm=False)
    k1, c1 = hist["best"]["k1"], hist["best"]["c1"]
    f, z = np.sqrt(k1 / m) / wn, c1 / (2 * np.sqrt(k1 * m))
    np.testing.assert_allclose(f, f_opt, rtol=0.01)
    np.testing.assert_allclose(z, z_opt, rtol=0.01)
    np.testing.assert_allclose(peak(f, z), ref.fun, rtol=0.01)
    assert hist["objective"][-1] < hist["objective"][0]
    # Den Hartog's fixed points: |X1| at the two frequencies where the undamped (c1 = 0) and
    # locked (c1 -> inf) curves cross is independent of damping, and equal at the optimum
    locked = lambda w: 1 / abs(k - (M + m) * w**2)
    free = lambda w: closed_form_x1(M, k, m, k1, 0.0, w)
    w_a = np.sqrt(k1 / m)
    grid = np.linspace(0.7 * wn, 1.3 * wn, 200001)
    diff = np.array([free(w) - locked(w) for w in grid[::50]])
    sign_changes = grid[::50][np.flatnonzero(np.diff(np.sign(diff)))]
    pts = [w for w in sign_changes if abs(w - w_a) > 1e-3 and abs(w - wn / np.sqrt(1 + mu)) > 1e-3]
    assert len(pts) >= 2
    heights = [locked(w) for w in (pts[0], pts[-1])]
    np.testing.assert_allclose(heights[0], heights[1], rtol=0.01)
    for w in (pts[0], pts[-1]):  # the crossing really is damping-independent
        np.testing.assert_allclose(closed_form_x1(M, k, m, k1, 3 * c1, w), locked(w), rtol=2e-3)


@pytest.mark.slow  # CI time
def test_friction_normal_force_optimum_is_interior():
    base = friction_system(aj.Coulomb(mu=0.5, eps=1e-3), N=2.0)
    band = (70.0, 120.0)
    tuned, hist = aj.tune(base, {"N": (0.01, 200.0)}, band, amplitude=10.0, steps=15,
                          objective=aj.objectives.SmoothPeak(n_freq=24),
                          confirm=False)
    N_opt = hist["best"]["N"]
    assert 0.05 < N_opt < 100.0
    om = np.linspace(*band, 24)
    peaks = {}
    for N in (1e-3, N_opt, 500.0):
        frf = aj.frequency_response(aj.replace_params(base, {"N": N}), om, amplitude=10.0)
        assert np.all(frf.status == 0), N
        peaks[N] = frf.amplitude.max()
    assert peaks[N_opt] < 0.8 * peaks[1e-3]  # nearly free: an undamped TMD's peaks
    assert peaks[N_opt] < 0.8 * peaks[500.0]  # stuck: a 1.2 kg mass on k1 with c1 only


@pytest.mark.slow  # CI time (the exact-peak impact checks run in CI)
def test_impact_tuning_lowers_band_peak_confirmed_by_marching():
    system, _ = aj.presets.impact("kelvin_voigt")
    tuned, hist = aj.tune(system, ["k1", "c1", "m"], (25.0, 45.0), amplitude=2.0, steps=12,
                          objective=aj.objectives.SmoothPeak(n_freq=16), confirm=(6, 8))
    assert hist["amplitude_after"].max() < 0.95 * hist["amplitude_before"].max()
    c = hist["confirm"]
    ok = (c["status_before"] == 0) & (c["status_after"] == 0)
    assert ok.sum() >= 4
    assert c["after"][ok].max() < c["before"][ok].max()
    # marching agrees with the shooting curves where both converged on period-1 orbits
    idx = np.searchsorted(hist["omegas"], c["omegas"])
    same = ok & (c["period_after"] == 1)
    np.testing.assert_allclose(c["after"][same], hist["amplitude_after"][np.minimum(idx, 15)][same],
                               rtol=1e-3)


def test_tune_compiles_once():
    """The first tuning traces the step program (a grid of 7 frequencies, used by no other
    test, so its compilation happens here), a second design of the same shape reuses it."""
    system = aj.ImpactAbsorber(M=1.0, k=1e3, c=0.0, m=0.1, gap=0.0,
                               contact=aj.KelvinVoigt(stiffness=80.0, damping=2.0,
                                                      adhesive=True))
    n0 = _design._TRACES["tune_step"]
    aj.tune(system, ["k1", "c1"], (25.0, 40.0), amplitude=1.0, steps=2,
            objective=aj.objectives.SmoothPeak(n_freq=7), confirm=False)
    n = _design._TRACES["tune_step"]
    assert n > n0                                    # traced: the counter counts
    other = aj.replace_params(system, {"k1": 95.0, "c1": 3.0})
    aj.tune(other, ["k1", "c1"], (25.0, 40.0), amplitude=1.0, steps=4,
            objective=aj.objectives.SmoothPeak(n_freq=7), confirm=False)
    assert _design._TRACES["tune_step"] == n


def test_tune_bad_input():
    system, _ = aj.presets.impact("kelvin_voigt")
    with pytest.raises(ValueError, match="has no parameter 'stiffness_of_nothing'"):
        aj.tune(system, ["stiffness_of_nothing"], (30, 40), amplitude=2.0)
    with pytest.raises(ValueError, match="objective must be an objective object"):
        aj.tune(system, ["k1"], (30, 40), amplitude=2.0, objective="max")
    with pytest.raises(ValueError, match=r"band\[1\] must be in"):
        aj.tune(system, ["k1"], (40, 30), amplitude=2.0)
    with pytest.raises(ValueError, match="strictly inside bounds"):
        aj.tune(system, {"k1": (500.0, 900.0)}, (30, 40), amplitude=2.0)


@pytest.mark.slow
def test_gradients_stay_finite_through_grazing_and_stick_slip():
    # 60 rad/s: the floating orbit's relative amplitude is 0.769 mm; sweep the clearance
    # through it (impacting -> grazing -> floating)
    system, _ = aj.presets.impact("kelvin_voigt")
    for gap in (0.70e-3, 0.769e-3, 0.85e-3):
        s = aj.replace_params(system, {"gap": gap})
        val, g, status = aj.value_and_grad(s, ["gap", "c1"], [60.0], amplitude=2.0,
                                           objective="amplitude")
        assert status[0] == 0 and np.isfinite(val) and all(np.isfinite(v) for v in g.values())
    # Coulomb: from nearly free sliding through stick-slip to sticking
    fr = friction_system(aj.Coulomb(mu=0.5, eps=1e-3))
    for N in (0.01, 3.0, 200.0):
        val, g, status = aj.value_and_grad(aj.replace_params(fr, {"N": N}), ["N", "k2"], [95.0],
                                           amplitude=10.0, objective="amplitude")
        assert status[0] == 0 and np.isfinite(val) and all(np.isfinite(v) for v in g.values())


def test_harmonic_balance_gives_design_gradients_of_a_friction_damped_beam():
    """``value_and_grad`` with ``method=HarmonicBalance``: on a linear tuned-mass-damper
    scene it equals shooting's value and gradient; on a beam with a smoothed friction
    contact (condensed balance) its gradient in the normal force and the friction
    coefficient equals central differences of its value."""
    st = aj.structure_from_matrices([[1.0]], [[1e3]], damping=[[1.0]], dof_names=["x1"])
    tmd = aj.StructuralSystem(st, [aj.TunedMassDamper("x1", m=0.05, k=45.0, c=0.3)],
                              load="x1")
    om = np.linspace(25.0, 38.0, 8)
    v_s, g_s, _ = aj.value_and_grad(tmd, ["tmd1.k", "tmd1.c"], om, amplitude=1.0,
                                    method=aj.Shooting(tol=1e-9))
    v_h, g_h, status = aj.value_and_grad(tmd, ["tmd1.k", "tmd1.c"], om, amplitude=1.0,
                                         method=aj.HarmonicBalance(harmonics=1, tol=1e-12))
    assert np.all(status == 0) and abs(v_h / v_s - 1) < 1e-7
    for k in g_s:
        assert abs(g_h[k] / g_s[k] - 1) < 1e-6

    beam = aj.cantilever_beam(4, length=1.0, EI=50.0, rho_A=1.0, rayleigh=(1.0, 1e-4))
    contact = aj.FrictionContact("w4", normal_force=2.0, friction=aj.Coulomb(mu=0.3, eps=1e-2))
    system = aj.StructuralSystem(beam, [contact], load="w4")
    om = np.linspace(22.0, 27.0, 6)
    hb = aj.HarmonicBalance(harmonics=7, tol=1e-12)
    names = ["friction_contact1.normal_force", "friction_contact1.mu"]
    v, g, status = aj.value_and_grad(system, names, om, amplitude=2.0, method=hb,
                                     objective=aj.objectives.MeanSquare())
    assert np.all(status == 0)
    for name, h in zip(names, (1e-4, 1e-5)):
        p = float(aj.get_param(system, name))
        up, _, _ = aj.value_and_grad(aj.replace_params(system, {name: p + h}), names, om,
                                     amplitude=2.0, method=hb,
                                     objective=aj.objectives.MeanSquare())
        down, _, _ = aj.value_and_grad(aj.replace_params(system, {name: p - h}), names, om,
                                       amplitude=2.0, method=hb,
                                       objective=aj.objectives.MeanSquare())
        assert abs(g[name] / ((up - down) / (2 * h)) - 1) < 1e-6
    with pytest.raises(ValueError, match="follows its peaks by shooting"):
        aj.value_and_grad(system, names, om, amplitude=2.0, method=hb,
                          objective=aj.objectives.ExactPeak())


def test_tune_by_harmonic_balance_follows_the_shooting_descent():
    """``tune`` with a grid objective and ``method=HarmonicBalance``: on a linear tuned mass
    damper (one harmonic is exact) each step of the descent sees the objective and gradient
    shooting sees, so the tuned design and the objective's history are shooting's."""
    st = aj.structure_from_matrices([[1.0]], [[1e3]], damping=[[1.0]], dof_names=["x1"])
    tmd = aj.StructuralSystem(st, [aj.TunedMassDamper("x1", m=0.05, k=40.0, c=0.2)],
                              load="x1")
    kw = dict(amplitude=1.0, objective=aj.objectives.SmoothPeak(), steps=10, confirm=False)
    _, h_s = aj.tune(tmd, ["tmd1.k", "tmd1.c"], (25.0, 38.0), method=aj.Shooting(tol=1e-9),
                     **kw)
    tuned, h_h = aj.tune(tmd, ["tmd1.k", "tmd1.c"], (25.0, 38.0),
                         method=aj.HarmonicBalance(harmonics=1, tol=1e-12), **kw)
    assert h_h["objective"][-1] < 0.9 * h_h["objective"][0]       # it did descend
    np.testing.assert_allclose(h_h["objective"], h_s["objective"], rtol=1e-6)
    for k in h_s["best"]:
        assert abs(h_h["best"][k] / h_s["best"][k] - 1) < 1e-6
    assert np.all(np.asarray(h_h["status_after"]) == 0)
    with pytest.raises(ValueError, match="follows its peaks by shooting"):
        aj.tune(tmd, ["tmd1.k"], (25.0, 38.0), amplitude=1.0,
                method=aj.HarmonicBalance(harmonics=1))


def test_failed_design_frequencies_are_seeded_by_marching(monkeypatch):
    """Frequencies where two Newton steps from the linear guess do not converge are seeded
    by a march from rest (no shooting of its own) and solved again by the design's own
    shooting: the first objective of ``tune`` is the one of the orbits converged at the
    full Newton budget (measured: equal to 1e-10)."""
    system, _ = aj.presets.impact("kelvin_voigt")
    objective = aj.objectives.MeanSquare(n_freq=6)
    marches = []
    march = _design.march_chunk
    monkeypatch.setattr(_design, "march_chunk", lambda *a: marches.append(a) or march(*a))
    _, hist = aj.tune(system, ["k1", "c1"], (35.0, 45.0), amplitude=2.0, steps=1,
                      objective=objective, method=aj.Shooting(newton_steps=2), confirm=False)
    # the linear guess failed somewhere (reseeding ran), and every frequency converged
    assert marches and hist["failed"][0] == 0
    ref, _, status = aj.value_and_grad(system, ["k1", "c1"], np.linspace(35.0, 45.0, 6),
                                       amplitude=2.0, objective=objective)
    assert np.all(status == 0)
    np.testing.assert_allclose(hist["objective"][0], ref, rtol=1e-8)
