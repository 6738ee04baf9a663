"""Energy balance: work of the force = change of mechanical energy + dissipated energy.

The work and the dissipation are integrated alongside the state from the laws' own power
expressions; the mechanical energy is evaluated from the state with the exact (nonsmooth)
contact potential.  A wrong force sign or a missing term in the vector field breaks it."""

import numpy as np
import pytest

import absorber_jax as aj

CASES = [
    ("kelvin_voigt", dict(eps=1e-8)),
    ("hertz", dict(eps=1e-8)),
    ("hunt_crossley", dict(eps=1e-8)),
    ("coulomb", dict()),
    ("dahl", dict()),
    ("lugre_physical", dict()),
]


@pytest.mark.parametrize("name, kw", CASES)
def test_energy_balance(name, kw):
    system, forcing = aj.presets.scene(name, **kw)
    t1 = 1.0 if name in aj.presets.IMPACT_SCENES else 3.0
    tr = aj.simulate(system, forcing, t1, rtol=1e-10, atol=1e-13, energy=True)
    E = np.asarray(tr.mechanical_energy())
    W = np.asarray(tr.work)
    D = np.asarray(tr.dissipated)
    residual = W - D - (E - E[0])
    scale = np.max(np.abs(W))
    assert scale > 1e-3  # the force does real work
    assert np.all(D[1:] >= -1e-12 * scale) and np.all(np.diff(D) >= -1e-9 * scale)
    assert np.max(np.abs(residual)) < 1e-6 * scale, np.max(np.abs(residual)) / scale
    assert D[-1] > 0.01 * scale  # the absorber (and damping) dissipate
