"""The exact band peak (dA/dω = 0 located on the orbit family, envelope-theorem gradient) and
the minimax design on it, against closed forms, dense grids and central differences."""

import numpy as np
import pytest
import reference_jumps as rj
from builders import TIGHT, WN, K, M, tmd
from reference_hinf import h_infinity, nishihara_asami, peaks, receptance

import absorber_jax as aj


def test_exact_peak_of_an_impact_absorber_matches_a_dense_grid_and_central_differences():
    system, _ = aj.presets.impact("kelvin_voigt")
    kw = dict(amplitude=2.0, objective=aj.objectives.ExactPeak(n_freq=16), **TIGHT)
    pk = aj.exact_peak(system, (25.0, 45.0), params=["k1", "c1"], **kw)
    assert pk.ok[pk.index] and pk.located[pk.index]
    w = pk.omega
    # a dense grid around the located peak; the grid maximum refined by the parabola through
    # its three highest points (error ~ spacing^3)
    dense = np.linspace(w - 0.2, w + 0.2, 41)
    fr = aj.frequency_response(system, dense, amplitude=2.0, **TIGHT)
    assert np.all(fr.ok)
    a = np.asarray(fr.amplitude)
    i = int(np.argmax(a))
    assert 0 < i < len(a) - 1
    y0, y1, y2 = a[i - 1:i + 2]
    dw = dense[1] - dense[0]
    den = y0 - 2 * y1 + y2
    grid_max = y1 - 0.125 * (y0 - y2) ** 2 / den
    grid_arg = dense[i] + 0.5 * dw * (y0 - y2) / den
    np.testing.assert_allclose(pk.value, grid_max, rtol=1e-6)
    np.testing.assert_allclose(w, grid_arg, rtol=1e-4)       # a flat maximum: ω* to ~dw^2
    # no grid point lies above it (frequency_response's parabolic extremes are ~1e-7 high)
    assert pk.value >= a.max() * (1 - 1e-6)
    # the gradient against central differences of the exact peak itself (k1; the c1 gradient
    # of the same envelope-theorem code is checked against the closed form on the TMD)
    for name in ("k1",):
        p = float(aj.get_param(system, name))
        h = 1e-4 * p
        up = aj.exact_peak(aj.replace_params(system, {name: p + h}), (25.0, 45.0),
                           params=["k1", "c1"], **kw)
        down = aj.exact_peak(aj.replace_params(system, {name: p - h}), (25.0, 45.0),
                             params=["k1", "c1"], **kw)
        fd = (up.value - down.value) / (2 * h)
        np.testing.assert_allclose(pk.gradient[name], fd, rtol=1e-6, err_msg=name)


def _check_peaks_and_gradients_against_the_closed_form():
    mu, f, zeta = 0.05, 0.95, 0.1
    system = tmd(mu, f, zeta)
    pk = aj.exact_peak(system, (70.0, 130.0), amplitude=1.0, params=["k1", "c1"],
                       objective=aj.objectives.ExactPeak(n_freq=16), **TIGHT)
    assert np.all(pk.ok) and np.all(pk.located)
    ref = peaks(mu, f, zeta)
    assert len(ref) == 2
    for j, (r, h) in enumerate(ref):
        np.testing.assert_allclose(pk.omegas[j], r * WN, rtol=1e-8)
        np.testing.assert_allclose(pk.amplitudes[j] * K, h, rtol=1e-8)
    assert pk.value == pytest.approx(max(h for _, h in ref) / K, rel=1e-8)
    # the envelope-theorem gradient against central differences of the closed-form peaks
    ka, ca = float(aj.get_param(system, "k1")), float(aj.get_param(system, "c1"))
    m = mu * M

    def closed_peaks(k1, c1):
        fz = (np.sqrt(k1 / m) / WN, c1 / (2 * np.sqrt(k1 * m)))
        return np.array([h for _, h in peaks(mu, *fz)]) / K

    for name, p in (("k1", ka), ("c1", ca)):
        h = 1e-5 * p
        args_p = (ka + h, ca) if name == "k1" else (ka, ca + h)
        args_m = (ka - h, ca) if name == "k1" else (ka, ca - h)
        fd = (closed_peaks(*args_p) - closed_peaks(*args_m)) / (2 * h)
        np.testing.assert_allclose(pk.gradients[name], fd, rtol=1e-6, err_msg=name)
    assert pk.gradient["k1"] == pk.gradients["k1"][pk.index]


def _check_a_narrow_resonance_between_grid_points():
    """A nearly undamped absorber (zeta = 0.002): its two resonances are ~0.2 rad/s wide,
    far narrower than the 4 rad/s grid spacing, so the uniform grid alone sees neither; the
    grid points at the linearisation's modes (``modes=True``) bracket both, and the located
    peaks equal the closed form's."""
    mu, f, zeta = 0.05, 0.95, 0.002
    pk = aj.exact_peak(tmd(mu, f, zeta), (70.0, 130.0), amplitude=1.0, params=["k1", "c1"],
                       objective=aj.objectives.ExactPeak(n_freq=16), **TIGHT)
    ref = peaks(mu, f, zeta)
    top = max(h for _, h in ref) / K
    uniform = pk.grid_amplitude[:16]
    assert uniform.max() < 0.2 * top               # the uniform grid alone misses them
    assert len(pk.grid_omegas) == 16 + 6            # 2 modes x 3 points
    assert np.all(pk.ok) and np.all(pk.located)
    for j, (r, h) in enumerate(ref):
        np.testing.assert_allclose(pk.omegas[j], r * WN, rtol=1e-8)
        np.testing.assert_allclose(pk.amplitudes[j] * K, h, rtol=1e-7)
    np.testing.assert_allclose(pk.value, top, rtol=1e-7)


def test_exact_peak_and_minimax_tuning_on_the_tmd():
    """The located peaks and their gradients against the closed form, a narrow resonance,
    then the minimax tuning to the H-infinity optimum for mu = 0.05 (mu = 0.2: the slow
    test below)."""
    _check_peaks_and_gradients_against_the_closed_form()
    _check_a_narrow_resonance_between_grid_points()
    _check_the_h_infinity_optimum(0.05, (70.0, 130.0))


@pytest.mark.slow  # CI time: ~1.5 min more; the same tuning as above at a heavier absorber
def test_minimax_tuning_reaches_the_h_infinity_optimum_at_mu_0_2():
    _check_the_h_infinity_optimum(0.2, (60.0, 140.0))


def test_tune_at_its_defaults_reaches_the_h_infinity_optimum():
    """``tune`` with no objective, optimiser or tolerance given: the H-infinity tuned mass
    damper (mu = 0.05) from a design 5 % detuned with half the damping, against the closed
    form of Nishihara & Asami (and an independent Nelder-Mead on the receptance)."""
    mu = 0.05
    f_ref, z_ref, peak_ref = h_infinity(mu)
    tuned, hist = aj.tune(tmd(mu, 1.05 * f_ref, 0.5 * z_ref), ["k1", "c1"], (70.0, 130.0),
                          amplitude=1.0)
    m = mu * M
    k1, c1 = float(aj.get_param(tuned, "k1")), float(aj.get_param(tuned, "c1"))
    f, z = np.sqrt(k1 / m) / WN, c1 / (2 * np.sqrt(k1 * m))
    peak = max(h for _, h in peaks(mu, f, z))            # the tuned design's closed-form peak
    print(f"tune defaults: f {f / f_ref - 1:.2e}, zeta {z / z_ref - 1:.2e}, "
          f"peak {peak / peak_ref - 1:.2e} off the H-infinity optimum")
    np.testing.assert_allclose(f, f_ref, rtol=1e-3)
    np.testing.assert_allclose(z, z_ref, rtol=1e-3)
    np.testing.assert_allclose(peak, peak_ref, rtol=1e-3)
    np.testing.assert_allclose(min(hist["objective"]) * K, peak_ref, rtol=1e-3)
    assert hist["settles_on"]["is_designed"]             # confirm ran, by default


def _linear_tmd(mu, f, zeta):
    """The tuned mass damper of ``tmd`` as a linear structure: an undamped primary (M, K)
    carrying a ``TunedMassDamper``."""
    m = mu * M
    ka = m * (f * WN) ** 2
    st = aj.structure_from_matrices([[M]], [[K]], dof_names=["x1"])
    return aj.StructuralSystem(
        st, [aj.TunedMassDamper("x1", m=m, k=ka, c=2 * zeta * np.sqrt(ka * m))], load="x1")


def test_design_objectives_of_a_linear_structure_are_its_closed_form():
    """A structure of linear elements is ``linear``: ``exact_peak`` evaluates its closed-form
    response (no integration).  The located peak, its frequency and its gradient against the
    receptance of reference_hinf (Brent to 1e-13) and its central differences; the amplitude
    there against a shooting sweep; the smooth band peak of ``value_and_grad`` and its
    gradient against the same damper integrated.  (Tuning to the H-infinity optimum:
    test_tune_at_its_defaults_reaches_the_h_infinity_optimum.)"""
    mu = 0.05
    f_ref, z_ref = nishihara_asami(mu)
    f0, z0 = 1.05 * f_ref, 0.5 * z_ref
    system = _linear_tmd(mu, f0, z0)
    assert system.linear and not tmd(mu, f0, z0).linear
    band = (70.0, 130.0)
    res = aj.exact_peak(system, band, amplitude=1.0, params=("tmd1.k", "tmd1.c"))
    assert np.all(res.ok) and np.all(res.located)

    def ref_peak(f, z):
        return max(peaks(mu, f, z, band[0] / WN, band[1] / WN), key=lambda p: p[1])

    r_top, h_top = ref_peak(f0, z0)
    np.testing.assert_allclose(res.value * K, h_top, rtol=1e-9)
    np.testing.assert_allclose(res.omega, r_top * WN, rtol=1e-7)
    # the gradient in the absorber's stiffness and damping [N/m, N s/m]: the reference's
    # peak differentiated centrally through f = sqrt(k/m)/wn, zeta = c/(2 sqrt(k m))
    m = mu * M
    k0, c0 = m * (f0 * WN) ** 2, 2 * z0 * np.sqrt(m * (f0 * WN) ** 2 * m)

    def h_of(k, c):
        return ref_peak(np.sqrt(k / m) / WN, c / (2 * np.sqrt(k * m)))[1] / K

    fd = [(h_of(k0 * (1 + 1e-5), c0) - h_of(k0 * (1 - 1e-5), c0)) / (2e-5 * k0),
          (h_of(k0, c0 * (1 + 1e-5)) - h_of(k0, c0 * (1 - 1e-5))) / (2e-5 * c0)]
    np.testing.assert_allclose([res.gradient["tmd1.k"], res.gradient["tmd1.c"]], fd, rtol=1e-5)
    # the orbit at the located frequency, by shooting
    fr = aj.frequency_response(system, [res.omega], amplitude=1.0)
    assert int(fr.status[0]) == 0
    np.testing.assert_allclose(float(fr.amplitude[0]), res.value, rtol=1e-7)
    # the grid objectives too: the smooth band peak and its gradient, closed form against
    # the same damper integrated (``tmd``: an ImpactAbsorber with no gap, not linear)
    om = np.linspace(*band, 8)
    v_lin, g_lin, st_lin = aj.value_and_grad(system, ["tmd1.k", "tmd1.c"], om, amplitude=1.0)
    v_sh, g_sh, st_sh = aj.value_and_grad(tmd(mu, f0, z0), ["k1", "c1"], om, amplitude=1.0)
    assert np.all(np.asarray(st_lin) == 0) and np.all(np.asarray(st_sh) == 0)
    np.testing.assert_allclose(v_lin, v_sh, rtol=1e-6)
    np.testing.assert_allclose([g_lin["tmd1.k"], g_lin["tmd1.c"]], [g_sh["k1"], g_sh["c1"]],
                               rtol=1e-5)


def _check_the_h_infinity_optimum(mu, band):
    f_ref, z_ref, peak_ref = h_infinity(mu)
    f_na, z_na = nishihara_asami(mu)
    np.testing.assert_allclose((f_ref, z_ref), (f_na, z_na), rtol=1e-7)  # the references
    # start 5 % off in frequency and with half the damping
    system = tmd(mu, 1.05 * f_ref, 0.5 * z_ref)
    tuned, hist = aj.tune(system, ["k1", "c1"], band, amplitude=1.0,
                          objective=aj.objectives.ExactPeak(n_freq=16), steps=40, confirm=False,
                          **TIGHT)
    m = mu * M
    k1, c1 = hist["best"]["k1"], hist["best"]["c1"]
    f, z = np.sqrt(k1 / m) / WN, c1 / (2 * np.sqrt(k1 * m))
    np.testing.assert_allclose(f, f_ref, rtol=1e-4, err_msg=f"frequency ratio, mu={mu}")
    np.testing.assert_allclose(z, z_ref, rtol=1e-4, err_msg=f"damping ratio, mu={mu}")
    np.testing.assert_allclose(min(hist["objective"]) * K, peak_ref, rtol=1e-4)
    # the optimum has equal peaks
    last = hist["peaks"][int(np.argmin(hist["objective"]))]
    np.testing.assert_allclose(last[0], last[1], rtol=1e-4)
    # the tuned design at its located peak frequencies, by the closed form
    np.testing.assert_allclose(receptance(mu, f, z, hist["peak_omegas"][-1] / WN), peak_ref,
                               rtol=1e-4)
    assert len(hist["objective"]) <= 30                  # SLSQP: a few dozen solves at most
    print(f"H-infinity mu={mu}: f {f:.8f} (ref {f_ref:.8f}), zeta {z:.8f} (ref {z_ref:.8f}), "
          f"{len(hist['objective'])} evaluations")


def test_exact_peak_bad_input():
    system = tmd(0.05, 1.0, 0.1)
    with pytest.raises(ValueError, match="n_freq"):
        aj.exact_peak(system, (70.0, 130.0), amplitude=1.0, n_freq=2)
    with pytest.raises(ValueError, match="peaks"):
        aj.exact_peak(system, (70.0, 130.0), amplitude=1.0, peaks=0)
    with pytest.raises(ValueError, match="band"):
        aj.exact_peak(system, (130.0, 70.0), amplitude=1.0)
    with pytest.raises(ValueError, match="no parameter"):
        aj.exact_peak(system, (70.0, 130.0), amplitude=1.0, params=["k9"])
    with pytest.raises(ValueError, match="exact_peak"):
        aj.tune(system, ["k1"], (70.0, 70.0), amplitude=1.0, objective="exact_peak")
    with pytest.raises(ValueError, match="robust_peak.*>= 3 frequencies"):
        aj.value_and_grad(system, ["k1"], [70.0, 80.0], amplitude=1.0, objective="robust_peak")
    with pytest.raises(ValueError, match="RobustPeak.probes must be an integer >= 1"):
        aj.objectives.RobustPeak(probes=0)
    with pytest.raises(ValueError, match="ExactPeak.peaks must be in"):
        aj.objectives.ExactPeak(n_freq=4, peaks=5)
    with pytest.raises(ValueError, match="tune.method must be an aj.Shooting"):
        aj.tune(system, ["k1"], (70.0, 130.0), amplitude=1.0, method=aj.Marching())
    with pytest.raises(TypeError, match="unexpected keyword argument 'n_frq'"):
        aj.tune(system, ["k1"], (70.0, 130.0), amplitude=1.0, n_frq=8)


def test_robust_objective_reports_the_coexisting_upper_branch():
    """A hardening oscillator inside its hysteresis (1.1-1.2): shooting from the linear guess
    follows the lower branch, so the plain exact peak is the linear response at the band edge;
    the attractor maps find the upper branch, whose amplitude at 1.2 is the worst response.
    Both against exact piecewise-linear references (reference_jumps)."""
    from builders import HARD, hardening
    from scipy.optimize import fsolve

    system = hardening()
    r = aj.robust_peak(system, (1.1, 1.2), amplitude=HARD["F0"], params=["contact1.stiffness"],
                       n_freq=8, probes=3, samples=12)
    c, F0 = HARD["c"], HARD["F0"]
    linear = F0 / abs(1 - 1.1**2 + 1j * c * 1.1)       # below the gap: the linear response
    assert r.plain.omega == pytest.approx(1.1)
    np.testing.assert_allclose(r.plain.value, linear, rtol=1e-6)
    assert r.source == "coexisting" and r.omega == pytest.approx(1.2)

    top = max(r.coexisting, key=lambda a: a.amplitude)
    assert top.omega == pytest.approx(1.2) and top.period_multiple == 1 and top.stable

    def upper(k_c):
        """The exact fixed point of the piecewise-linear period map near the marched orbit."""
        p = dict(c=c, F0=F0, k_c=k_c, g=HARD["g"])
        x = fsolve(lambda x: rj.period_map(x, 1.2, **p) - x, top.state, xtol=1e-13)
        return rj.amplitude(x, 1.2, **p)

    np.testing.assert_allclose(r.value, upper(HARD["k_c"]), rtol=1e-6)
    assert r.value > 5 * r.plain.value
    h = 1e-4 * HARD["k_c"]
    fd = (upper(HARD["k_c"] + h) - upper(HARD["k_c"] - h)) / (2 * h)
    # measured 1.7e-4: the library's contact is smoothed at the gap (eps), the reference not
    np.testing.assert_allclose(r.gradient["contact1.stiffness"], fd, rtol=1e-3)


@pytest.mark.slow  # CI time: ~2.5 min (attractor maps in every round, four compilations)
def test_robust_tuning_removes_the_coexisting_upper_branch():
    """The hardening oscillator's clearance tuned on the robust objective: at the start the
    attractor maps find the upper branch (5.8x the exact peak of the branch shooting
    follows, which does not depend on the clearance at all: a plain tuning has nothing to
    descend); the rounds follow it as the design moves until the maps at the result find one
    response per probe, and every response found there is the exact piecewise-linear orbit
    (reference_jumps' period map)."""
    from builders import HARD, hardening
    from scipy.optimize import fsolve

    c, F0 = HARD["c"], HARD["F0"]
    tuned, hist = aj.tune(hardening(), {"contact1.gap": (0.05, 2.0)}, (1.1, 1.2), amplitude=F0,
                          objective=aj.objectives.RobustPeak(n_freq=8, probes=3,
                                                                probe_samples=12, rounds=2),
                          steps=6,
                          confirm=False)
    first, last = hist["rounds"][0], hist["rounds"][-1]
    linear = F0 / abs(1 - 1.1**2 + 1j * c * 1.1)
    np.testing.assert_allclose(first["plain"], linear, rtol=1e-6)
    assert first["worst"] > 5 * first["plain"] and first["followed"] >= 1
    assert hist["robust"]["source"] == "branch" and last["followed"] == 0
    assert hist["robust"]["value"] < 0.3 * first["worst"]
    assert len(last["found"]) == 3                     # one stable response per probe
    g = hist["best"]["contact1.gap"]
    assert 0.05 < g < 0.5
    p = dict(c=c, F0=F0, k_c=HARD["k_c"], g=g)
    for f in last["found"]:
        w = f["omega"]
        x = fsolve(lambda x, w=w: rj.period_map(x, w, **p) - x, f["state"], xtol=1e-13)
        # measured 1.4e-6: marched amplitudes (sampled extremes), the contact smoothed at the gap
        np.testing.assert_allclose(f["amplitude"], rj.amplitude(x, w, **p), rtol=1e-5)
    assert max(f["amplitude"] for f in last["found"]) <= hist["robust"]["value"] * (1 + 1e-9)


@pytest.mark.slow  # CI time: three more compilations (the design grid, attractors, Floquet)
def test_global_starts_stability_margin_and_settling():
    """Global starts from a badly detuned design, under a stability margin, confirmed by
    marching from several initial states at the located peak."""
    f_ref, z_ref, peak_ref = h_infinity(0.05)
    starts = {"k1": [300.0, 450.0, 600.0], "c1": [0.3, 1.0, 3.0]}
    tuned, hist = aj.tune(tmd(0.05, 1.3, 0.03), ["k1", "c1"], (70.0, 130.0), amplitude=1.0,
                          objective=aj.objectives.ExactPeak(n_freq=16, stability_margin=0.01),
                          steps=30, tol=1e-9, starts=(starts, 2), confirm=(4, 8))
    grid = hist["starts"]["grid_peak"]
    designs = hist["starts"]["designs"]
    assert hist["starts"]["tuned_from"] == [designs[i] for i in np.argsort(grid)[:2]]
    assert min(hist["objective"]) <= grid.min()
    m = 0.05 * M
    k1, c1 = hist["best"]["k1"], hist["best"]["c1"]
    np.testing.assert_allclose(np.sqrt(k1 / m) / WN, f_ref, rtol=1e-4)
    np.testing.assert_allclose(c1 / (2 * np.sqrt(k1 * m)), z_ref, rtol=1e-4)
    assert hist["feasible"] and hist["unstable"] == 0
    settle = hist["settles_on"]
    assert settle["is_designed"]
    np.testing.assert_allclose(settle["worst_stable"] * K, peak_ref, rtol=1e-3)
    # a margin no design meets: nothing is feasible, and the history says so
    _, hist = aj.tune(tmd(0.05, 1.0, 0.1), ["k1", "c1"], (70.0, 130.0), amplitude=1.0,
                      objective=aj.objectives.ExactPeak(n_freq=16, stability_margin=0.999),
                      steps=3, tol=1e-9, confirm=False)
    assert not hist["feasible"] and hist["unstable"] >= 1
