"""Linear structures: matrix and modal models, tuned mass dampers, the
shear building and the cantilever beam, against closed forms written here independently."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from builders import MASSES, RAYLEIGH, STOREYS, TMDS

import absorber_jax as aj

cantilever_beam, shear_building = aj.cantilever_beam, aj.shear_building
structure_from_matrices, structure_from_modes = aj.structure_from_matrices, aj.structure_from_modes

OMEGAS = np.linspace(5.0, 120.0, 400)


def _reference_receptance(omega):
    """The building's receptance with the dampers condensed into frequency-dependent
    stiffnesses at their floors: a damper (m, k, c) on a floor moving as X e^{iωt} pushes
    back with -ω² m (k + iωc) / (k + iωc - ω² m) X (its own mass's equation eliminated)."""
    m, k = np.array(MASSES), np.array(STOREYS)
    K = np.array([[k[0] + k[1], -k[1], 0.0], [-k[1], k[1] + k[2], -k[2]], [0.0, -k[2], k[2]]])
    M = np.diag(m)
    C = RAYLEIGH[0] * M + RAYLEIGH[1] * K
    out = []
    for w in omega:
        D = K - w**2 * M + 1j * w * C
        for dof, mt, kt, ct in TMDS:
            j = int(dof[-1]) - 1
            z = kt + 1j * w * ct
            D[j, j] += -(w**2) * mt * z / (z - w**2 * mt)
        out.append(np.linalg.inv(D))
    return np.array(out)


def _building():
    return shear_building(MASSES, STOREYS, rayleigh=RAYLEIGH)


def test_building_with_three_dampers_matches_the_condensed_closed_form():
    s = _building().with_tuned_mass_dampers(TMDS)
    assert s.dof_names[3:] == ("tmd1", "tmd2", "tmd3")
    H = np.asarray(s.receptance(OMEGAS))[:, :3, :3]
    Href = _reference_receptance(OMEGAS)
    err = np.max(np.abs(H - Href)) / np.max(np.abs(Href))
    print("building + 3 TMDs: max receptance error", err)
    assert err < 1e-6
    # the dampers do something: the top floor's peak falls well below the bare building's
    bare = np.abs(np.asarray(_building().receptance(OMEGAS))[:, 2, 2]).max()
    assert np.abs(H[:, 2, 2]).max() < 0.5 * bare


def test_modal_model_equals_the_matrix_model():
    s = _building()
    Hm = np.asarray(s.receptance(OMEGAS))
    Hq = np.asarray(s.modal().receptance(OMEGAS))
    assert np.max(np.abs(Hq - Hm)) / np.max(np.abs(Hm)) < 1e-8
    # dampers added to the modal model act through the mode shapes at their floors
    Ht = np.asarray(s.with_tuned_mass_dampers(TMDS).receptance(OMEGAS))
    Hqt = np.asarray(s.modal().with_tuned_mass_dampers(TMDS).receptance(OMEGAS))
    assert np.max(np.abs(Hqt - Ht)) / np.max(np.abs(Ht)) < 1e-8
    # a modal model given by its data reproduces the same structure
    sm = s.modal()
    w = np.sqrt(np.diag(np.asarray(sm.stiffness)))
    zeta = np.diag(np.asarray(sm.damping)) / (2 * w)
    again = structure_from_modes(w, zeta, np.asarray(sm.dof_map), dof_names=s.dof_names)
    assert np.max(np.abs(np.asarray(again.receptance(OMEGAS)) - Hm)) / np.abs(Hm).max() < 1e-8


def test_modal_damping_ratios_are_what_was_asked():
    zeta = np.array([0.02, 0.05, 0.01])
    s = shear_building(MASSES, STOREYS, modal_damping=zeta)
    sm = s.modal()
    w = np.sqrt(np.diag(np.asarray(sm.stiffness)))
    np.testing.assert_allclose(np.diag(np.asarray(sm.damping)) / (2 * w), zeta, rtol=1e-10)
    np.testing.assert_allclose(w, np.asarray(s.natural_frequencies()), rtol=1e-12)
    # half-power check on the first mode's resonance of the modal model: |H| peaks at
    # ~ω1 sqrt(1 - 2ζ²) with magnitude close to the single-mode value 1/(2ζ ω1²) φφ
    phi = np.asarray(sm.dof_map)[:, 0]
    om = np.linspace(0.9 * w[0], 1.1 * w[0], 4001)
    H33 = np.abs(np.asarray(s.receptance(om))[:, 2, 2])
    single = phi[2] ** 2 / (2 * zeta[0] * w[0] ** 2)
    assert abs(H33.max() / single - 1) < 0.05


def test_truncated_modal_model_converges_to_the_full_one():
    b = cantilever_beam(8, length=1.0, EI=2.0, rho_A=3.0, modal_damping=0.02)
    tip = b.dof_index("w8")
    w1 = float(b.natural_frequencies()[0])
    om = np.linspace(0.5 * w1, 1.5 * w1, 101)
    full = np.asarray(b.receptance(om))[:, tip, tip]
    errs = [np.max(np.abs(np.asarray(b.modal(n, dofs=["w8"]).receptance(om))[:, 0, 0] - full))
            / np.abs(full).max() for n in (1, 2, 4)]
    print("modal truncation errors near mode 1 (1, 2, 4 modes):", errs)
    assert errs[0] > errs[1] > errs[2] and errs[2] < 1e-3


BETA_L = np.array([1.8751040687, 4.6940911330, 7.8547574382])  # cos βL cosh βL = -1


def test_cantilever_beam_frequencies_converge_at_the_hermite_rate():
    EI, rho_A, L = 2.0, 3.0, 1.0
    exact = BETA_L**2 * np.sqrt(EI / (rho_A * L**4))
    errs = []
    for n in (8, 16):
        w = np.asarray(cantilever_beam(n, length=L, EI=EI, rho_A=rho_A).natural_frequencies())
        errs.append(np.abs(w[:3] - exact) / exact)
    rate = np.log2(errs[0] / errs[1])
    print("beam frequency errors (8 el.)", errs[0], "rates", rate)
    assert np.all(errs[0] < [1e-5, 3e-4, 3e-3])
    assert np.all((rate > 3.6) & (rate < 4.4))       # h^4 for cubic Hermite elements


def test_cantilever_static_tip_compliance_is_exact():
    EI, L = 2.0, 1.5
    b = cantilever_beam(8, length=L, EI=EI, rho_A=3.0)
    H = np.asarray(b.receptance(0.0)).real
    w, th = b.dof_index("w8"), b.dof_index("th8")
    assert abs(H[w, w] * 3 * EI / L**3 - 1) < 1e-9      # P L³ / 3EI
    assert abs(H[th, w] * 2 * EI / L**2 - 1) < 1e-9     # P L² / 2EI (Maxwell: = H[w, th])
    assert abs(H[w, th] / H[th, w] - 1) < 1e-9


def test_receptance_gradient_wrt_a_damper_matches_central_differences():
    dof, mt, k0, ct = TMDS[0]

    def peak(kt):
        d = [(dof, mt, kt, ct)]
        H = _building().with_tuned_mass_dampers(d).receptance(jnp.linspace(20.0, 40.0, 64))
        return jnp.sum(jnp.abs(H[:, 2, 2]) ** 2)

    g = float(jax.grad(peak)(k0))
    h = 1e-5 * k0
    fd = (float(peak(k0 + h)) - float(peak(k0 - h))) / (2 * h)
    assert abs(g - fd) <= 1e-5 * abs(fd)


@pytest.mark.parametrize("build, field", [
    (lambda: structure_from_matrices([[1.0, 0.2], [0.0, 1.0]], np.eye(2)), "mass"),
    (lambda: structure_from_matrices(np.eye(2), [[1.0, 0.0], [0.0, -1.0]]), "stiffness"),
    (lambda: structure_from_matrices(np.eye(2), np.eye(2), rayleigh=(0.1, 0.0),
                                     modal_damping=0.02), "at most one"),
    (lambda: structure_from_matrices(np.eye(2), np.eye(2), modal_damping=[0.1]),
     "modal_damping"),
    (lambda: shear_building([1.0, 1.0], [1.0, -1.0]), "storey_stiffnesses"),
    (lambda: structure_from_modes([1.0, -2.0], 0.01, np.eye(2)), "frequencies"),
    (lambda: structure_from_modes([1.0, 2.0], 0.01, np.eye(3)), "mode_shapes"),
    (lambda: _building().with_tuned_mass_dampers([("roof", 1.0, 1.0, 0.0)]), "dof"),
    (lambda: _building().with_tuned_mass_dampers([("floor1", 0.0, 1.0, 0.0)]), "mass"),
    (lambda: cantilever_beam(0, length=1.0, EI=1.0, rho_A=1.0), "n_elements"),
    (lambda: _building().modal(4), "n_modes"),
])
def test_bad_structures_raise_naming_the_field(build, field):
    with pytest.raises(ValueError, match=field):
        build()
