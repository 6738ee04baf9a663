"""Finite-element-size structures: sparse beam matrices, matrices from files and the
Craig–Bampton reduction, against Euler–Bernoulli beam theory (static deflection, natural
frequencies) and against the unreduced model (receptances, a harmonic-balance orbit)."""

import numpy as np
import pytest
import scipy.io
import scipy.sparse as sp

import absorber_jax as aj

L, EI, RHO_A = 1.0, 100.0, 1.0
# clamped-free Euler–Bernoulli beam: ω_r = (β_r L)² sqrt(EI / (ρA L⁴))
BETA_L = np.array([1.8751040687119611, 4.6940911329741745, 7.8547574382376126])


def test_beam_matrices_give_the_static_deflection_and_frequencies_of_beam_theory():
    M, K, names = aj.beam_matrices(200, length=L, EI=EI, rho_A=RHO_A)
    assert sp.issparse(M) and M.shape == (400, 400) and names[-2] == "w200"
    # a tip load P: w(x) = P x² (3L - x) / (6 EI), exact for cubic Hermite elements (the
    # unequilibrated sparse solve itself loses ~1e-8 to the mesh's conditioning)
    f = np.zeros(400)
    f[names.index("w200")] = 1.0
    w = sp.linalg.spsolve(K.tocsc(), f)
    x = np.array([0.25, 0.5, 1.0])
    exact = x**2 * (3 * L - x) / (6 * EI)
    got = [w[names.index(f"w{int(round(xi * 200))}")] for xi in x]
    np.testing.assert_allclose(got, exact, rtol=1e-7)
    # the Craig–Bampton model (tip kept, 24 fixed-interface modes): the three lowest free
    # frequencies of beam theory (measured 4e-9, 4e-8, 3e-7; with 6 modes 7e-7, 3e-5, 2e-4)
    cb = aj.craig_bampton(M, K, ["w200"], 24, dof_names=names)
    omega = np.asarray(cb.natural_frequencies())[:3]
    np.testing.assert_allclose(omega, BETA_L**2 * np.sqrt(EI / (RHO_A * L**4)), rtol=1e-6)


def test_craig_bampton_is_exact_statically_and_converges_with_its_modes():
    n = 50
    M, K, names = aj.beam_matrices(n, length=L, EI=EI, rho_A=RHO_A)
    full = aj.structure_from_matrices(M, K, rayleigh=(0.0, 1e-4), dof_names=names)
    i, j = names.index(f"w{n}"), names.index("w25")
    errors = []
    for m in (0, 2, 5, 10, 20):
        cb = aj.craig_bampton(M, K, [f"w{n}"], m, rayleigh=(0.0, 1e-4), dof_names=names,
                              observe=["w25"])
        assert cb.dof_names == (f"w{n}", "w25") and cb.num_coords == 1 + m
        H0, Hf0 = np.asarray(cb.receptance(0.0)), np.asarray(full.receptance(0.0))
        # static: the boundary is exact (the interior's static response is kept whole)
        assert abs(H0[0, 0] / Hf0[i, i] - 1) < 1e-8
        assert abs(H0[1, 0] / Hf0[j, i] - 1) < 1e-8
        # between the second and third modes (≈ 62 and 176 rad/s)
        H, Hf = np.asarray(cb.receptance(100.0)), np.asarray(full.receptance(100.0))
        errors.append(abs(H[0, 0] / Hf[i, i] - 1))
    # each added batch of modes lowers the error (measured: 0.34, 2.2e-3, 2.1e-5, 1e-6, 4e-8)
    assert all(b < 0.2 * a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 1e-6


def test_a_harmonic_balance_orbit_on_the_reduced_beam_equals_the_full_ones():
    """A 40-element beam (80 DOFs) with a smoothed friction contact at its tip, forced at
    its tip near the first mode: the condensed balance of the full model against that of
    its Craig–Bampton models."""
    n = 40
    M, K, names = aj.beam_matrices(n, length=L, EI=EI, rho_A=RHO_A)
    tip = f"w{n}"
    damper = aj.FrictionContact(tip, normal_force=1.0, friction=aj.Coulomb(mu=0.3, eps=1e-2))
    forcing = aj.Harmonic(amplitude=2.0, omega=3.3 * np.sqrt(EI))
    hb = aj.HarmonicBalance(harmonics=7, tol=1e-12)
    full = aj.structure_from_matrices(M, K, rayleigh=(1.0, 1e-4), dof_names=names)
    ref = aj.steady_state(aj.StructuralSystem(full, [damper], load=tip), forcing, method=hb,
                          floquet=False)
    assert int(ref.status) == 0
    errors = []
    for m in (2, 8, 20):
        cb = aj.craig_bampton(M, K, [tip], m, rayleigh=(1.0, 1e-4), dof_names=names)
        ss = aj.steady_state(aj.StructuralSystem(cb, [damper], load=tip), forcing, method=hb,
                             floquet=False)
        assert int(ss.status) == 0
        errors.append(abs(complex(ss.harmonic) / complex(ref.harmonic) - 1))
    # measured: 6.8e-4, 2.4e-6, 3.1e-8
    assert all(b < 0.1 * a for a, b in zip(errors, errors[1:])) and errors[-1] < 1e-6, errors


def test_matrices_are_read_from_matrix_market_and_numpy_files(tmp_path):
    M, K, names = aj.beam_matrices(3, length=L, EI=EI, rho_A=RHO_A)
    scipy.io.mmwrite(tmp_path / "k.mtx", K, symmetry="symmetric")
    sp.save_npz(tmp_path / "m.npz", M.tocsr())
    np.save(tmp_path / "m.npy", M.toarray())
    np.savez(tmp_path / "k_dense.npz", K=K.toarray())
    Kr, Mr = aj.read_matrix(tmp_path / "k.mtx"), aj.read_matrix(tmp_path / "m.npz")
    assert sp.issparse(Kr) and sp.issparse(Mr)
    np.testing.assert_array_equal(Kr.toarray(), K.toarray())
    np.testing.assert_array_equal(aj.read_matrix(tmp_path / "m.npy"), M.toarray())
    np.testing.assert_array_equal(aj.read_matrix(tmp_path / "k_dense.npz"), K.toarray())
    st = aj.structure_from_matrices(Mr, Kr, dof_names=names)
    ref = aj.cantilever_beam(3, length=L, EI=EI, rho_A=RHO_A)
    np.testing.assert_allclose(np.asarray(st.natural_frequencies()),
                               np.asarray(ref.natural_frequencies()), rtol=1e-12)


def test_bad_matrices_and_reductions_are_refused(tmp_path):
    with pytest.raises(ValueError, match="read_matrix.path: no such file"):
        aj.read_matrix(tmp_path / "missing.mtx")
    (tmp_path / "m.txt").write_text("1")
    with pytest.raises(ValueError, match="unknown format"):
        aj.read_matrix(tmp_path / "m.txt")
    big = sp.identity(5000, format="csr")
    with pytest.raises(ValueError, match="too large.*craig_bampton"):
        aj.structure_from_matrices(big, big)
    M, K, names = aj.beam_matrices(4, length=L, EI=EI, rho_A=RHO_A)
    with pytest.raises(ValueError, match="craig_bampton.n_modes"):
        aj.craig_bampton(M, K, ["w4"], 7, dof_names=names)
    with pytest.raises(ValueError, match="craig_bampton.boundary"):
        aj.craig_bampton(M, K, [], 2)
    with pytest.raises(ValueError, match="unknown degree of freedom 'tip'"):
        aj.craig_bampton(M, K, ["tip"], 2, dof_names=names)
    with pytest.raises(ValueError, match="craig_bampton.stiffness must be symmetric"):
        aj.craig_bampton(M, K + sp.csr_matrix(([1.0], ([0], [1])), shape=K.shape), [0], 2)
    with pytest.raises(ValueError, match="interior .* singular"):
        aj.craig_bampton(sp.identity(3), sp.csr_matrix((3, 3)), [0], 1)
