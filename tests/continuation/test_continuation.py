"""Continuation of periodic orbits: branches through folds, bifurcations detected
and located, branch switching at a period doubling, against independent references: a
closed-form linear FRF, the jump frequencies of slow stepped marching sweeps written with
exact piecewise-linear flows (reference_jumps.py), and the exact continuation of NLvib's
example 03 (reference_nlvib03.py)."""

import warnings

import numpy as np
import pytest
import reference_jumps as rj
import reference_nlvib03 as ref03
from builders import HARD, CubicSpring, hardening, nlvib03
from reference_jumps import slow_sweep_jumps

import absorber_jax as aj


def test_linear_branch_follows_the_closed_form_frf_without_bifurcations():
    """A TMD on one DOF (linear): the branch in ω is the closed-form receptance (1e-6), every
    point stable, no bifurcation, and it ends on the bound."""
    k, m, c, kt, mt, ct, F0 = 1e3, 1.0, 0.4, 50.0, 0.05, 0.3, 2.0
    st = aj.structure_from_matrices(np.eye(1) * m, np.eye(1) * k, damping=np.eye(1) * c)
    sysm = aj.StructuralSystem(st, [aj.TunedMassDamper("x1", m=mt, k=kt, c=ct)], load="x1")
    br = aj.continuation(sysm, aj.Harmonic(amplitude=F0, omega=20.0), "omega",
                         bounds=(20.0, 45.0), method=aj.PseudoArclength(step=0.05, max_step=0.1))
    w = br.values
    zt = kt + 1j * w * ct
    d_tmd = zt * (-mt * w**2) / (zt - mt * w**2)          # the TMD as a dynamic stiffness
    X = F0 / (k - m * w**2 + 1j * w * c + d_tmd)
    err = np.max(np.abs(br.dof("x1", "harmonic") - np.abs(X)) / np.abs(X))
    print(f"linear branch: {len(br)} points, worst relative error {err:.1e}")
    assert err < 1e-6
    assert br.termination == "bounds" and np.isclose(w[-1], 45.0, rtol=1e-12)
    assert np.all(np.diff(w) > 0) and len(br) >= 8
    assert br.bifurcations == () and np.all(br.stable) and np.all(br.ok)


def test_folds_are_the_jump_frequencies_of_slow_sweeps():
    """Hardening oscillator with hysteresis: the two folds of the continuation are where
    slow stepped marching sweeps (exact piecewise-linear flows, independent of any
    continuation) jump down (sweeping up) and up (sweeping down), to 1e-3 (we see ~1e-5); the
    branch between the folds is unstable, outside them stable."""
    up = slow_sweep_jumps("up", **HARD)
    down = slow_sweep_jumps("down", **HARD)
    br = aj.continuation(hardening(), aj.Harmonic(amplitude=HARD["F0"], omega=0.8), "omega",
                         bounds=(0.8, 1.6))
    folds = br.of_kind("fold")
    assert [b.kind for b in br.bifurcations] == ["fold", "fold"], br.bifurcations
    hi, lo = folds[0].value, folds[1].value
    e_up = abs(hi - up["W_jump"]) / up["W_jump"]
    e_down = abs(lo - down["W_jump"]) / down["W_jump"]
    print(f"folds {hi:.8f} {lo:.8f}; jumps {up['W_jump']:.8f} {down['W_jump']:.8f}; "
          f"relative differences {e_up:.1e} {e_down:.1e}")
    assert e_up < 1e-3 and e_down < 1e-3
    # the amplitude at the upper fold is the one the up sweep had just before falling off
    assert abs(folds[0].amplitude - up["amp_before"]) < 1e-2 * up["amp_before"]
    # stability: stable before the first fold, unstable between, stable after the second
    i1, i2 = folds[0].index, folds[1].index
    assert np.all(br.stable[:i1]) and np.all(br.stable[i2 + 2:])
    assert not np.any(br.stable[i1 + 2:i2])
    assert br.termination == "bounds" and np.all(br.ok)


def test_band_continuation_covers_the_band_and_finds_both_folds():
    """Branches from two start values followed together (four half-branches, one vmapped
    corrector call per round) cover the hysteresis band of the hardening oscillator; the
    folds they find are the jump frequencies of the slow marching sweeps (1e-3), every
    point converged, the points between the folds unstable and a point's multipliers those
    of steady_state there (1e-5)."""
    up = slow_sweep_jumps("up", **HARD)
    down = slow_sweep_jumps("down", **HARD)
    sysm = hardening()
    forcing = aj.Harmonic(amplitude=HARD["F0"], omega=1.0)
    brs = aj.band_continuation(sysm, forcing, "omega", bounds=(0.8, 1.6), starts=2)
    assert len(brs) == 4 and all(np.all(b.ok) for b in brs)
    assert all(b.termination == "bounds" for b in brs), [b.termination for b in brs]
    assert min(b.values.min() for b in brs) == pytest.approx(0.8, abs=1e-12)
    assert max(b.values.max() for b in brs) == pytest.approx(1.6, abs=1e-12)
    folds = sorted({round(f.value, 6) for b in brs for f in b.of_kind("fold")})
    print(f"band_continuation folds {folds}; jumps {up['W_jump']:.6f} {down['W_jump']:.6f}")
    for w in (up["W_jump"], down["W_jump"]):
        assert min(abs(f - w) / w for f in folds) < 1e-3
    # every fold lies between its own half-branch's points index and index + 1 (a fold seen
    # by both half-branches of a cell is located once and given to the other), at the
    # values continuation locates on its one branch, from other brackets, to 1e-8
    br = aj.continuation(sysm, aj.Harmonic(amplitude=HARD["F0"], omega=0.8), "omega",
                         bounds=(0.8, 1.6))
    single = [f.value for f in br.of_kind("fold")]
    assert len(single) == 2
    for b in brs:
        for f in b.of_kind("fold"):
            a1, a2 = b.amplitude[f.index], b.amplitude[f.index + 1]
            assert min(a1, a2) <= f.amplitude <= max(a1, a2), (f, a1, a2)
            assert f.located and min(abs(f.value - w) / w for w in single) < 1e-8, f.value
    # ... and some fold was seen by two half-branches and located once: the copy spent no
    # solve and has the located one's value
    located = {f.value for b in brs for f in b.of_kind("fold") if f.evaluations > 0}
    shared = [f for b in brs for f in b.of_kind("fold") if f.evaluations == 0]
    assert shared and all(f.value in located for f in shared)
    # on the half-branch through both folds: stable outside them, unstable between
    two = [b for b in brs if len(b.of_kind("fold")) == 2]
    assert len(two) >= 1
    for b in two:
        i1, i2 = (f.index for f in b.of_kind("fold"))
        assert np.all(b.stable[:i1]) and np.all(b.stable[i2 + 2:])
        assert not np.any(b.stable[i1 + 2:i2])
    b = brs[1]
    i = len(b) // 2
    ss = aj.steady_state(sysm, aj.Harmonic(amplitude=HARD["F0"], omega=float(b.values[i])),
                         guess=b.steady.state[i])
    assert np.max(np.abs(np.sort_complex(b.multipliers[i])
                         - np.sort_complex(ss.multipliers))) < 1e-5


def test_band_continuation_fills_the_parts_its_branches_did_not_reach():
    """One start whose down half-branch stops short (max_points) leaves the low end of the
    band uncovered: the fill passes start branches there, every point of them an orbit of
    the exact piecewise-linear reference (amplitude 1e-6), and together they cover the
    band; without fill the gap stays."""
    sysm = hardening()
    forcing = aj.Harmonic(amplitude=HARD["F0"], omega=1.0)
    method = aj.PseudoArclength(max_points=10)
    lo, hi = 0.8, 1.6
    alone = aj.band_continuation(sysm, forcing, "omega", bounds=(lo, hi), starts=[1.2],
                                 method=method, fill=0)
    assert len(alone) == 2 and alone[0].termination == "max_points"
    assert min(b.values.min() for b in alone) > lo + 0.1
    brs = aj.band_continuation(sysm, forcing, "omega", bounds=(lo, hi), starts=[1.2],
                               method=method, fill=4)
    assert len(brs) > 2 and all(np.all(b.ok) for b in brs)
    spans = sorted((b.values.min(), b.values.max()) for b in brs)
    reach = lo
    for a, b in spans:
        assert a <= reach + 2e-3 * (hi - lo), f"gap {reach:.4f}-{a:.4f}"
        reach = max(reach, b)
    assert reach >= hi - 2e-3 * (hi - lo)
    for b in brs[2:]:                       # the fill passes' branches against the reference
        for i in (0, len(b) - 1):
            ex = rj.periodic_orbit(float(b.values[i]), x_guess=np.asarray(b.states[i]), **HARD)
            assert ex["converged"]
            assert abs(b.amplitude[i] - ex["amp"]) < 1e-6 * ex["amp"]


def test_fill_starts_spread_over_the_gaps_by_width():
    """A fill pass's starts: as many as asked, at least one per gap, the rest to the gaps
    whose parts are widest, each at the centre of an equal part of its gap and bounded by
    it; with more gaps than starts, the widest ones."""
    from absorber_jax._continuation.continuation import _fill_starts

    gaps = [(28.3, 28.5), (29.1, 29.16), (30.0, 30.03)]       # widest first (as _gaps)
    values, limits = _fill_starts(gaps, 8)
    assert values.size == 8 and np.all(np.diff(values) > 0)
    per = {g: [v for v, lim in zip(values, limits) if lim == g] for g in gaps}
    assert [len(per[g]) for g in gaps] == [5, 2, 1]
    for (g0, g1), vs in per.items():
        k = len(vs)
        assert np.allclose(vs, g0 + (np.arange(k) + 0.5) * (g1 - g0) / k)
    values, limits = _fill_starts(gaps, 2)
    assert limits == [(28.3, 28.5), (29.1, 29.16)]
    assert np.allclose(values, [28.4, 29.13])
    assert _fill_starts([], 8)[0].size == 0


def test_curved_predictor_errs_at_third_order_on_a_helix():
    """The predictor a step h along a branch (a helix in the unknowns, radius R, speed c
    per unit angle R, curvature 1/(R c²); two points a step d apart with their unit
    tangents): the tangent's error is h²/(2 R c²); bent by the curvature read off the
    tangents' turn, the error falls to third order (at h = d = R/10 more than ten times
    less).  Across a turn wider than max_angle (a corner: a grazing) the predictor is the
    tangent's."""
    from absorber_jax._continuation.driver import _predict

    R, d = 2.0, 0.2

    def point(s):
        z = np.array([R * np.cos(s / R), R * np.sin(s / R), 0.3 * s])
        t = np.array([-np.sin(s / R), np.cos(s / R), 0.3])
        return dict(z=z, t=t / np.linalg.norm(t), xi=z[:-1], s0=np.ones(2), section=0,
                    ok=True)

    # the curve's speed is sqrt(1 + 0.09): arclength s' = s * sqrt(1.09)
    c = np.sqrt(1.09)
    for h in (0.1, 0.2):
        a, p = point(1.0), point(1.0 - d / c)
        true = point(1.0 + h / c)["z"]
        tangent = np.linalg.norm(a["z"] + h * a["t"] - true)
        curved = np.linalg.norm(_predict([p, a], h, 0.35) - true)
        assert tangent > 0.45 * h**2 / (R * c**2)      # h²κ/2, κ = 1/(R c²)
        assert curved < 0.1 * tangent
    # a corner: the tangent alone; another section or a first point: likewise
    a, p = point(1.0), point(1.0 - 1.5 * R)
    assert np.allclose(_predict([p, a], 0.1, 0.35), a["z"] + 0.1 * a["t"])
    assert np.allclose(_predict([dict(point(0.8), section=1), a], 0.1, 0.35),
                       a["z"] + 0.1 * a["t"])
    assert np.allclose(_predict([a], 0.1, 0.35), a["z"] + 0.1 * a["t"])


def test_step_control_follows_a_tight_turn_without_sharp_rejections():
    """The arclength step after each point, on a branch that is a circle of radius R in
    the unknowns (every step of max_step would turn the tangent by 1 rad, three times
    max_angle), corrected exactly (the circle cut by the predictor's hyperplane): the
    driver's rules (curved predictor, growth after an easy step held to half of max_angle
    of turn, no growth right after a rejected try, a sharp step cut to that turn) go once
    round with no step rejected as sharp after the first two, each step turning the
    tangent by max_angle/4 to max_angle; the step a sharp try is cut to turns it by about
    max_angle/2."""
    import math

    from absorber_jax._continuation.driver import _grow, _predict, _shrink

    method = aj.PseudoArclength()
    R = method.max_step
    rng = np.random.default_rng(0)

    def on_circle(zp, tp):
        c = float(tp @ zp)
        nrm = np.array([-tp[1], tp[0]])
        s = math.sqrt(R * R - c * c) * (1.0 if nrm @ zp >= 0 else -1.0)
        z = c * tp + s * nrm
        t = np.array([-z[1], z[0]]) / R
        return dict(z=z, t=t * np.sign(t @ tp), xi=z[:-1], s0=np.ones(1), section=0, ok=True)

    phi = rng.uniform(0, 2 * np.pi)
    points = [on_circle(R * np.array([np.cos(phi), np.sin(phi)]),
                        np.array([-np.sin(phi), np.cos(phi)]))]
    h, retried, sharp_after, turned, turns = method.step, False, [], 0.0, []
    while turned < 2 * np.pi:
        a = points[-1]
        b = on_circle(_predict(points, h, method.max_angle), a["t"])
        turn = float(np.clip(b["t"] @ a["t"], -1, 1))
        chord = b["z"] - a["z"]
        aside = float(np.clip(chord @ a["t"] / np.linalg.norm(chord), -1, 1))
        angle = max(math.acos(turn), math.acos(aside))
        if angle > method.max_angle:
            sharp_after.append(len(points))
            cut = _shrink(method, turn, aside, True) * h
            assert 0.3 * method.max_angle < cut / R < 0.7 * method.max_angle
            h, retried = cut, True
            continue
        points.append(b)
        turned += math.acos(turn)
        turns.append(math.acos(turn))
        h = min(max(_grow(method, 1, turn, aside, retried) * h, method.min_step),
                method.max_step)
        retried = False
    assert all(k <= 2 for k in sharp_after), sharp_after
    assert min(turns[3:]) > 0.25 * method.max_angle and max(turns) <= method.max_angle
    # a failed corrector halves the step; an easy step on a straight branch grows it by 1.5
    assert _shrink(method, -1.0, 1.0, False) == 0.5
    assert _grow(method, 1, 1.0, 1.0, False) == 1.5
    assert _grow(method, 1, 1.0, 1.0, True) == 1.0
    assert _grow(method, 7, 1.0, 1.0, False) == 0.6


def test_close_returns_of_a_settling_trajectory_lie_on_the_periodic_orbit():
    """band_continuation's fallback seeds (the closest returns of a marched trajectory):
    marched from the scaled linear response at 1.1 (below the hysteresis band: one stable
    orbit), the trajectory settles (the transient decays like exp(-c t / 2): ~1e-6 after
    the 240 periods), so its closest returns lie near the orbit: each seed's state is the
    exact piecewise-linear orbit's state at t = 0 to 1e-3 of the orbit's size, and the
    corrector from a seed converges to it (1e-6)."""
    from absorber_jax._continuation.constants import CLOSE_RETURNS
    from absorber_jax._continuation.driver import (
        _axis,
        _close_returns,
        _config,
        _Driver,
        _first_orbit,
        _run_batched,
    )
    from absorber_jax._continuation.problem import _Problem
    from absorber_jax._integration.flow import state_scale

    sysm = hardening()
    w = 1.1
    f = aj.Harmonic(amplitude=HARD["F0"], omega=w)
    method = aj.PseudoArclength()
    prob = _Problem(system=sysm, forcing=f, s0=state_scale(sysm, f), pscale=np.asarray(w),
                    cfg=_config(sysm, f, "omega", w, None, 1e-9, 1e-9, 200_000),
                    parameter="omega", n=1)
    drv = _Driver(prob, method, (w, w))
    z0 = np.append(np.asarray(sysm.linear_guess(f)) / np.asarray(prob.s0), 1.0)
    (seeds,) = _close_returns([drv], [z0])
    assert len(seeds) == CLOSE_RETURNS
    ex = rj.periodic_orbit(w, **HARD)
    assert ex["converged"]
    x_ex = np.asarray(sysm.to_internal(np.asarray(ex["x"]))) / np.asarray(prob.s0)
    for z in seeds:
        assert np.max(np.abs(z[:-1] - x_ex)) < 1e-3 * np.max(np.abs(x_ex))
    (first,) = _run_batched([_first_orbit(drv, seeds[:1], _axis(prob, "up"))], prob, method)
    assert first["ok"] and np.max(np.abs(first["z"][:-1] - x_ex)) < 1e-6 * np.max(np.abs(x_ex))


def test_multipliers_at_a_branch_point_equal_steady_state():
    """The Floquet multipliers the continuation reads off its final Jacobian equal those of
    steady_state at the same parameter, and both equal the exact piecewise-linear ones
    (reference_jumps.periodic_orbit) to 1e-5: on the stable upper branch, on the unstable
    middle branch, and in another parameter (the gap)."""
    system = hardening()
    # from 1.0 (below the lower fold: the resonant orbit is the only one) up past the fold
    br = aj.continuation(system, aj.Harmonic(amplitude=HARD["F0"], omega=1.0), "omega",
                         bounds=(0.95, 1.3), method=aj.PseudoArclength(max_points=60))
    folds = br.of_kind("fold")
    assert folds, "the upper fold must be passed"

    def check(sysm, f, branch, i, **scene):
        ss = aj.steady_state(sysm, f, guess=branch.states[i])
        assert int(ss.status) == 0
        ex = rj.periodic_orbit(float(f.omega), x_guess=np.asarray(branch.states[i]),
                               **dict(HARD, **scene))
        assert ex["converged"]
        a, b, e = (np.sort_complex(np.asarray(m))
                   for m in (branch.multipliers[i], ss.multipliers, ex["mu"]))
        print(f"{branch.parameter} = {branch.values[i]:.5f}: branch {a}, steady_state {b}, "
              f"exact {e}")
        assert np.max(np.abs(a - e)) < 1e-5 and np.max(np.abs(b - e)) < 1e-5
        assert bool(branch.stable[i]) == bool(ss.stable) == bool(np.max(np.abs(e)) < 1)
        assert abs(branch.amplitude[i] - ex["amp"]) < 1e-5 * ex["amp"]

    for i in (3, folds[0].index + 4):
        check(system, aj.Harmonic(amplitude=HARD["F0"], omega=float(br.values[i])), br, i)
    assert not bool(br.stable[folds[0].index + 4])            # the middle branch: a saddle
    # continuation in a system parameter: the gap, from 0.5 up (the amplitude falls to the
    # linear one once the stop is out of reach)
    f = aj.Harmonic(amplitude=HARD["F0"], omega=1.1)
    bg = aj.continuation(system, f, "contact1.gap", bounds=(0.5, 3.0),
                         method=aj.PseudoArclength(step=0.05, max_step=0.2))
    assert bg.termination == "bounds" and np.all(bg.ok)
    lin = HARD["F0"] / abs(1 - 1.1**2 + 1j * 1.1 * HARD["c"])
    assert abs(bg.amplitude[-1] - lin) < 1e-6 * lin          # gap 3 > amplitude: linear
    j = len(bg) // 3
    g = float(bg.values[j])
    check(aj.replace_params(system, {"contact1.gap": g}), f, bg, j, g=g)


def test_a_section_moved_off_time_zero_reports_the_same_orbit():
    """The orbit statistics from a Poincaré section a quarter period after t = 0 (what
    continuation uses once the section at t = 0 falls inside a contact): the state reported
    is the orbit's at t = 0 (1e-7 of its size), the amplitudes are the section-0 ones
    (1e-9), and the section's clearances are the distances to the stop computed from the
    samples independently."""
    import jax.numpy as jnp

    from absorber_jax._integration.flow import integrate_flow, make_config, state_scale
    from absorber_jax._periodic.orbit import SAMPLES_PER_PERIOD, finish_orbit
    from absorber_jax._systems.forcing import PhasedHarmonic

    system = hardening()
    f = aj.Harmonic(amplitude=HARD["F0"], omega=1.1)
    ss = aj.steady_state(system, f)
    assert int(ss.status) == 0
    cfg = make_config(system, f, None, 1e-10, 1e-10)
    sc = np.asarray(state_scale(system, f))
    x0 = np.asarray(system.to_internal(jnp.asarray(ss.state))) / sc
    j = SAMPLES_PER_PERIOD // 4
    ts = np.arange(SAMPLES_PER_PERIOD + 1) * (f.period / SAMPLES_PER_PERIOD)
    ys, _ = integrate_flow((system, f), jnp.asarray(x0), float(ts[-1]), jnp.asarray(ts), cfg=cfg)
    ys = np.asarray(ys)
    fj = PhasedHarmonic(amplitude=f.amplitude, omega=f.omega,
                        phase=2 * np.pi * j / SAMPLES_PER_PERIOD)
    out, sec = finish_orbit(system, fj, jnp.asarray(ys[j]), 1, cfg, 0, 0.0, 0, n_cap=1,
                       multipliers=jnp.asarray(ss.multipliers), section=jnp.asarray(j))
    size = np.max(np.abs(ss.state))
    assert np.max(np.abs(np.asarray(out.state) - np.asarray(ss.state))) < 1e-7 * size
    assert abs(float(out.amplitude) - float(ss.amplitude)) < 1e-9 * float(ss.amplitude)
    clear = np.array([-float(np.max(np.asarray(system.penetrations(jnp.asarray(y * sc)))))
                      for y in ys[:-1]])
    assert abs(float(sec.clearance) - clear[j]) < 1e-9
    assert abs(float(sec.best_clearance) - clear.max()) < 1e-9 * HARD["g"]
    assert clear[int(sec.best)] == pytest.approx(clear.max(), abs=1e-9)


def test_hard_contact_branch_takes_its_section_where_the_absorber_flies_free():
    """The hard Kelvin-Voigt impact absorber (scripts/benchmark_hard_contacts.py) near
    28.4 rad/s: its period-1 orbit is in contact at t = 0, where the state moves with the
    impact's timing and Newton's basin shrinks (with the section kept at t = 0 the corrector
    takes 5 iterations a point past 28.42 rad/s, the arclength step cannot grow, and a
    half-branch of 40 points ends at 28.49 rad/s).  The section moves to where the absorber
    flies farthest from the walls: a half-branch passes from below 28.3 to beyond 28.6 rad/s
    (to the fold at 28.68) within its 40 points at a median of at most 3 iterations, every point
    converged, and the states it reports (the orbits' at t = 0, see
    test_a_section_moved_off_time_zero_reports_the_same_orbit) are in contact at some.  The
    start at 28.0 rad/s from the linear response may fail (Newton's basin there is small and
    its outcome hangs on rounding); the fill pass starts the branches from marched returns."""
    import jax.numpy as jnp

    system = aj.ImpactAbsorber(M=1.0, k=1e3, c=0.5, m=0.2, gap=2e-3,
                               contact=aj.KelvinVoigt(stiffness=2e4, damping=2.0, adhesive=True))
    f = aj.Harmonic(amplitude=3.0, omega=28.0)
    brs = aj.band_continuation(system, f, "omega", bounds=(27.0, 29.5), starts=[28.0],
                               fill=1, method=aj.PseudoArclength(max_points=40, locate=False),
                               rtol=1e-7, atol=1e-7)
    through = [b for b in brs if np.all(b.ok) and b.values.min() < 28.3
               and b.values.max() > 28.6]
    assert through, [(b.termination, b.values.min(), b.values.max()) for b in brs]
    up = through[0]
    assert len(up.values) <= 40
    assert np.median(np.asarray(up.steady.iterations)) <= 3
    pen = [float(np.max(np.asarray(system.penetrations(system.to_internal(jnp.asarray(x))))))
           for x in up.states]
    assert max(pen) > 0.1 * 2e-3, max(pen)


@pytest.fixture(scope="module")
def nlvib_branch():
    sysm = nlvib03()
    br = aj.continuation(sysm, aj.Harmonic(amplitude=0.1, omega=0.8), "omega",
                         bounds=(0.5, 0.8), direction="down")
    return sysm, br


def test_nlvib03_bifurcations_match_the_exact_continuation(nlvib_branch):
    """NLvib example 03 from Ω = 0.8 down to 0.5 along one branch: both folds, both period
    doublings (the flip window) and both Neimark–Sacker points, located, against the exact
    piecewise-linear continuation (1e-4 relative; the smoothed contact and the corrector
    tolerance set what we see, ~1e-5)."""
    _, br = nlvib_branch
    ex = ref03.continuation()
    exact = {"fold": [f["Omega"] for f in ex["folds"]],
             "period_doubling": [s["Omega"] for s in ex["stability_changes"]
                                 if s["kind"].startswith("flip")],
             "neimark_sacker": [s["Omega"] for s in ex["stability_changes"]
                                if s["kind"] == "Neimark-Sacker"]}
    assert br.termination == "bounds", br.termination
    for kind, values in exact.items():
        ours = sorted(b.value for b in br.of_kind(kind))
        assert len(ours) == len(values) == 2, (kind, ours, values)
        err = np.max(np.abs(np.array(ours) - np.sort(values)) / np.sort(values))
        print(f"{kind}: ours {np.round(ours, 7)}, exact {np.round(np.sort(values), 7)}, "
              f"worst relative difference {err:.1e}")
        assert err < 1e-4
    # multipliers at the located points: -1, a complex pair on the unit circle (where the
    # test function is continuous: the lower Neimark–Sacker point sits 1e-6 from grazing,
    # where the multipliers jump across the circle, and is bracketed, not converged)
    located = [b for b in br.bifurcations if b.located]
    print([(b.kind, round(b.value, 7), b.located, b.evaluations) for b in br.bifurcations])
    assert {b.kind for b in located} == {"fold", "period_doubling", "neimark_sacker"}
    for b in located:
        mu = b.multipliers
        if b.kind == "period_doubling":
            assert np.min(np.abs(mu + 1)) < 1e-3
        if b.kind == "neimark_sacker":
            c = mu[np.abs(mu.imag) > 1e-3]
            assert np.min(np.abs(np.abs(c) - 1)) < 1e-3
    # the branch's peak of |Q2| against the exact one
    q2 = br.dof("x2", "harmonic")
    assert abs(q2.max() - ex["peak_Q2"]) < 2e-3 * ex["peak_Q2"]


def test_harmonic_balance_labels_along_nlvib03_equal_the_floquet_labels(nlvib_branch):
    """Stability of harmonic-balance orbits along NLvib example 03's branch: at every point
    of the shooting branch more than 3e-3 from the exact bifurcations,
    ``HarmonicBalance(harmonics=21, condense=False)`` from that orbit's state converges (at
    90 % of them or more; a failure is flagged, never labelled) to an orbit near
    shooting's (the unilateral spring's kink: algebraic convergence in H), labelled as
    the shooting orbit's Floquet multipliers label it, in every window: stable, the saddle
    branch between the folds (a multiplier beyond +1), the flip window (beyond -1) and the
    Neimark–Sacker window (a complex pair outside the circle)."""
    sysm, br = nlvib_branch
    ex = ref03.continuation()
    exact = np.array([f["Omega"] for f in ex["folds"]]
                     + [c["Omega"] for c in ex["stability_changes"]])
    values, states = np.asarray(br.values), np.asarray(br.states)
    far = np.flatnonzero(np.min(np.abs(values[:, None] - exact[None, :]), axis=1) > 3e-3)
    method = aj.HarmonicBalance(harmonics=21, condense=False)
    ok, same, kinds, gaps = [], [], set(), []
    for i in far:
        ss = aj.steady_state(sysm, aj.Harmonic(amplitude=0.1, omega=float(values[i])),
                             method=method, guess=states[i])
        converged = int(ss.status) == 0
        ok.append(converged)
        if not converged:
            assert not bool(ss.stable)           # a failed point is never called stable
            continue
        shoot_stable = bool(br.stable[i])
        same.append(bool(ss.stable) == shoot_stable)
        gaps.append(abs(float(ss.amplitude) / float(br.amplitude[i]) - 1))
        mu = np.asarray(br.multipliers[i])
        out = mu[np.abs(mu) > 1 + 1e-6]
        kinds.add("stable" if shoot_stable else
                  "neimark_sacker" if np.any(np.abs(out.imag) > 1e-6) else
                  "flip" if np.any(out.real < 0) else "saddle")
    print(f"{len(far)} points: {sum(ok)} converged, labels equal at {sum(same)}, "
          f"largest amplitude gap {max(gaps):.1e}, windows {sorted(kinds)}")
    assert np.mean(ok) >= 0.9
    assert all(same)
    assert kinds == {"stable", "saddle", "flip", "neimark_sacker"}
    assert max(gaps) < 1e-2          # measured 2.6e-3


@pytest.mark.slow  # CI time (the bifurcations of the same branch are asserted in CI)
def test_period_doubling_branch_switching(nlvib_branch):
    """At the flip of NLvib 03 the period-2 branch is reached by branch switching; it spans
    the flip window and rejoins the period-1 branch at the other flip; at a point inside,
    shooting with n = 2 from a marched state finds the same orbit, and marching from a
    perturbed state lands on it (it is stable)."""
    sysm, br = nlvib_branch
    pd = br.of_kind("period_doubling")
    pd_hi = max(pd, key=lambda b: b.value)
    br2 = aj.continuation(sysm, aj.Harmonic(amplitude=0.1, omega=0.8), "omega",
                          bounds=(0.5, 0.8), start=pd_hi)
    assert br2.period_multiple == 2 and np.all(br2.ok)
    assert br2.termination == "rejoined", br2.termination
    lo = min(b.value for b in pd)
    assert br2.values.min() < lo + 2e-3 and br2.values.max() <= pd_hi.value + 1e-4
    i = int(np.argmin(np.abs(br2.values - 0.746)))
    w = float(br2.values[i])
    f = aj.Harmonic(amplitude=0.1, omega=w)
    # shooting with n = 2 from elsewhere: from the orbit two branch points away (from the
    # linear guess it finds the coexisting non-resonant orbit instead)
    j = i - 2
    assert abs(br2.values[j] - w) > 1e-4
    sh = aj.steady_state(sysm, f, method=aj.Shooting(n=2), guess=br2.states[j])
    ma = aj.steady_state(sysm, f, method="marching",
                         guess=np.asarray(br2.states[i]) * (1 + 1e-3), n_max=4)
    print(f"period-2 branch at Ω = {w:.5f}: |x2| amplitude {br2.amplitude[i]:.6f}, "
          f"shooting n=2 {float(sh.amplitude):.6f}, marching {float(ma.amplitude):.6f} "
          f"(period {int(ma.period_multiple)})")
    for other in (sh, ma):
        assert int(other.status) == 0
        assert abs(float(other.amplitude) - br2.amplitude[i]) < 1e-5 * br2.amplitude[i]
    assert int(ma.period_multiple) == 2 and bool(br2.stable[i]) and bool(sh.stable)


def test_bad_input_is_named():
    system = hardening()
    f = aj.Harmonic(amplitude=0.05, omega=1.0)
    cases = [
        (dict(parameter="nope", bounds=(0.5, 1.5)), "nope"),
        (dict(bounds=(1.5, 0.5)), "bounds"),
        (dict(bounds=(1.2, 1.5)), "inside bounds"),
        (dict(bounds=(-1.0, 1.5)), "omega"),
        (dict(parameter="contact1.gap", bounds=(-1.0, 1.0)), "gap"),
        (dict(bounds=(0.5, 1.5), direction="sideways"), "direction"),
        (dict(bounds=(0.5, 1.5), n=0), "n must"),
        (dict(bounds=(0.5, 1.5), method="newton"), "PseudoArclength"),
        (dict(bounds=(0.5, 1.5), start="fold"), "start"),
    ]
    for kw, text in cases:
        kw = dict(kw)
        p = kw.pop("parameter", "omega")
        with pytest.raises(ValueError, match=text):
            aj.continuation(system, f, p, **kw)
    for kw, text in [(dict(bounds=(0.5, 1.5), starts=0), "starts"),
                     (dict(bounds=(0.5, 1.5), starts=[0.2, 1.0]), "starts must lie inside"),
                     (dict(bounds=(0.5, 1.5), starts="many"), "starts"),
                     (dict(bounds=(0.5, 1.5), fill=-1), "fill"),
                     (dict(bounds=(0.5, 1.5), fill=1.5), "fill"),
                     (dict(bounds=(1.5, 0.5)), "bounds")]:
        with pytest.raises(ValueError, match=text):
            aj.band_continuation(system, f, "omega", **kw)
    with pytest.raises(ValueError, match="min_step <= step"):
        aj.PseudoArclength(step=1.0, max_step=0.1)
    with pytest.raises(ValueError, match="max_points"):
        aj.PseudoArclength(max_points=1)


def test_cli_continue_and_attractors_inside_the_hysteresis(tmp_path, capsys):
    """The CLI on a scene file: `continue` writes the branch (CSV rows = points, JSON with the
    two folds, PNG); `attractors` at ω = 1.15, inside the hysteresis window, finds the two
    stable orbits, whose amplitudes are the stable branch points' there (steady_state from
    the branch, 1e-5)."""
    import json

    from absorber_jax._io.cli import main

    scene = {"structure": {"type": "matrices", "mass": [[1.0]], "stiffness": [[1.0]],
                           "damping": [[HARD["c"]]]},
             "elements": [{"type": "contact", "dof": "x1", "gap": HARD["g"],
                           "contact": {"law": "kelvin_voigt", "stiffness": HARD["k_c"],
                                       "damping": 0.0}}],
             "load": {"dof": "x1", "amplitude": HARD["F0"]}}
    path = tmp_path / "hard.json"
    path.write_text(json.dumps(scene))
    out = tmp_path / "cont"
    assert main(["continue", "--file", str(path), "--bounds", "0.8:1.6", "--out",
                 str(out), "--step", "0.05", "--max-step", "0.2"]) == 0
    summ = json.loads((out / "summary.json").read_text())
    br = summ["branches"][0]
    assert [b["kind"] for b in br["bifurcations"]] == ["fold", "fold"]
    rows = (out / "branch.csv").read_text().strip().splitlines()
    assert len(rows) == br["points"] + 1 and (out / "branches.png").stat().st_size > 0
    lo, hi = sorted(b["value"] for b in br["bifurcations"])
    assert lo < 1.15 < hi
    out2 = tmp_path / "att"
    assert main(["attractors", "--file", str(path), "--omega", "1.15", "--samples", "8",
                 "--max-periods", "800", "--out", str(out2)]) == 0
    maps = json.loads((out2 / "summary.json").read_text())["maps"]
    amps = sorted(a["amplitude"] for a in maps[0]["attractors"] if a["periodic"])
    assert len(amps) == 2 and (out2 / "attractors.png").stat().st_size > 0
    # the same two orbits by shooting, seeded from the stable branch points nearest 1.15
    system = hardening()
    f = aj.Harmonic(amplitude=HARD["F0"], omega=1.15)
    bra = aj.continuation(system, aj.Harmonic(amplitude=HARD["F0"], omega=0.8), "omega",
                          bounds=(0.8, 1.6),
                          method=aj.PseudoArclength(step=0.05, max_step=0.2))
    ref = []
    for part in (bra.values[:bra.of_kind("fold")[0].index + 1],):
        i = int(np.argmin(np.abs(part - 1.15)))
        ref.append(float(aj.steady_state(system, f, guess=bra.states[i]).amplitude))
    k = bra.of_kind("fold")[1].index + 1
    i = k + int(np.argmin(np.abs(bra.values[k:] - 1.15)))
    ref.append(float(aj.steady_state(system, f, guess=bra.states[i]).amplitude))
    np.testing.assert_allclose(amps, sorted(ref), rtol=1e-5)
    assert main(["attractors", "--file", str(path), "--omega", "x", "--out", str(out2)]) == 2


def test_a_harmonic_balance_branch_has_shootings_folds_and_floquet_labels():
    """``continuation(orbit=HarmonicBalance(9))`` on a Duffing oscillator
    (``ẍ + 2ẋ + 10³x + 10⁶x³ = 5 sin ωt``) through both folds: the folds where the shooting
    branch has them (measured 1.3e-11 and 4.8e-10), and along the branch Hill's stability
    labels equal the Floquet labels of shooting at the same orbits (the unstable middle
    branch included)."""

    st = aj.structure_from_matrices([[1.0]], [[1e3]], damping=[[2.0]], dof_names=["x"])
    duffing = aj.StructuralSystem(st, [CubicSpring("x", k3=1e6)], load="x")
    forcing = aj.Harmonic(amplitude=5.0, omega=25.0)
    shoot = aj.continuation(duffing, forcing, "omega", bounds=(25.0, 70.0))
    hb = aj.continuation(duffing, forcing, "omega", bounds=(25.0, 70.0),
                         orbit=aj.HarmonicBalance(harmonics=9, stability="hill"))
    assert hb.termination == "bounds" and np.all(hb.ok)
    folds = sorted(b.value for b in hb.of_kind("fold"))
    ref = sorted(b.value for b in shoot.of_kind("fold"))
    assert len(folds) == len(ref) == 2 and len(hb.bifurcations) == 2
    np.testing.assert_allclose(folds, ref, rtol=1e-5)
    stable = np.asarray(hb.stable)
    assert stable.any() and (~stable).any()
    picks = np.linspace(0, len(hb.values) - 1, 12).astype(int)
    for i in picks:
        ss = aj.steady_state(duffing, forcing.with_omega(float(hb.values[i])),
                             guess=np.asarray(hb.states[i]), method=aj.Shooting(tol=1e-10))
        assert int(ss.status) == 0
        assert bool(ss.stable) == bool(stable[i]), (hb.values[i], ss.multipliers,
                                                    hb.multipliers[i])
        assert abs(float(ss.amplitude) / float(hb.amplitude[i]) - 1) < 1e-6
    with pytest.raises(ValueError, match="period-1 orbits"):
        aj.continuation(duffing, forcing, "omega", bounds=(25.0, 70.0), n=2,
                        orbit=aj.HarmonicBalance())
    # the band covered from three starts by balanced half-branches (their multipliers from
    # the monodromy, the default): no part left, the folds where the shooting branch has
    # them, and the labels as the Hill branch's
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)       # a part not reached warns
        band = aj.band_continuation(duffing, forcing, "omega", bounds=(25.0, 70.0),
                                    starts=3, fill=1,
                                    orbit=aj.HarmonicBalance(harmonics=9))  # monodromy
    assert len(band) == 6 and all(np.all(b.ok) for b in band)
    found = np.array([b.value for br in band for b in br.bifurcations])
    assert {b.kind for br in band for b in br.bifurcations} == {"fold"}
    for f in ref:
        assert np.min(np.abs(found - f)) < 1e-5 * f
    hb_amp = np.asarray(hb.amplitude)
    compared = 0
    for br in band:
        for w, a, st in zip(br.values, np.asarray(br.amplitude), np.asarray(br.stable)):
            if np.min(np.abs(np.asarray(ref) - w)) > 1e-2 * w:       # away from the folds
                # the Hill branch's nearest orbit (in frequency and amplitude: three
                # coexist between the folds)
                i = int(np.argmin(np.abs(hb.values / w - 1) + np.abs(hb_amp / a - 1)))
                if abs(hb.values[i] / w - 1) < 5e-3 and abs(hb_amp[i] / a - 1) < 5e-2:
                    assert st == stable[i], (w, a, hb.values[i], hb_amp[i])
                    compared += 1
    assert compared > 20, compared


def test_a_branch_retracing_two_grazings_in_a_row_is_closed():
    # a branch through the grazings A, B, C, D, B', C' (B' and C' the same orbits as B and
    # C: parameter values and states within LOOP_TOL) has gone round a loop; one that only
    # passes one grazing again (a junction of sheets: A, B, C, B'), or passes two again
    # that are not the same orbits, has not
    from absorber_jax._continuation.branch import Bifurcation
    from absorber_jax._continuation.driver import _passed_before

    def g(value, state, kind="grazing", located=True):
        return Bifurcation(kind=kind, value=value, amplitude=1.0, state=np.asarray(state),
                           multipliers=np.zeros(4), index=0, period_multiple=1,
                           located=located, evaluations=1)

    s = np.array([1.0, 2.0, -1.0, 0.5])
    A, B, C, D = (g(v, s * v) for v in (25.18, 27.20, 27.78, 27.92))
    Bp, Cp = g(27.20 * (1 + 1e-9), B.state + 1e-9), g(27.78, C.state * (1 - 1e-9))
    assert _passed_before([A, B, C, D, Bp, Cp])
    assert not _passed_before([A, B, C, Bp])
    assert not _passed_before([A, B, C, D, Bp, g(27.78, C.state * 1.01)])
    assert not _passed_before([A, B, C, D, Bp, g(27.78 * 1.001, C.state)])
    # folds between the grazings do not matter; unlocated grazings are not compared
    assert _passed_before([A, B, g(26.0, s, kind="fold"), C, D, Bp, Cp])
    assert not _passed_before([A, B, C, D, Bp, g(27.78, C.state, located=False)])


def test_a_branch_back_on_a_part_it_followed_is_retraced():
    # points round a circle in (state, parameter), then on round it again: the first point
    # of the second lap lies on a chord of the first (off it by the circle's sag, 1.7e-2 of
    # its length), going the same way; a point as near going the other way, or off the
    # chord by a tenth of its length, or with another count of impacts than the chord's
    # ends (a chord across a grazing corner joins two sheets), does not retrace it
    from types import SimpleNamespace

    from absorber_jax._continuation.driver import _retraced

    def point(theta, impacts=3, off=0.0):
        r = 1.0 + off
        ss = SimpleNamespace(impacts=float(impacts), period_multiple=1)
        return dict(x0=np.array([r * np.cos(theta), 0.5]), z=np.array([0.0, r * np.sin(theta)]),
                    ss=ss)

    s = np.ones(2)
    lap = [point(th) for th in np.linspace(0.0, 2 * np.pi, 40, endpoint=False)]
    d = 2 * np.pi / 40
    again = [point(2 * np.pi + 0.3 * d), point(2 * np.pi + 1.3 * d)]
    assert _retraced(lap + again, s, 0.35)
    assert not _retraced(lap, s, 0.35)                       # a smooth curve: never
    assert not _retraced(lap[:4], s, 0.35)
    back = [point(1.7 * d), point(1.3 * d)]                  # the same place, the other way
    assert not _retraced(lap + back, s, 0.35)
    aside = [point(2 * np.pi + 0.3 * d), point(2 * np.pi + 1.3 * d, off=0.1 * d)]
    assert not _retraced(lap + aside, s, 0.35)
    other = [point(2 * np.pi + 0.3 * d, 4), point(2 * np.pi + 1.3 * d, 4)]
    assert not _retraced(lap + other, s, 0.35)
    # ... nor does it where one end of the chord has another count (a grazing corner)
    for k in (1, 2):                                    # either end of the chord
        corner = lap[:k] + [point(k * d, 4)] + lap[k + 1:]
        assert not _retraced(corner + again, s, 0.35)
    # the count kept in a point (``_Driver.point``) is the one compared
    kept = [dict(q, impacts=3, ss=SimpleNamespace(impacts=4.0, period_multiple=1))
            for q in lap + again]
    assert _retraced(kept, s, 0.35)
    kept[-1]["impacts"] = 4
    assert not _retraced(kept, s, 0.35)
    # a branch going on straight ahead never lies inside one of its earlier chords
    line = [dict(point(0.0), x0=np.array([0.1 * k, 0.5]), z=np.array([0.0, 0.02 * k]))
            for k in range(30)]
    assert not _retraced(line, s, 0.35)
    # a chord across a jump of the state at t = 0 (an impact crossing t = 0: 13 times as
    # long as its neighbours) is no piece of the branch: a point near it, going its way,
    # does not retrace the branch
    jump = [dict(q, x0=q["x0"] + np.array([0.0, 2.0 * (k >= 10)])) for k, q in enumerate(lap)]
    assert not _retraced(jump, s, 0.35)
    p9, p10 = (np.append(jump[k]["x0"], jump[k]["z"][-1]) for k in (9, 10))
    near = [dict(point(0.0), x0=(p9 + f * (p10 - p9))[:2] + [0.0, 0.01],
                 z=np.array([0.0, (p9 + f * (p10 - p9))[2]])) for f in (0.3, 0.5)]
    assert not _retraced(jump + near, s, 0.35)
