"""Rigid impacts (``Restitution``): against the closed-form event-exact reference of
tests/reference_impacts.py (simulation with chatter and sticking, periodic orbits, impacts
per period, Floquet multipliers by finite differences of its period map), design gradients
against central differences, vmapped sweeps, and the compliant laws converging to it."""

import warnings

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np
import pytest
from reference_impacts import RigidImpactAbsorber

import absorber_jax as aj

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

# the hard-contact scene of scripts/benchmark_hard_contacts.py with a rigid ball
SCENE = dict(M=1.0, k=1e3, c=0.5, m=0.2, gap=2e-3)
E, F0 = 0.6, 3.0


# the hard scene's unstable four-impact orbit at 20 rad/s (e matched to its Kelvin-Voigt
# contact), public state [m, m/s]: a guess that selects it among the coexisting orbits there
FOUR_IMPACTS_AT_20 = [-1.5721e-4, 0.1246499, -3.8506e-4, 0.12361709]
# ... and its three-impact orbit there (the guess from the linear response falls into the
# chaotic motion at 20 rad/s, whose marched close returns lead to one orbit or another as
# the rounding of its many impacts goes)
THREE_IMPACTS_AT_20 = [-2.94e-4, 0.1232535, 9.2023e-4, 0.10951931]


# its unstable 16-impact orbit at 29.36 rad/s (|mu| = 25), one of several coexisting there
SIXTEEN_IMPACTS_AT_29_36 = [-0.027401199668089612, -1.927423215133603, -0.028438092341957745,
                            -2.233586617351216]


def rigid(e=E, **kw):
    return aj.ImpactAbsorber(**{**SCENE, **kw}, contact=aj.Restitution(e))


def reference(omega, e=E, **kw):
    p = SCENE
    return RigidImpactAbsorber(p["M"], p["k"], p["c"], p["m"], p["gap"], e, F0, omega, **kw)


def test_simulation_matches_the_event_exact_reference_through_chatter_and_sticking():
    ts = np.linspace(0.0, 2.0, 2001)
    ref, events = reference(30.0).run([0, 0, 0, 0], 0.0, 2.0, ts)
    kinds = [k for _, k in events]
    # the run chatters into sticking and is released again, several times
    assert kinds.count("stick") >= 10 and kinds.count("release") >= 10
    assert kinds.count("impact") > 300
    errs = []
    for rtol in (1e-7, 1e-12):
        tr = aj.simulate(rigid(), aj.Harmonic(amplitude=F0, omega=30.0), 2.0, ts=ts,
                         integrator=aj.Integrator(rtol=rtol, atol=rtol * 1e-2))
        assert int(tr.status) == 0
        u = np.asarray(tr.x2) - np.asarray(tr.x1)
        assert np.max(np.abs(u)) <= SCENE["gap"] * (1 + 1e-12)   # never through a wall
        scale = np.max(np.abs(ref[:, 0]))
        errs.append(max(np.max(np.abs(np.asarray(tr.x1) - ref[:, 0])),
                        np.max(np.abs(np.asarray(tr.x2) - ref[:, 2]))) / scale)
    # (rigid walls cap the step at T/256, so even a loose tolerance stays accurate)
    assert errs[0] < 1e-8 and errs[1] < 1e-10, errs


@pytest.mark.parametrize("omega", [25.0, 37.5, 40.0])
def test_orbits_impacts_and_floquet_multipliers_match_the_reference(omega):
    system = rigid()
    ss = aj.steady_state(system, aj.Harmonic(amplitude=F0, omega=omega))
    assert int(ss.status) == 0
    ref = reference(omega)
    n = int(ss.period_multiple)
    T = 2 * np.pi / omega
    y0 = np.asarray(ss.state)
    y1, events = ref.run(y0, 0.0, n * T)
    scale = np.array([1.0, omega, 1.0, omega]) * SCENE["gap"]
    assert np.max(np.abs(y1[-1] - y0) / scale) < 1e-7        # periodic for the reference
    assert float(ss.impacts) == sum(k == "impact" for _, k in events) / n
    assert float(ss.impacts) >= 2
    # the monodromy matrix of the reference's period map by central differences
    J = np.zeros((4, 4))
    for i in range(4):
        h = np.zeros(4)
        h[i] = 1e-7 * scale[i]
        J[:, i] = (ref.run(y0 + h, 0.0, n * T)[0][-1] - ref.run(y0 - h, 0.0, n * T)[0][-1]) / (
            2 * h[i])
    mu_ref = np.sort(np.abs(np.linalg.eigvals(J)))
    mu = np.sort(np.abs(np.asarray(ss.multipliers)))
    np.testing.assert_allclose(mu, mu_ref, rtol=1e-5, atol=1e-6)
    assert bool(ss.stable) == bool(mu_ref[-1] < 1.0)


def test_sticking_orbit_reports_its_time_held_against_the_wall():
    ss = aj.steady_state(rigid(), aj.Harmonic(amplitude=F0, omega=30.0))
    assert int(ss.status) == 0
    _, events = reference(30.0).run(np.asarray(ss.state), 0.0, 2 * np.pi / 30.0)
    held, t_stick = 0.0, None
    for t, k in events:
        if k == "stick":
            t_stick = t
        elif k == "release" and t_stick is not None:
            held, t_stick = held + t - t_stick, None
    if t_stick is not None:
        held += 2 * np.pi / 30.0 - t_stick
    assert held > 0.05 * 2 * np.pi / 30.0
    np.testing.assert_allclose(float(ss.contact_fraction), held / (2 * np.pi / 30.0),
                               atol=1e-6)
    # the two sticking walls' Zeno sequences end in a plastic contact: multipliers 0
    assert np.sum(np.abs(np.asarray(ss.multipliers)) < 1e-8) >= 1


def test_sweep_under_vmap_equals_single_solves():
    omegas = np.array([25.0, 37.5, 40.0, 45.0])
    fr = aj.frequency_response(rigid(), omegas, amplitude=F0)
    assert np.all(np.asarray(fr.status) == 0), fr.failures()
    for i in (0, 1):
        one = aj.steady_state(rigid(), aj.Harmonic(amplitude=F0, omega=float(omegas[i])))
        np.testing.assert_allclose(fr.amplitude[i], float(one.amplitude), rtol=1e-7)
        assert fr.impacts[i] == float(one.impacts)


def test_a_rigid_sweep_retries_in_its_own_shooting_programs(monkeypatch):
    # lanes one after the other (event-driven): the retry marches in a program of its own
    # and polishes the marched orbits in the shooting programs the sweep already has (the
    # first pass's, then the resume's for the rest of the Newton budget); the
    # march-then-shoot program is never built.  Marching settles only on attractors: what
    # it finds is stable (the 4-impact orbit at 37.5 rad/s the first pass found), or it is
    # flagged (no period within n_max) where the first pass's orbits are unstable
    from absorber_jax._periodic import sweep as _sweep

    omegas = np.array([25.0, 37.5, 40.0, 45.0])
    full = aj.frequency_response(rigid(), omegas, amplitude=F0)
    assert np.all(np.asarray(full.status) == 0), full.failures()
    assert full.stable[1] and full.impacts[1] == 4.0

    def refused(*args, **kwargs):
        raise AssertionError("the march-then-shoot program was built")

    monkeypatch.setattr(_sweep, "retry_chunk", refused)
    three = aj.Shooting(newton_steps=3)     # too few from the linear guess: all retried
    # a small sweep's first pass has the whole budget: the polish in its program alone
    whole = aj.frequency_response(rigid(), omegas, amplitude=F0, method=three)
    # a large sweep's first pass one step, the resume two: the polish in both, in turn
    monkeypatch.setattr(_sweep, "SMALL_CHUNK", 0)
    monkeypatch.setattr(_sweep, "FIRST_PASS_NEWTON", 1)
    split = aj.frequency_response(rigid(), omegas, amplitude=F0, method=three)
    for rescued in (whole, split):
        status = np.asarray(rescued.status)
        assert np.all(np.asarray(rescued.iterations) > 100)          # all marched
        assert status[1] == 0
        np.testing.assert_allclose(rescued.amplitude[1], full.amplitude[1], rtol=1e-7)
        assert rescued.impacts[1] == 4.0
        assert np.all(rescued.stable[status == 0])
        assert set(status[status != 0]) <= {aj.Status.NOT_PERIODIC}
    # the same marches, the same Newton budget: the same orbits (to the shooting
    # tolerance: a first pass of one step stops at an iterate whose residual meets it,
    # where the whole budget in one program takes the next step too)
    np.testing.assert_array_equal(np.asarray(split.status), np.asarray(whole.status))
    ok = np.asarray(whole.status) == 0
    np.testing.assert_allclose(split.amplitude[ok], whole.amplitude[ok], rtol=1e-6)


def test_vmapped_lanes_each_follow_their_own_events():
    # lanes of different frequencies and starts (2 to 26 impacts a period, chatter among
    # them) vmapped together: each lane's period map and monodromy equal its own solve
    # (the lanes are integrated one by one, not in lockstep), and periods integrated one
    # at a time (the marches of band_continuation) equal the period map applied in turn
    from absorber_jax._integration.flow import integrate_periods, make_config

    system = rigid(e=0.947)
    omegas = jnp.array([21.0, 28.5, 44.0])
    forcing = aj.Harmonic(amplitude=F0, omega=21.0)
    cfg = make_config(system, forcing)
    x0 = jnp.array([[0.3, 0.2, 0.1, -0.4], [-0.2, 0.5, -0.3, 0.8], [0.1, -0.1, 0.0, 0.2]])

    def period(w, x):
        return aj.orbit_map(system, forcing.with_omega(w), x, 1, cfg)[0]

    def monodromy(w, x):
        return jax.jacfwd(lambda y: period(w, y))(x)

    together = jax.jit(jax.vmap(lambda w, x: (period(w, x), monodromy(w, x))))(omegas, x0)
    for i in range(3):
        alone = jax.jit(lambda w, x: (period(w, x), monodromy(w, x)))(omegas[i], x0[i])
        for a, b in zip(together, alone):
            np.testing.assert_allclose(a[i], b, rtol=1e-12, atol=1e-12)
    # on the stable orbit's side (44 rad/s), where the periods' restarts (rounding) do not
    # grow from period to period
    f = forcing.with_omega(44.0)
    ys, st = jax.jit(lambda x: integrate_periods((system, f), x, 0.0, f.period, 5, cfg))(x0[2])
    assert int(st) == 0
    x = x0[2]
    for k in range(5):
        x = period(44.0, x)
        np.testing.assert_allclose(ys[k], x, rtol=1e-9, atol=1e-9)


def test_padding_lanes_run_one_after_the_other_are_skipped():
    # a batch padded to its compiled size (band_continuation's corrector rounds): lane by
    # lane, a padding lane is not run (its outputs zeros) and the real lanes equal their
    # solves alone; vmapped, every lane is computed
    from absorber_jax._core.devices import lanes_on_devices

    system = rigid(e=0.947)
    forcing = aj.Harmonic(amplitude=F0, omega=21.0)
    from absorber_jax._integration.flow import make_config

    cfg = make_config(system, forcing)
    omegas = jnp.array([21.0, 28.5, 44.0, 21.0])
    x0 = jnp.array([[0.3, 0.2, 0.1, -0.4], [-0.2, 0.5, -0.3, 0.8], [0.1, -0.1, 0.0, 0.2],
                    [0.3, 0.2, 0.1, -0.4]])
    live = jnp.array([True, False, True, False])

    def one(shared, w, x):
        return aj.orbit_map(system, forcing.with_omega(w), x, 1, shared)

    for serial in (True, False):
        out, st = jax.jit(lambda c, w, x, lv, serial=serial: lanes_on_devices(
            one, c, w, x, ndev=1, serial=serial, live=lv))(cfg, omegas, x0, live)
        for i in range(4):
            if serial and not live[i]:
                assert np.all(np.asarray(out[i]) == 0.0) and int(st[i]) == 0
                continue
            alone = aj.orbit_map(system, forcing.with_omega(float(omegas[i])), x0[i], 1, cfg)
            np.testing.assert_allclose(out[i], alone[0], rtol=1e-12, atol=1e-12)


def test_sampled_flight_apexes_equal_the_close_integration():
    # the closest approach of an impacting orbit's free flights to the walls, from the
    # corrector's own 256 samples a period (Section.approach) against the orbit integrated
    # again at rtol 1e-12 with 4096 samples (what a grazing is located on): within 1e-8 of
    # the motion's length scale (measured 6e-10), far inside the 1e-6 that lets the
    # continuation skip the close integration
    import dataclasses

    from absorber_jax._continuation.constants import APPROACH_MARGIN
    from absorber_jax._continuation.driver import _apex, _orbit_kinematics
    from absorber_jax._integration.flow import make_config, state_scale
    from absorber_jax._periodic.orbit import sample_orbit, sampled_approach

    system = rigid(e=0.947)
    coarse = jax.jit(lambda f, x, cfg: sampled_approach(system, f, sample_orbit(
        system, f, x, 1, cfg)[0], 1))
    seen = 0
    for w in (21.0, 24.0, 30.0, 42.0, 44.0):
        f = aj.Harmonic(amplitude=F0, omega=w)
        ss = aj.steady_state(system, f)
        if int(ss.status) != 0:
            continue
        cfg = make_config(system, f)
        sc = state_scale(system, f)
        x0 = system.to_internal(ss.state)
        g = float(coarse(f, x0 / sc, cfg))
        ts = jnp.linspace(0.0, f.period, 4097)
        kin, _ = _orbit_kinematics(system, f, x0, ts, dataclasses.replace(cfg, rtol=1e-12,
                                                                          atol=1e-12))
        length = float(np.max(np.abs(sc)))
        exact = _apex(*(np.asarray(k) for k in kin), float(ts[1]), length, length * w)
        if exact == -length:                # no flight turns before a wall
            assert g == -np.inf
            continue
        seen += 1
        assert exact < -1e3 * APPROACH_MARGIN * length          # clear of the walls
        assert abs(g - exact) <= 1e-8 * length, (w, g, exact)
    assert seen >= 3


def test_design_gradient_through_the_impacts_matches_central_differences():
    # a stable orbit with four impacts a period and no sticking
    omega, names = 37.5, ["gap", "e", "m", "k"]
    system = rigid()
    val, grads, status = aj.value_and_grad(system, names, [omega], amplitude=F0,
                                           objective=aj.objectives.MeanSquare(n_freq=1))
    assert np.all(status == 0)
    tight = dict(method=aj.Shooting(tol=1e-12),
                 integrator=aj.Integrator(rtol=1e-12, atol=1e-12))

    def amp2(name, value):
        s = aj.replace_params(system, {name: value})
        ss = aj.steady_state(s, aj.Harmonic(amplitude=F0, omega=omega), **tight)
        assert int(ss.status) == 0 and float(ss.impacts) == 4.0
        return float(ss.amplitude) ** 2

    np.testing.assert_allclose(val, amp2("gap", SCENE["gap"]), rtol=1e-6)
    for name in names:
        p = float(aj.get_param(system, name))
        h = 1e-5 * p
        fd = (amp2(name, p + h) - amp2(name, p - h)) / (2 * h)
        assert abs(fd) > 1e-3 * val / p          # each parameter matters here
        # (measured: within 2e-9 of the central differences for all four)
        np.testing.assert_allclose(grads[name], fd, rtol=1e-6, err_msg=name)


@pytest.mark.slow
def test_penalty_laws_converge_to_the_rigid_mode_at_a_fitted_rate():
    # Kelvin-Voigt walls with the restitution of the rigid law (exact for a single impact):
    # the orbit's amplitude converges as the contact stiffens
    omega = 37.5
    f = aj.Harmonic(amplitude=F0, omega=omega)
    exact = float(aj.steady_state(rigid(), f).amplitude)
    ks = np.array([1e5, 1e6, 1e7])
    errs = []
    for kc in ks:
        law = aj.KelvinVoigt.from_restitution(kc, E, SCENE["m"], SCENE["M"], eps=1e-9)
        ss = aj.steady_state(aj.ImpactAbsorber(**SCENE, contact=law), f)
        assert int(ss.status) == 0
        errs.append(abs(float(ss.amplitude) - exact) / exact)
    rate = np.polyfit(np.log(ks), np.log(errs), 1)[0]
    assert np.all(np.diff(errs) < 0), errs
    assert -1.2 < rate < -0.3, (rate, errs)


def test_bad_restitution_input_is_refused_before_compilation():
    with pytest.raises(ValueError, match="Restitution.e must be in"):
        aj.Restitution(1.5)
    with pytest.raises(ValueError, match="gap"):
        aj.ImpactAbsorber(M=1.0, k=1e3, c=0.5, m=0.2, gap=0.0, contact=aj.Restitution(0.5))
    assert aj.parameter_names(rigid()) == ["M", "k", "c", "m", "gap", "e"]
    assert float(aj.get_param(rigid(e=0.3), "e")) == 0.3
    assert isinstance(rigid().contact, aj.AbstractContactLaw)
    assert not isinstance(rigid().contact, aj.AbstractCompliantLaw)
    assert float(jnp.asarray(rigid().contact.impulse(2.0, 0.5))) == pytest.approx(1.6)


def test_a_one_storey_structure_with_a_rigid_ball_equals_the_impact_absorber():
    st = aj.structure_from_matrices([[SCENE["M"]]], [[SCENE["k"]]], damping=[[SCENE["c"]]],
                                    dof_names=["x1"])
    ball = aj.ImpactDamper("x1", m=SCENE["m"], gap=SCENE["gap"], contact=aj.Restitution(E))
    structural = aj.StructuralSystem(st, [ball], load="x1")
    assert structural.hybrid
    ts = np.linspace(0.0, 1.0, 1001)
    f = aj.Harmonic(amplitude=F0, omega=30.0)
    tight = aj.Integrator(rtol=1e-11, atol=1e-13)
    a = aj.simulate(rigid(), f, 1.0, ts=ts, integrator=tight)
    b = aj.simulate(structural, f, 1.0, ts=ts, integrator=tight)
    np.testing.assert_allclose(np.asarray(b.ys)[:, 0], np.asarray(a.x1), atol=1e-12)
    f = aj.Harmonic(amplitude=F0, omega=37.5)
    s1, s2 = aj.steady_state(rigid(), f), aj.steady_state(structural, f)
    np.testing.assert_allclose(float(s2.amplitude), float(s1.amplitude), rtol=1e-9)
    assert float(s2.impacts) == float(s1.impacts) == 4.0
    np.testing.assert_allclose(np.sort(np.abs(np.asarray(s2.multipliers))),
                               np.sort(np.abs(np.asarray(s1.multipliers))), rtol=1e-6)


@pytest.mark.parametrize("with_spring", [False, True])
def test_prepared_contact_matrices_give_every_hybrid_member_unchanged(with_spring):
    # StructuralSystem.prepared reads the rigid elements from matrices; every hybrid member
    # must equal the one evaluating the elements, in every mode and in its derivatives, on
    # an affine system (two balls and a floor-to-floor stop) and on one that is not (a
    # cubic spring added: the rate at zero contact force is then evaluated as before)
    from builders import CubicSpring

    st = aj.shear_building([2.0, 1.0], [1e3, 1.5e3], rayleigh=(0.3, 1e-3))
    elements = [aj.ImpactDamper("floor2", m=0.3, gap=2e-3, contact=aj.Restitution(0.7)),
                aj.ImpactDamper("floor1", m=0.2, gap=1e-3, contact=aj.Restitution(0.5)),
                aj.Contact("floor2", other="floor1", gap=3e-3, contact=aj.Restitution(0.6))]
    if with_spring:
        elements.append(CubicSpring("floor1", k3=2e6))
    system = aj.StructuralSystem(st, elements, load="floor2")
    ready = system.prepared()
    assert ready.contact_matrices is not None and system.contact_matrices is None
    assert (ready.contact_matrices.A is None) == with_spring
    assert ready.prepared() is ready
    f = aj.Harmonic(amplitude=2.0, omega=25.0)

    @jax.jit
    def members(sys_, t, s, ds, mode):
        rate = jax.jvp(lambda y: sys_.mode_rate(t, y, f, mode), (s,), (ds,))
        switch = jax.jvp(lambda y: sys_.switch_function(t, y, f, mode), (s,), (ds,))
        return (*rate, *switch, *sys_.next_mode(t, s, f, mode), sys_.mode_of(t, s, f),
                sys_.admissible_state(t, s, f))

    rng = np.random.default_rng(3)
    n = system.num_states
    for _ in range(3):
        s = jnp.asarray(rng.normal(size=n) * 1e-3)
        ds = jnp.asarray(rng.normal(size=n))
        t = float(rng.uniform(0.0, 0.3))
        for mode in ([0, 0, 0], [1, 0, 0], [0, -1, 1], [-1, 0, 1]):
            mode = jnp.asarray(mode)
            a = members(system, t, s, ds, mode)
            b = members(ready, t, s, ds, mode)
            for k in (0, 1, 2, 3, 5, 7):      # rates, switches, jumped and admissible states
                np.testing.assert_allclose(b[k], a[k], rtol=1e-10,
                                           atol=1e-10 * np.max(np.abs(a[k])))
            for k in (4, 6):                  # next mode, mode
                np.testing.assert_array_equal(b[k], a[k])


def test_elastic_impacts_of_two_balls_conserve_a_buildings_energy():
    # no damping, no load, e = 1: every impact (its impulse from the structure's mass
    # matrix) must keep the mechanical energy; e < 1 must lose some at every impact
    st = aj.shear_building([2.0, 1.0], [1e3, 1e3])
    balls = [aj.ImpactDamper("floor2", m=0.3, gap=2e-3, contact=aj.Restitution(1.0)),
             aj.ImpactDamper("floor1", m=0.2, gap=1e-3, contact=aj.Restitution(1.0))]
    system = aj.StructuralSystem(st, balls, load="floor2")
    y0 = np.zeros(system.num_states)
    y0[:2] = [0.01, -0.02]                       # the floors released from a deflection
    f = aj.Harmonic(amplitude=0.0, omega=20.0)
    ts = np.linspace(0.0, 3.0, 3001)
    tr = aj.simulate(system, f, 3.0, y0=y0, ts=ts,
                     integrator=aj.Integrator(rtol=1e-11, atol=1e-14))
    assert int(tr.status) == 0
    s = np.asarray(tr.ys)
    energy = np.array([float(system.mechanical_energy(jnp.asarray(si))) for si in s[::100]])
    strokes = s[:, [4, 6]]
    assert np.all(np.abs(strokes) <= np.array([2e-3, 1e-3]) * (1 + 1e-12))
    # both balls hit their walls many times
    for j, gap in enumerate((2e-3, 1e-3)):
        assert np.sum(np.abs(strokes[:, j]) > 0.9 * gap) > 20
    np.testing.assert_allclose(energy, energy[0], rtol=1e-8)
    lossy = aj.StructuralSystem(st, [b.__class__(b.dof, m=b.m, gap=b.gap,
                                                 contact=aj.Restitution(0.7)) for b in balls],
                                load="floor2")
    tr = aj.simulate(lossy, f, 3.0, y0=y0, ts=ts, integrator=aj.Integrator(rtol=1e-11,
                                                                           atol=1e-14))
    e_end = float(lossy.mechanical_energy(jnp.asarray(tr.ys)[-1]))
    assert e_end < 0.9 * energy[0]


def test_restitution_of_a_compliant_law_matches_the_closed_form():
    for adhesive, tol in ((True, 1e-8), (False, 1e-6)):
        for e in (0.3, 0.6, 0.9):
            law = aj.KelvinVoigt.from_restitution(2e4, e, 0.2, 1.0, adhesive=adhesive)
            assert abs(aj.restitution_of(law, 0.2, 1.0) - e) < tol
    # Hertz with viscous damping: more elastic at higher speed (the damping force grows
    # more slowly than the elastic one)
    hertz = aj.Hertz(stiffness=5.2e10, damping=2e4)
    es = [aj.restitution_of(hertz, 50.0, 1000.0, v) for v in (0.01, 0.1, 1.0)]
    assert 0 < es[0] < es[1] < es[2] < 1
    with pytest.raises(ValueError, match="compliant"):
        aj.restitution_of(aj.Restitution(0.5), 0.2)


def _stop_oscillator():
    # x'' + 0.1 x' + x = A sin t with a rigid stop at x = 1, e = 0.8
    st = aj.structure_from_matrices([[1.0]], [[1.0]], damping=[[0.1]], dof_names=["x"])
    return aj.StructuralSystem(st, [aj.Contact("x", gap=1.0, contact=aj.Restitution(0.8))],
                               load="x")


def test_rigid_stop_against_ground_matches_the_event_exact_reference():
    from reference_impacts import RigidStopOscillator

    ts = np.linspace(0.0, 60.0, 601)
    for A, W in ((0.5, 1.0), (2.0, 1.0)):
        ref, events = RigidStopOscillator(1.0, 0.1, 1.0, 1.0, 0.8, A, W).run([0, 0], 0.0, 60.0,
                                                                           ts)
        assert sum(k == "impact" for _, k in events) >= 8
        tr = aj.simulate(_stop_oscillator(), aj.Harmonic(amplitude=A, omega=W), 60.0, ts=ts,
                         integrator=aj.Integrator(rtol=1e-11, atol=1e-13))
        assert int(tr.status) == 0
        x = np.asarray(tr.ys)[:, 0]
        assert np.max(x) <= 1.0 + 1e-12
        np.testing.assert_allclose(x, ref[:, 0], atol=1e-9)


def test_continuation_passes_grazing_and_locates_it():
    # grazing where the free response 10 A reaches the stop: A = 0.1 exactly
    from reference_impacts import RigidStopOscillator

    br = aj.continuation(_stop_oscillator(), aj.Harmonic(amplitude=0.05, omega=1.0),
                         "amplitude", bounds=(0.05, 0.2))
    assert br.termination == "bounds"
    graze = [b for b in br.bifurcations if b.kind == "grazing"]
    assert len(graze) == 1 and graze[0].located
    assert abs(graze[0].value - 0.1) < 1e-8
    impacts = np.asarray(br.steady.impacts)
    values = np.asarray(br.values)
    at = graze[0].index
    # no impact up to the grazing, one beyond it
    assert np.all(impacts[:at + 1] == 0) and np.all(values[:at + 1] <= 0.1 + 1e-9)
    assert np.all(impacts[at + 1:] == 1)
    # the impacting orbits born there may first run back below A = 0.1 (unstable, beside
    # the free orbits) to a fold, then on (stable): each is periodic for the reference, with
    # one impact a period
    back = np.flatnonzero((np.arange(values.size) > at) & (values < 0.1))
    for i in np.concatenate([back, np.flatnonzero(values > 0.12)[::10]]):
        y0 = np.asarray(br.steady.state)[i]
        ref = RigidStopOscillator(1.0, 0.1, 1.0, 1.0, 0.8, float(values[i]), 1.0)
        y1, events = ref.run(y0, 0.0, 2 * np.pi)
        assert np.max(np.abs(y1[-1] - y0)) < 1e-7
        assert sum(k == "impact" for _, k in events) == 1


@pytest.fixture(scope="module")
def four_impact_branch():
    """The hard scene with e matched to its Kelvin-Voigt contact, continued from the
    four-impact orbit at 20 rad/s up to 26 rad/s: ``(e, branch)`` (one continuation for the
    two tests that read it)."""
    e = aj.restitution_of(aj.KelvinVoigt(stiffness=2e4, damping=2.0, adhesive=True),
                          SCENE["m"], SCENE["M"])
    br = aj.continuation(rigid(e), aj.Harmonic(amplitude=F0, omega=20.0), "omega",
                         bounds=(20.0, 26.0), guess=FOUR_IMPACTS_AT_20)
    return e, br


def test_continuation_passes_the_grazing_where_a_fifth_impact_is_born(four_impact_branch):
    # from 20 rad/s, unstable orbits with four impacts a period until one flight between
    # them grazes a wall; the branch goes on along the orbits with the fifth impact born
    # there
    e, br = four_impact_branch
    (graze,) = br.of_kind("grazing")[:1]
    assert graze.located and 25.0 < graze.value < 25.4
    impacts = np.asarray(br.steady.impacts)
    assert np.all(impacts[: graze.index + 1] == 4.0)
    # the event-exact reference at the located value: periodic, four impacts, and the
    # highest apex of the relative motion between them touches the wall
    W = float(graze.value)
    T = 2 * np.pi / W
    ts = np.linspace(0.0, T, 40_001)
    y, events = reference(W, e).run(np.asarray(graze.state), 0.0, T, ts)
    scale = np.array([1.0, W, 1.0, W]) * SCENE["gap"]
    assert np.max(np.abs(y[-1] - y[0]) / scale) < 1e-8
    assert sum(k == "impact" for _, k in events) == 4
    u = np.abs(y[:, 2] - y[:, 0])
    w = y[:, 3] - y[:, 1]
    k = 1 + np.flatnonzero((u[1:-1] >= u[:-2]) & (u[1:-1] >= u[2:])
                           & (np.abs(w[1:-1]) < 1e-3 * W * SCENE["gap"]))   # smooth apexes
    d = 0.5 * (u[k - 1] - u[k + 1]) / (u[k - 1] - 2 * u[k] + u[k + 1])
    apex = u[k] - 0.25 * (u[k - 1] - u[k + 1]) * d
    assert abs(np.max(apex) / SCENE["gap"] - 1) < 1e-7
    # a point just before it: every flight clear of the walls
    i = graze.index
    y, _ = reference(float(br.values[i]), e).run(np.asarray(br.states[i]), 0.0,
                                                 2 * np.pi / float(br.values[i]), ts)
    assert np.max(np.abs(y[:, 2] - y[:, 0])) <= SCENE["gap"] * (1 + 1e-12)
    # beyond it: orbits with five impacts, born below the grazing value (the branch
    # folds back there), each periodic for the reference with five impacts
    born = np.flatnonzero(impacts == 5.0)
    assert born.size >= 5 and born[0] == graze.index + 1
    assert np.all(np.asarray(br.values)[born[:5]] < W)
    for j in born[:3]:
        Wj = float(br.values[j])
        y, events = reference(Wj, e).run(np.asarray(br.states[j]), 0.0, 2 * np.pi / Wj)
        assert np.max(np.abs(y[-1] - np.asarray(br.states[j])) / scale) < 1e-7
        assert sum(k == "impact" for _, k in events) == 5


def test_every_point_past_a_grazing_is_an_orbit_of_the_reference():
    # the hard scene from its three-impact orbit at 20 rad/s: at 21.98212 rad/s a flight
    # grazes a wall and the four-impact orbits born there run back down to 20 rad/s.  A
    # Newton step that crosses the grazing lands where the period map jumps; such a point
    # is no orbit and must not be reported solved (the branch located the grazing after
    # it, then stopped)
    e = aj.restitution_of(aj.KelvinVoigt(stiffness=2e4, damping=2.0, adhesive=True),
                          SCENE["m"], SCENE["M"])
    br = aj.continuation(rigid(e), aj.Harmonic(amplitude=F0, omega=20.0), "omega",
                         bounds=(20.0, 23.0), guess=THREE_IMPACTS_AT_20)
    assert br.termination == "bounds" and br.reached
    (graze,) = br.of_kind("grazing")
    assert graze.located and abs(graze.value - 21.98212) < 1e-4
    v, impacts = np.asarray(br.values), np.asarray(br.steady.impacts)
    assert np.all(impacts[: graze.index + 1] == 3) and np.all(impacts[graze.index + 1:] == 4)
    assert np.all(v[graze.index + 1:] < graze.value) and v[-1] == 20.0
    assert np.all(np.asarray(br.status) == 0)
    for j in range(len(v)):
        W = float(v[j])
        y0 = np.asarray(br.states[j])
        y1, events = reference(W, e).run(y0, 0.0, 2 * np.pi / W)
        scale = SCENE["gap"] * np.array([1.0, W, 1.0, W])
        assert np.max(np.abs(y1[-1] - y0) / scale) < 1e-7, (j, W)
        assert sum(k == "impact" for _, k in events) == impacts[j]


def test_continuation_moves_its_section_off_an_impact_and_follows_the_branch_on(
        four_impact_branch):
    # the same branch on: the five-impact orbits born at 25.18 rad/s fold back down to
    # 20.09 rad/s, turn stable and go up to 26 rad/s.  At 21.51 rad/s on the way down an
    # impact drifts through the Poincaré section at t = 0 (the period map jumps there); the
    # branch moves its section to where the ball flies farthest from the walls and goes on
    e, br = four_impact_branch
    assert br.termination == "bounds" and br.reached
    v, impacts = np.asarray(br.values), np.asarray(br.steady.impacts)
    (graze,) = br.of_kind("grazing")
    folds = br.of_kind("fold")
    assert len(folds) == 1 and 20.0 < folds[0].value < 20.2
    born = np.arange(graze.index + 1, len(v))
    assert np.all(impacts[born] == 5.0)
    down = born[born <= folds[0].index]
    assert v[down].min() < 21.3 and v[-1] == 26.0      # past 21.51 down, and back up
    stable = np.flatnonzero(np.asarray(br.stable))
    assert stable.size >= 3 and np.all(impacts[stable] == 5.0)
    # points past the old stop, a stable one and an unstable one on the way back up, each
    # periodic with five impacts for the event-exact reference, labelled by its multipliers
    scale = np.array([1.0, 1.0, 1.0, 1.0]) * SCENE["gap"]
    checks = [down[-1], stable[len(stable) // 2], len(v) - 2]
    for j in checks:
        W = float(v[j])
        T = 2 * np.pi / W
        y0 = np.asarray(br.states[j])
        sc = scale * np.array([1.0, W, 1.0, W])
        y1, events = reference(W, e).run(y0, 0.0, T)
        assert np.max(np.abs(y1[-1] - y0) / sc) < 1e-7
        assert sum(k == "impact" for _, k in events) == 5
        J = np.zeros((4, 4))
        for i in range(4):
            h = np.zeros(4)
            h[i] = 1e-7 * sc[i]
            J[:, i] = (reference(W, e).run(y0 + h, 0.0, T)[0][-1]
                       - reference(W, e).run(y0 - h, 0.0, T)[0][-1]) / (2 * h[i])
        mu_ref = np.max(np.abs(np.linalg.eigvals(J)))
        assert bool(br.stable[j]) == bool(mu_ref < 1.0)
        np.testing.assert_allclose(np.max(np.abs(np.asarray(br.multipliers[j]))), mu_ref,
                                   rtol=1e-4)
    # the period doubling where the branch turns unstable again: located (two complex pairs
    # meet on the negative real axis first, and one of the real multipliers they part into
    # crosses -1), the orbits 0.005 rad/s either side of it stable and unstable with a real
    # multiplier either side of -1
    pds = br.of_kind("period_doubling")
    (pd,) = [b for b in pds if 21.4 < b.value < 21.7]
    assert pd.located
    # and the bubble of period doublings on the stable part near the fold (20.50 and
    # 20.70 rad/s): between them the orbit is unstable with a real multiplier below -1
    bubble = sorted((b for b in pds if 20.3 < b.value < 20.9), key=lambda b: b.value)
    assert len(bubble) == 2 and all(b.located for b in bubble)
    mid = 0.5 * (bubble[0].value + bubble[1].value)
    ss = aj.steady_state(rigid(e), aj.Harmonic(amplitude=F0, omega=mid),
                         guess=np.asarray(br.states[bubble[0].index]))
    mu = np.asarray(ss.multipliers)
    assert int(ss.status) == 0 and not bool(ss.stable)
    assert np.min(mu[np.abs(mu.imag) < 1e-9].real) < -1.0
    guess = np.asarray(br.states[pd.index])
    for dw, stable_side in ((-0.005, True), (0.005, False)):
        ss = aj.steady_state(rigid(e), aj.Harmonic(amplitude=F0, omega=pd.value + dw),
                             guess=guess)
        mult = np.asarray(ss.multipliers)
        real = mult[np.abs(mult.imag) < 1e-9].real
        assert int(ss.status) == 0 and bool(ss.stable) == stable_side
        assert (real.min() > -1.0) == stable_side and abs(real.min() + 1.0) < 0.1


@pytest.mark.slow
def test_sweep_continuation_and_attractor_map_agree_on_an_impacting_orbit():
    # one stable orbit (37.5 rad/s, four impacts a period) seen by every entry point
    omega = 37.5
    f = aj.Harmonic(amplitude=F0, omega=omega)
    ss = aj.steady_state(rigid(), f)
    fr = aj.frequency_response(rigid(), [omega], amplitude=F0)
    br = aj.continuation(rigid(), aj.Harmonic(amplitude=F0, omega=37.0), "omega",
                         bounds=(37.0, 38.0))
    i = int(np.argmin(np.abs(np.asarray(br.values) - omega)))
    amap = aj.attractors(rigid(), f, samples=8)
    periodic = [a for a in amap.attractors if a.periodic and a.stable]
    assert bool(ss.stable) and float(ss.impacts) == 4.0
    assert fr.impacts[0] == 4.0 and bool(fr.stable[0])
    assert abs(br.values[i] - omega) < 0.2              # the nearest branch point
    assert float(np.asarray(br.steady.impacts)[i]) == 4.0 and bool(np.asarray(br.stable)[i])
    near = [a for a in periodic if abs(a.amplitude - float(ss.amplitude)) < 1e-6]
    assert near and near[0].impacts == 4.0 and near[0].period_multiple == 1
    # the bifurcation diagram colours the states that reach it as period-1 (the attractor's
    # period, whatever each state's marching status), and says so in its legend
    (dmap,) = aj.bifurcation_diagram(rigid(), f, [omega], samples=8)
    assert np.all(dmap.periods()[near[0].members] == 1)
    assert np.all(dmap.periods() == amap.periods())
    fig, ax = plt.subplots()
    aj.plot_bifurcation_diagram([dmap], ax=ax)
    labels = ax.get_legend_handles_labels()[1]
    plt.close(fig)
    assert "period-1" in labels
    assert ("not periodic" in labels) == any(not a.periodic for a in amap.attractors)


def test_energy_lost_in_sticking_and_chatter_is_newtons_loss_per_impact():
    # a strongly, slowly shaken primary: the ball chatters into sticking on both walls
    omega, F = 20.0, 30.0
    T = 2 * np.pi / omega
    system = rigid(c=0.0)
    ts = np.linspace(0.0, T, 200_001)
    tr = aj.simulate(system, aj.Harmonic(amplitude=F, omega=omega), T, ts=ts,
                     integrator=aj.Integrator(rtol=1e-12, atol=1e-14))
    assert int(tr.status) == 0
    p = SCENE
    ref = RigidImpactAbsorber(p["M"], p["k"], 0.0, p["m"], p["gap"], E, F, omega)
    _, events = ref.run([0, 0, 0, 0], 0.0, T)
    kinds = [k for _, k in events]
    assert kinds.count("stick") >= 1 and kinds.count("impact") > 20
    # mechanical energy change = work of the force - Newton's loss at every impact
    s = jnp.asarray(tr.ys)
    energy = np.asarray(jax.vmap(system.mechanical_energy)(jax.vmap(system.to_internal)(s)))
    # the work ∫ F v1 dt by parts, [F x1] - ∫ x1 F' dt: x1 is continuous through the
    # impacts (v1 jumps), so the trapezoid rule keeps second order
    x1 = np.asarray(tr.x1)
    force = F * np.sin(omega * ts)
    dforce = F * omega * np.cos(omega * ts) * x1
    work = force[-1] * x1[-1] - force[0] * x1[0] - np.sum(0.5 * (dforce[1:] + dforce[:-1])
                                                          * np.diff(ts))
    lost = work - (energy[-1] - energy[0])
    np.testing.assert_allclose(lost, sum(ref.losses), rtol=1e-6)
    # the losses matter: the balance at 1e-6 of them is ~1e-8 of the work
    assert sum(ref.losses) > 1e-3 * abs(work)
    # while stuck the ball moves with the wall: samples held against a wall
    u = np.asarray(tr.x2) - np.asarray(tr.x1)
    assert np.mean(np.abs(np.abs(u) - p["gap"]) < 1e-12) > 0.05


def test_a_zeno_sequence_below_the_rounding_floor_ends_in_sticking():
    # the hard scene's ball (e = 0.947) released 1 nm off the wall it is pressed against
    # (~0.3 m/s², the primary moving at 0.12 m/s): its bounces decay until the flights'
    # rounding of the relative position gives them back as much energy as the impacts take
    # (~4e-9 m/s), long before what remains of the sequence is ZENO_FRACTION of the period.
    # The event-exact reference at that fraction chatters on without sticking; ended where
    # a bounce no longer rises above the rounding, the sequence sticks where the reference
    # with a looser fraction (1e-5 of the period) does, and the ball rides the wall until
    # it is released
    e, gap, omega = 0.947, SCENE["gap"], 20.05
    system = rigid(e)
    forcing = aj.Harmonic(amplitude=F0, omega=omega)
    t0, x1, v1 = 42.934, -2.937e-4, 0.1220
    a_rel = -(float(forcing(t0)) - SCENE["c"] * v1 - SCENE["k"] * x1) / SCENE["M"]
    side = np.sign(a_rel)
    y0 = np.array([x1, v1, x1 + side * (gap - 1e-9), v1])
    ts = t0 + np.linspace(0.0, 0.01, 2001)
    tr = aj.simulate(system, forcing, ts[-1], t0=t0, ts=ts, y0=y0)
    assert int(tr.status) == 0
    _, events = reference(omega, e, zeno=1e-7).run(y0, t0, ts[-1], ts)
    assert not any(k == "stick" for _, k in events)
    assert sum(k == "impact" for _, k in events) > 100
    ref, events = reference(omega, e, zeno=1e-5).run(y0, t0, ts[-1], ts)
    t_stick = [t for t, k in events if k == "stick"]
    assert len(t_stick) == 1
    np.testing.assert_allclose(np.asarray(tr.x1), ref[:, 0], rtol=0, atol=1e-10 * gap)
    np.testing.assert_allclose(np.asarray(tr.x2), ref[:, 2], rtol=0, atol=1e-10 * gap)
    u = np.asarray(tr.x2) - np.asarray(tr.x1)
    w = np.asarray(tr.v2) - np.asarray(tr.v1)
    t_free = min([t for t, k in events if k == "release"] + [ts[-1]])
    held = (ts > t_stick[0] + 1e-5) & (ts < t_free - 1e-5)
    assert np.sum(held) > 100
    assert np.all(np.abs(u[held] - side * gap) < 1e-15) and np.all(w[held] == 0.0)
    assert not np.any((np.abs(u - side * gap) < 1e-15)[ts < t_stick[0] - 1e-5] & (
        w[ts < t_stick[0] - 1e-5] == 0.0))


def test_a_rigid_band_runs_on_two_cpu_devices():
    # band_continuation of an event-driven system in a process with two CPU devices (its
    # batched correctors' lanes split over both, each device running its lanes one after
    # the other: flights in closed form); its points are the orbits steady_state finds in
    # this process
    import json
    import os
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent(f"""
        import json, warnings
        import absorber_jax as aj
        assert aj.use_cpu_cores(2) == 2
        system = aj.ImpactAbsorber(**{SCENE!r}, contact=aj.Restitution(0.947))
        f = aj.Harmonic(amplitude={F0!r}, omega=42.0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            brs = aj.band_continuation(system, f, "omega", bounds=(42.0, 44.0), starts=2,
                                       fill=0)
        print(json.dumps([[b.values.tolist(), b.steady.amplitude.tolist(),
                           b.steady.status.tolist()] for b in brs]))
    """)
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    branches = json.loads(out.stdout.strip().splitlines()[-1])
    assert len(branches) == 4
    values = np.concatenate([np.asarray(v) for v, _, _ in branches])
    assert values.min() == pytest.approx(42.0) and values.max() == pytest.approx(44.0)
    v, amp, status = branches[3]                    # the upper start, up
    assert all(s == 0 for s in status)
    for i in (0, len(v) - 1):
        one = aj.steady_state(rigid(e=0.947), aj.Harmonic(amplitude=F0, omega=v[i]))
        assert int(one.status) == 0
        np.testing.assert_allclose(amp[i], float(one.amplitude), rtol=1e-6)


def test_a_branch_creeping_to_an_impacts_grazing_locates_it_and_goes_on():
    # the hard rigid scene from 29.36 rad/s down: orbits with 16 impacts, the slowest of
    # which slows to zero speed at a grazing (its saltation, ~1/speed, grows without bound
    # and Newton's basin shrinks with it: the branch would creep towards it for hundreds of
    # points).  The grazing is extrapolated on the fixed sequence of events; beyond it the
    # orbits have one impact fewer (the flight turns short of the wall), back up (a
    # nonsmooth fold)
    e = aj.restitution_of(aj.KelvinVoigt(stiffness=2e4, damping=2.0, adhesive=True),
                          SCENE["m"], SCENE["M"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        down = aj.continuation(rigid(e), aj.Harmonic(amplitude=F0, omega=29.36), "omega",
                               bounds=(29.0, 29.45), direction="down",
                               guess=SIXTEEN_IMPACTS_AT_29_36)
    graze = down.of_kind("grazing")[0]
    impacts, v = np.asarray(down.steady.impacts), np.asarray(down.values)
    assert graze.located and 29.05 < graze.value < 29.2
    count = impacts[graze.index]
    assert count == 16 and impacts[graze.index + 1] == count - 1
    # (creeping on, the branch would spend its 400 points short of the grazing)
    assert graze.index < 250
    # the orbit at the located value (steady_state from the reported state: at the
    # grazing itself the period map is not smooth and |mu| runs to the hundreds, so the
    # reported state is an approximation, 1e-4 of the state scale): periodic for the
    # event-exact reference, and its highest flight reaches the wall
    W = float(graze.value)
    T = 2 * np.pi / W
    scale = np.array([1.0, W, 1.0, W]) * SCENE["gap"]
    ss = aj.steady_state(rigid(e), aj.Harmonic(amplitude=F0, omega=W), guess=graze.state)
    assert int(ss.status) == 0
    assert np.max(np.abs(np.asarray(ss.state) - graze.state) / scale) < 1e-4
    y, events = reference(W, e).run(np.asarray(ss.state), 0.0, T, np.linspace(0, T, 40_001))
    assert np.max(np.abs(y[-1] - y[0]) / scale) < 1e-7
    assert abs(np.max(np.abs(y[:, 2] - y[:, 0])) / SCENE["gap"] - 1) < 1e-7
    assert sum(k == "impact" for _, k in events) in (count - 1, count)
    # beyond: periodic with one impact fewer
    j = graze.index + 1
    Wj = float(v[j])
    y, events = reference(Wj, e).run(np.asarray(down.states[j]), 0.0, 2 * np.pi / Wj)
    assert np.max(np.abs(y[-1] - np.asarray(down.states[j])) / scale) < 1e-5
    assert sum(k == "impact" for _, k in events) == count - 1
