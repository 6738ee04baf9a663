"""Stiff and extreme cases: each returns finite states, amplitudes and gradients, or a clearly
flagged failure; never a silent NaN, never a hang (every loop is bounded)."""

import equinox as eqx
import numpy as np
import pytest

import absorber_jax as aj


def impact(law=None, **kw):
    base = dict(M=1.0, k=1e3, c=0.1, m=0.4, gap=1e-3,
                contact=law or aj.KelvinVoigt(stiffness=400.0, damping=20.0, adhesive=True))
    base.update(kw)
    return aj.ImpactAbsorber(**base)


def friction(law, N=2.0):
    return aj.FrictionAbsorber(m1=1.0, k1=1e4, c1=2.0, m2=1.0, k2=1e4, c2=0.0, normal_force=N,
                               friction=law)


HC = lambda e: aj.HuntCrossley(stiffness=3260.0, damping=aj.hunt_crossley_damping(3260.0, e, 0.1),
                               adhesive=True)

def lugre(sigma0):
    return aj.LuGre(mu_c=0.5, mu_s=0.6, v_s=1e-2, sigma0=sigma0, sigma1=1e2, sigma2=0.0)


# LuGre with sigma0 = 1e8 (a lightly damped 1e4 rad/s bristle mode, sliding rate 1e7 1/s,
# ~145k Tsit5 steps per period): with |v| exact (the default) shooting from the linear guess
# converges in 7 Newton steps (2.4501 mm, stable, ~22 s with compilation on 2 cores) and
# marching from rest settles on the same orbit (scripts/study_lugre_stiff_bristles.py).  The
# bristle force stays within mu_s N and the orbit closes under an independent integration
# (_check_stiff_bristle_orbit).
CASES = {
    "lugre_sigma0_1e6": (friction(lugre(1e6)), 10.0, 50.0, "N"),
    "lugre_sigma0_1e8": (friction(lugre(1e8)), 10.0, 50.0, None),
    "hertz_steel_1e10": (impact(aj.Hertz(stiffness=1e10, damping=20.0,
                                         adhesive=True)), 2.0, 47.4, None),
    "eps_1e-9": (impact(aj.KelvinVoigt(stiffness=400.0, damping=20.0, eps=1e-9,
                                       adhesive=True)), 2.0, 47.4,
                 None),
    "force_1e4": (impact(), 1e4, 47.4, None),
    "absorber_mass_1e-6": (impact(m=1e-6), 2.0, 47.4, None),
    "zero_gap": (impact(gap=0.0), 2.0, 47.4, "k1"),
    "normal_force_0": (friction(aj.Coulomb(mu=0.5), N=0.0), 10.0, 50.0, None),
    "normal_force_stuck_1e6": (friction(aj.Coulomb(mu=0.5), N=1e6), 10.0, 50.0, None),
    "stribeck_vs_1e-8": (friction(aj.Stribeck(mu_c=0.5, mu_s=0.6, v_s=1e-8)), 10.0, 50.0, None),
    "hunt_crossley_e_0.01": (impact(HC(0.01)), 2.0, 47.4, None),
    "hunt_crossley_e_0.999": (impact(HC(0.999)), 2.0, 47.4, "c1"),
    "omega_0.5": (impact(), 2.0, 0.5, None),
    "omega_1e4": (impact(), 2.0, 1e4, None),
}

# steady-state outcomes that are flags by design; None: either success or a flag is fine
# (omega = 0.5 rad/s: shooting over a 12.6 s period of a lightly damped 31.6 rad/s mode)
FLAGGED_STEADY = {"omega_0.5": None}


def _finite_or_flagged(status, *values):
    if int(status) == 0:
        for v in values:
            assert np.all(np.isfinite(np.asarray(v))), "status 0 but non-finite values"
        return "ok"
    return aj.describe(status)


def _check_stiff_bristle_orbit(system, forcing, ss):
    """The steady state of the stiff-bristle case is physical and periodic: the bristle force
    never exceeds the static level mu_s N (with the smoothed |v| at eps = 1e-4 the model has a
    fully stuck orbit holding 5 N against 1.2 N), the absorber slips, and an independent
    integration (simulate, tighter tolerances) from the state returns to it after a period."""
    assert int(ss.status) == 0 and bool(ss.stable), aj.describe(ss.status)
    law, N, T = system.friction, float(system.normal_force), forcing.period
    tr = aj.simulate(system, forcing, T, y0=ss.state, ts=np.linspace(0.0, T, 401), rtol=1e-10,
                     atol=1e-14, max_steps=2_000_000)
    ys = np.asarray(tr.ys)
    bristle = float(law.sigma0) * np.abs(ys[:, 4])
    assert bristle.max() <= float(law.mu_s) * N * (1 + 1e-6), bristle.max()
    assert np.abs(ys[:, 3] - ys[:, 1]).max() > 1e-2  # it slips: not a stuck artefact
    scale = np.abs(ys).max(axis=0)
    np.testing.assert_allclose(ys[-1] / scale, ys[0] / scale, atol=1e-5)


# further checks of a case's steady state, beyond "finite or flagged"
STEADY_CHECKS = {"lugre_sigma0_1e8": _check_stiff_bristle_orbit}


# CI time: cases whose physics other tests also cover (N = 0: test_steady's zero-normal-force
# FRF against the closed form; N = 1e6, stuck: test_stickslip's stuck orbit against exp(AT);
# LuGre gradients: test_design; omega = 0.5 accepts a flag either way) run with -m slow
SLOW_CASES = ("absorber_mass_1e-6", "normal_force_0", "normal_force_stuck_1e6",
              "lugre_sigma0_1e6", "omega_0.5")


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in SLOW_CASES
                                  else n for n in CASES])
def test_extreme_case(name):
    system, F0, omega, grad_param = CASES[name]
    forcing = aj.Harmonic(amplitude=F0, omega=omega)
    T = 2 * np.pi / omega
    tr = aj.simulate(system, forcing, 3 * T, throw=False, max_steps=300_000)
    sim = _finite_or_flagged(tr.status, tr.ys)
    out = dict(solver=tr.solver, simulate=sim)
    if grad_param is None:
        ss = aj.steady_state(system, forcing, max_steps=300_000)
        out["steady"] = _finite_or_flagged(ss.status, ss.amplitude, ss.state)
        amp = float(ss.amplitude)
        if name in STEADY_CHECKS:
            STEADY_CHECKS[name](system, forcing, ss)
    else:
        # value_and_grad solves the same steady state (shooting) and differentiates it; the
        # separate steady_state call is skipped here to keep CI short (LuGre 1e6: ~1 min)
        amp, g, status = aj.value_and_grad(system, [grad_param], [omega], amplitude=F0,
                                           objective="amplitude")
        out["steady"] = out["gradient"] = _finite_or_flagged(status[0], amp, list(g.values()))
    out["amplitude_mm"] = amp * 1e3 if out["steady"] == "ok" else None
    print(name, out)
    # most extreme cases must actually be solved, not merely flagged
    if name != "omega_0.5":
        assert sim == "ok", (name, sim)
    expected = FLAGGED_STEADY.get(name, "ok")
    if expected is not None:
        assert out["steady"] == expected, (name, out["steady"])
    for v in out.values():
        assert v != aj.describe(aj.Status.NONFINITE), (name, out)


# The automatic choice against both solvers' step counts over eight forcing periods: it must pick
# Kvaerno5 only where Tsit5 needs an order of magnitude more steps (or fails), and Tsit5 where
# it does not.  (Kvaerno5 costs ~10x Tsit5 per step here, ~100x inside shooting.)  Not here:
# the 1e-6 kg absorber, where Kvaerno5 is chosen for shooting's sake (Tsit5 takes fewer steps
# from rest, but its shooting reports NO_CONVERGENCE; Kvaerno5 finds 1.6041 mm in 4.7 s).
def _case(name):
    system, F0, omega, _ = CASES[name]
    return system, aj.Harmonic(amplitude=F0, omega=omega)


def _coulomb_scene_eps_1e_6():  # the paper's Coulomb scene, much sticking
    system, forcing = aj.presets.friction("coulomb")
    return eqx.tree_at(lambda s: s.friction.eps, system, 1e-6), forcing


AUTO_CASES = {
    "lugre_sigma0_1e6": lambda: _case("lugre_sigma0_1e6"),
    "lugre_sigma0_1e8": lambda: _case("lugre_sigma0_1e8"),
    "coulomb_scene_eps_1e-6": _coulomb_scene_eps_1e_6,
    "kelvin_voigt_table1": lambda: (impact(), aj.Harmonic(amplitude=2.0, omega=47.4)),
    "normal_force_stuck_1e6": lambda: _case("normal_force_stuck_1e6"),
}


@pytest.mark.parametrize("name", list(AUTO_CASES))
def test_automatic_solver_choice_follows_step_counts(name):
    system, forcing = AUTO_CASES[name]()
    steps = {}
    for solver in ("tsit5", "kvaerno5"):
        tr = aj.simulate(system, forcing, 8 * forcing.period, solver=solver, throw=False,
                         max_steps=100_000)
        steps[solver] = int(tr.num_steps) if int(tr.status) == 0 else np.inf
    assert np.isfinite(steps["kvaerno5"]), name
    ratio = steps["tsit5"] / steps["kvaerno5"]
    auto = aj.choose_solver(system, forcing)
    print(name, auto, steps, ratio)
    if auto == "kvaerno5":
        assert ratio > 10, (name, steps)
    else:
        assert ratio < 3, (name, steps)
