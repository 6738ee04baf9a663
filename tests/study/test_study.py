"""Design studies: persistence, resumption, Dask workers (one lost mid-study), Monte Carlo
against the closed-form peak of a tuned mass damper, bad input."""

from __future__ import annotations

import hashlib
import os
import pathlib
import threading
import time

import numpy as np
import pytest

import absorber_jax as aj

xr = pytest.importorskip("xarray")
pytest.importorskip("zarr")

# a tuned mass damper (Den Hartog's tuning, mass ratio 0.05) on a lightly damped primary
M, K, C = 1.0, 1e4, 2.0
MU = 0.05
MT = MU * M
KT = MT * (np.sqrt(K / M) / (1 + MU)) ** 2
CT = 2 * np.sqrt(3 * MU / (8 * (1 + MU) ** 3)) * np.sqrt(KT * MT)
F0 = 1.0
OMEGAS = np.linspace(80.0, 120.0, 8)


def tmd_system(kt=KT, ct=CT):
    st = aj.structure_from_matrices(np.eye(1) * M, np.eye(1) * K, damping=np.eye(1) * C)
    return aj.StructuralSystem(st, [aj.TunedMassDamper("x1", m=MT, k=kt, c=ct)], load="x1")


def receptance(w, kt, ct):
    """|X1| / F0 of the primary, closed form (the TMD as a dynamic stiffness)."""
    z = kt + 1j * w * ct
    return np.abs(1.0 / (K - M * w**2 + 1j * w * C + z * (-MT * w**2) / (z - MT * w**2)))


def closed_form_peak(kt, ct, band=(80.0, 120.0)):
    """The largest |X1| over the band: a fine grid, then the maximum of each local peak by
    bounded scalar minimisation to 1e-13 rad/s."""
    from scipy.optimize import minimize_scalar

    w = np.linspace(*band, 4001)
    a = receptance(w, kt, ct)
    best = max(a[0], a[-1])
    for i in np.flatnonzero((a[1:-1] >= a[:-2]) & (a[1:-1] >= a[2:])) + 1:
        r = minimize_scalar(lambda x: -receptance(x, kt, ct), bounds=(w[i - 1], w[i + 1]),
                            method="bounded", options={"xatol": 1e-13})
        best = max(best, -r.fun)
    return F0 * best


class Counting(aj.questions.AbstractQuestion):
    """The frequency response, each chunk computed appended to a log file (one line: the
    process id and the chunk's first design value), each chunk started likewise to
    ``log + ".start"``; a stop (a KeyboardInterrupt, as Ctrl-C) once the log has
    as many lines as the file ``log + ".stop"`` says, while it exists; a pause per chunk."""

    inner: aj.questions.AbstractQuestion
    log: str
    pause: float = 0.0

    def coords(self, system):
        return self.inner.coords(system)

    def variables(self, system):
        return self.inner.variables(system)

    def points(self, system):
        return self.inner.points(system)

    def compute(self, system, params):
        with open(self.log + ".start", "a") as f:
            f.write(f"{os.getpid()} {next(iter(params.values()))[0]!r}\n")
        if self.pause:
            time.sleep(self.pause)
        out = self.inner.compute(system, params)
        with open(self.log, "a") as f:
            f.write(f"{os.getpid()} {next(iter(params.values()))[0]!r}\n")
        stop = pathlib.Path(self.log + ".stop")
        if stop.exists() and len(_lines(self.log)) >= int(stop.read_text()):
            raise KeyboardInterrupt
        return out


def _lines(path):
    p = pathlib.Path(path)
    return p.read_text().splitlines() if p.exists() else []


def _values(path):
    return [line.split()[1] for line in _lines(path)]


def _tree_digest(path):
    h = hashlib.sha256()
    for p in sorted(pathlib.Path(path).rglob("*")):
        if p.is_file():
            h.update(str(p.relative_to(path)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()


GRID = aj.Grid({"tmd1.k": KT * np.linspace(0.9, 1.1, 6), "tmd1.c": CT * np.array([0.5, 1.0])})
QUESTION = aj.questions.FrequencyResponse(OMEGAS, amplitude=F0)


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
    assert len(_lines(log)) == 2
    pathlib.Path(log + ".stop").unlink()
    # the rerun computes only the chunks missing: the interrupted one included
    res = aj.study(tmd_system(), GRID, Counting(QUESTION, log), store=store, chunk=2)
    lines = _lines(log)
    assert res.reused == 1 and len(res.computed) == 5
    # every chunk written exactly once; the interrupted chunk was computed, not written,
    # then computed again: 6 chunks, 7 computations, one of them repeated
    assert len(lines) == 7 and len(set(_values(log))) == 6
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
    digest = _tree_digest(store)
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
    assert _tree_digest(store) == digest
    assert not (tmp_path / "t").exists()


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    import sys

    import cloudpickle

    # the workers cannot import this test module: its question class travels by value
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as lc, \
            distributed.Client(lc) as client:
        yield client


def test_study_on_a_two_worker_cluster_equals_the_local_one(cluster, tmp_path):
    local = aj.study(tmd_system(), GRID, QUESTION, chunk=2)
    res = aj.study(tmd_system(), GRID, QUESTION, store=tmp_path / "s.zarr", chunk=2,
                   client=cluster)
    assert sorted(res.computed) == list(range(6))
    for k in ("amplitude", "dof_amplitude", "spectral_radius", "peak"):
        np.testing.assert_allclose(res.data[k].values, local.data[k].values, rtol=1e-12,
                                   atol=0)
    np.testing.assert_array_equal(res.data["status"].values, local.data["status"].values)


def test_a_worker_killed_mid_study_loses_no_chunk(cluster, tmp_path):
    log = str(tmp_path / "log.txt")
    pids = cluster.run(os.getpid)
    killed = []

    def kill_one():
        # once a chunk is done, kill a worker in the middle of its next one
        t0 = time.time()
        while time.time() - t0 < 120:
            done = [int(line.split()[0]) for line in _lines(log)]
            busy = [int(line.split()[0]) for line in _lines(log + ".start")]
            for pid in pids.values():
                if done and busy.count(pid) > done.count(pid):
                    os.kill(pid, 9)
                    killed.append(pid)
                    return
            time.sleep(0.02)

    grid = aj.Grid({"tmd1.k": KT * np.linspace(0.9, 1.1, 12)})
    th = threading.Thread(target=kill_one)
    th.start()
    res = aj.study(tmd_system(), grid, Counting(QUESTION, log, pause=0.5),
                   store=tmp_path / "s.zarr", chunk=1, client=cluster)
    th.join()
    assert killed
    # every chunk written once, none missing; the values those of a local run
    assert sorted(res.computed) == list(range(12))
    assert bool(xr.open_zarr(tmp_path / "s.zarr", consolidated=False)["chunk_done"].all())
    local = aj.study(tmd_system(), grid, QUESTION, chunk=1)
    np.testing.assert_allclose(res.data["amplitude"].values, local.data["amplitude"].values,
                               rtol=1e-12)
    assert sorted(set(_values(log))) == sorted(_values(log)) and len(_values(log)) == 12
    # the killed worker had started a chunk it never finished: computed again elsewhere
    started = [line.split() for line in _lines(log + ".start")]
    finished = [line.split() for line in _lines(log)]
    lost = ({v for pid, v in started if int(pid) == killed[0]}
            - {v for pid, v in finished if int(pid) == killed[0]})
    assert len(lost) == 1 and len(started) == 13, (started, finished)
