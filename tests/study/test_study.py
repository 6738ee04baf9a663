"""Design studies: persistence, resumption, Dask workers (one lost mid-study), Monte Carlo
against the closed-form peak of a tuned mass damper, bad input."""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from study_scene import (
    CT,
    F0,
    GRID,
    KT,
    OMEGAS,
    QUESTION,
    Counting,
    closed_form_peak,
    log_lines,
    log_values,
    receptance,
    tmd_system,
    tree_digest,
)

import absorber_jax as aj

xr = pytest.importorskip("xarray")


def test_grid_study_is_labelled_and_equals_the_closed_form_response(tmp_path):
    res = aj.study(tmd_system(), GRID, QUESTION, store=tmp_path / "s.zarr", chunk=4)
    d = res.data
    assert d["amplitude"].dims == ("tmd1.k", "tmd1.c", "omega")
    assert d["amplitude"].attrs["units"] == "m" and d["tmd1.k"].attrs["units"] == "N/m"
    assert d.attrs["system"] == "StructuralSystem" and res.failures() == 0
    assert sorted(res.computed) == [0, 1, 2] and res.reused == 0
    kt, ct = np.meshgrid(d["tmd1.k"], d["tmd1.c"], indexing="ij")
    exact = F0 * receptance(OMEGAS[None, None, :], kt[..., None], ct[..., None])
    err = np.max(np.abs(d["amplitude"].values - exact) / exact)
    assert err < 1e-7, err
    # the same study in memory, and read back from the store by a rerun: the same numbers
    again = aj.study(tmd_system(), GRID, QUESTION, store=tmp_path / "s.zarr", chunk=4)
    assert again.computed == () and again.reused == 3
    mem = aj.study(tmd_system(), GRID, QUESTION, chunk=4)
    for k in ("amplitude", "dof_amplitude", "peak", "spectral_radius"):
        np.testing.assert_array_equal(again.data[k].values, d[k].values)
        np.testing.assert_allclose(mem.data[k].values, d[k].values, rtol=1e-12)


def test_interrupted_study_resumes_computing_each_chunk_once(tmp_path):
    store, log = tmp_path / "s.zarr", str(tmp_path / "log.txt")
    pathlib.Path(log + ".stop").write_text("2")
    with pytest.raises(KeyboardInterrupt):
        aj.study(tmd_system(), GRID, Counting(QUESTION, log), store=store, chunk=2)
    assert len(log_lines(log)) == 2
    pathlib.Path(log + ".stop").unlink()
    # the rerun computes only the chunks missing: the interrupted one included
    res = aj.study(tmd_system(), GRID, Counting(QUESTION, log), store=store, chunk=2)
    lines = log_lines(log)
    assert res.reused == 1 and len(res.computed) == 5
    # every chunk written exactly once; the interrupted chunk was computed, not written,
    # then computed again: 6 chunks, 7 computations, one of them repeated
    assert len(lines) == 7 and len(set(log_values(log))) == 6
    ref = aj.study(tmd_system(), GRID, QUESTION, chunk=2)
    for k in ("amplitude", "status", "peak"):
        np.testing.assert_allclose(res.data[k].values, ref.data[k].values, rtol=1e-12)


def test_monte_carlo_peak_distribution_matches_the_closed_form():
    designs = aj.MonteCarlo(12, {"tmd1.k": aj.Uniform(0.95, 1.05, relative=True),
                                 "tmd1.c": aj.Uniform(0.95, 1.05, relative=True)}, seed=3)
    res = aj.study(tmd_system(), designs,
                   aj.questions.ExactPeak((80.0, 120.0), amplitude=F0), chunk=4)
    d = res.data
    assert d["peak"].dims == ("sample",) and d.sizes["sample"] == 12
    kt, ct = d["tmd1.k"].values, d["tmd1.c"].values
    assert np.all(np.abs(kt / KT - 1) <= 0.05) and np.all(np.abs(ct / CT - 1) <= 0.05)
    assert np.ptp(kt) > 0.05 * KT                      # the samples spread over the range
    ref = np.array([closed_form_peak(a, b) for a, b in zip(kt, ct)])
    err = np.max(np.abs(d["peak"].values - ref) / ref)
    assert bool(d["located"].all()) and err < 1e-8, err
    # the same samples again from the same seed; Latin hypercube: one sample per stratum
    np.testing.assert_array_equal(designs.table(tmd_system())["tmd1.k"], kt)
    lhs = aj.LatinHypercube(10, {"tmd1.k": aj.Uniform(0.0, 1.0)}, seed=1).table(tmd_system())
    assert sorted(np.floor(lhs["tmd1.k"] * 10).astype(int)) == list(range(10))


def test_bad_input_is_refused_before_computing_and_leaves_the_store(tmp_path):
    store = tmp_path / "s.zarr"
    small = aj.Grid({"tmd1.k": [KT, 1.1 * KT]})
    aj.study(tmd_system(), small, QUESTION, store=store)
    digest = tree_digest(store)
    with pytest.raises(ValueError, match="unknown parameter 'k9'"):
        aj.study(tmd_system(), aj.Grid(k9=[1.0, 2.0]), QUESTION, store=store)
    with pytest.raises(ValueError, match="non-empty"):
        aj.Grid({"tmd1.k": []})
    with pytest.raises(ValueError, match="another study"):
        aj.study(tmd_system(), aj.Grid({"tmd1.k": [KT, 1.2 * KT]}), QUESTION, store=store)
    with pytest.raises(ValueError, match="another study"):
        aj.study(tmd_system(ct=2 * CT), small, QUESTION, store=store)
    with pytest.raises(ValueError, match="tmd1.k"):
        aj.study(tmd_system(), aj.Grid({"tmd1.k": [-1.0, KT]}), QUESTION, store=tmp_path / "t")
    with pytest.raises(ValueError, match="Uniform"):
        aj.Uniform(1.0, 0.5)
    assert tree_digest(store) == digest
    assert not (tmp_path / "t").exists()


def test_the_store_opens_as_zarr_elsewhere(tmp_path):
    # the store is Zarr version 2: xarray with the zarr package reads the same dataset
    # (in a process of its own, which needs no JAX)
    import importlib.util

    if importlib.util.find_spec("zarr") is None:
        pytest.skip("zarr is not installed")
    res = aj.study(tmd_system(), GRID, QUESTION, store=tmp_path / "s.zarr", chunk=4)
    code = ("import sys, xarray as xr\n"
            "ds = xr.open_zarr(sys.argv[1], consolidated=False).load()\n"
            "import numpy as np\n"
            "np.savez(sys.argv[2], amplitude=ds['amplitude'].values, k=ds['tmd1.k'].values)\n"
            "print(int(ds['chunk_done'].sum()), ds['amplitude'].attrs['units'])\n")
    run = subprocess.run([sys.executable, "-c", code, str(tmp_path / "s.zarr"),
                          str(tmp_path / "s.npz")], capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == ["3", "m"]
    other = np.load(tmp_path / "s.npz")
    flat = res.data.stack(design=("tmd1.k", "tmd1.c"))
    np.testing.assert_array_equal(other["amplitude"],
                                  flat["amplitude"].transpose("design", "omega").values)
    np.testing.assert_array_equal(other["k"], flat["tmd1.k"].values)


def _dask(out):
    """tests/study/dask_study.py in a process of its own (Dask's threads and worker
    processes kept out of the test process); returns its JSON report."""
    pytest.importorskip("distributed")
    here = pathlib.Path(__file__).resolve().parent
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(here.parent), os.environ.get("PYTHONPATH", "")]))
    run = subprocess.run([sys.executable, str(here / "dask_study.py"), str(out)],
                         env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads((out / "report.json").read_text())


def test_a_worker_killed_mid_study_loses_no_chunk(tmp_path):
    # a study on a two-worker cluster, one worker killed mid-study: every chunk written,
    # the numbers those of a local run
    report = _dask(tmp_path)
    killed, log = report["killed"], str(tmp_path / "log.txt")
    assert killed and report["workers"] == 2
    # every chunk written once, none missing; the values those of a local run
    assert sorted(report["computed"]) == list(range(12))
    assert sorted(os.listdir(tmp_path / "s.zarr" / "chunk_done")) == sorted(
        [".zarray", ".zattrs"] + [str(c) for c in range(12)])
    grid = aj.Grid({"tmd1.k": KT * np.linspace(0.9, 1.1, 12)})
    local = aj.study(tmd_system(), grid, QUESTION, chunk=1)
    res = aj.study(tmd_system(), grid, Counting(QUESTION, log, pause=0.5),
                   store=tmp_path / "s.zarr", chunk=1)
    assert res.computed == ()                    # read back: the cluster wrote every chunk
    for k in ("amplitude", "dof_amplitude", "spectral_radius", "peak"):
        np.testing.assert_allclose(res.data[k].values, local.data[k].values, rtol=1e-12,
                                   atol=0)
    np.testing.assert_array_equal(res.data["status"].values, local.data["status"].values)
    # the killed worker was in the middle of a chunk: that chunk was started again on the
    # other worker (under load the killed worker may have begun a second one in the
    # instant before the kill, started again too); a chunk restarted may also have been
    # logged as finished by the killed worker before the kill arrived, but each was
    # written once (above)
    started = [line.split() for line in log_lines(log + ".start")]
    finished = log_values(log)
    values = [v for _, v in started]
    again = {v for v in values if values.count(v) >= 2}
    assert len(started) >= 13 and again, started
    assert killed in [int(pid) for pid, v in started if v in again]
    assert sorted(set(finished)) == sorted(set(values)) and len(set(finished)) == 12
    assert all(finished.count(v) == 1 for v in finished if v not in again)
