"""Benchmark: a design study of a friction absorber, locally and on Dask workers, against
the plain sweep, side by side in one run.

Scene: ``FrictionAbsorber(m1=1, k1=1e4, c1=2, m2=0.2, k2=1.8e3, c2, N, Coulomb(mu=0.5))``
(exact stick–slip), 10 N at 64 frequencies over 70–120 rad/s.  The study: a grid of
100 normal forces (0.01–200 N, geometric) × 100 absorber dampings (0–2 N s/m) = 10,000
designs × 64 frequencies, in chunks of 4 designs (256 solves each, one compiled program).

Every configuration runs ``--designs`` of its designs, spread evenly through the grid (a
whole number of chunks), after a warm-up that pays the compilation, and reports solves per
second, the extrapolated time of the whole study, and the time per chunk against the plain
sweep (``frequency_response`` with the same designs as ``params``, chunk by chunk):

- **sweep**: ``frequency_response`` chunk by chunk, in this process (the reference);
- **local**: ``aj.study`` with a store on disk, in this process;
- **dask-1**, **dask-2**: ``aj.study`` on a ``LocalCluster`` of 1 and 2 worker processes
  (one thread each), each worker first warmed by one chunk of its own (its compilation,
  read from the persistent compilation cache the local run filled, reported separately).

In-process runs use every core as a JAX device (``aj.use_cpu_cores``); on a machine with a
GPU JAX runs them there instead, and the same lines report the study's throughput on it.
``--full STORE`` then runs the whole study locally into the store ``STORE`` (run
again to resume it) and reports its rate.

    python scripts/benchmark_study.py [--designs 32] [--workers 1,2] [--full STORE]
                                      [--out FILE]

Prints each result as it comes; ``--out`` writes them to FILE
(docs/benchmark_study.txt holds the last run).
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time

import numpy as np

import absorber_jax as aj

LINES = []
CHUNK = 4
OMEGAS = np.linspace(70.0, 120.0, 64)
F0 = 10.0


def report(line):
    print(line, flush=True)
    LINES.append(line)


def system():
    return aj.FrictionAbsorber(m1=1.0, k1=1e4, c1=2.0, m2=0.2, k2=1.8e3, c2=0.0,
                               normal_force=2.0, friction=aj.Coulomb(mu=0.5))


def full_grid():
    return aj.Grid(N=np.geomspace(0.01, 200.0, 100), c2=np.linspace(0.0, 2.0, 100))


def subset(n):
    """``n`` designs spread evenly through the full grid's order (every normal force and
    damping range represented), as an explicit list."""
    table = full_grid().table(system())
    idx = np.linspace(0, 9_999, n).round().astype(int)
    return aj.Designs({k: v[idx] for k, v in table.items()})


def question():
    return aj.questions.FrequencyResponse(OMEGAS, amplitude=F0)


def run_sweep(designs):
    table = designs.table(system())
    n = len(next(iter(table.values())))
    t0 = time.perf_counter()
    failed = 0
    for i in range(0, n, CHUNK):
        fr = aj.frequency_response(system(), OMEGAS, amplitude=F0,
                                   params={k: v[i:i + CHUNK] for k, v in table.items()})
        failed += int((np.asarray(fr.status) != 0).sum())
    return time.perf_counter() - t0, failed


def run_study(designs, client=None):
    path = tempfile.mkdtemp(prefix="benchmark_study_") + "/s.zarr"
    try:
        t0 = time.perf_counter()
        res = aj.study(system(), designs, question(), store=path, chunk=CHUNK, client=client)
        return time.perf_counter() - t0, res
    finally:
        shutil.rmtree(os.path.dirname(path), ignore_errors=True)


def warm_worker(designs):
    """One chunk computed in this process (on a Dask worker: its compilation paid)."""
    table = designs.table(system())
    question().compute(system(), table)
    return True


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--designs", type=int, default=32)
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--full", default=None, metavar="STORE")
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    n = max(CHUNK, a.designs // CHUNK * CHUNK)
    total = 10_000 * OMEGAS.size
    points = n * OMEGAS.size
    import jax

    aj.use_cpu_cores()          # before JAX starts: every core a CPU device (unused on a GPU)
    report(f"study benchmark on {os.cpu_count()} cores, jax {jax.__version__} "
           f"({jax.default_backend()}: {jax.devices()[0].device_kind}): friction "
           f"absorber (exact Coulomb), {n} of 10,000 designs x {OMEGAS.size} frequencies "
           f"({points} solves, chunks of {CHUNK} designs)")
    warm = subset(CHUNK)
    t_first, _ = run_sweep(warm)
    report(f"[warm-up] first chunk with compilation: {t_first:.1f} s")
    t_sweep, failed = run_sweep(subset(n))
    rate = points / t_sweep
    report(f"[sweep] {t_sweep:.1f} s, {rate:.1f} solves/s ({failed} failed); whole study "
           f"{total / rate / 3600:.1f} h")
    t_local, res = run_study(subset(n))
    r_local = points / t_local
    report(f"[local] {t_local:.1f} s, {r_local:.1f} solves/s ({res.failures()} failed); "
           f"per chunk {(t_local - t_sweep) / (n // CHUNK) * 1e3:+.0f} ms against the sweep "
           f"({t_local / t_sweep:.3f}x); whole study {total / r_local / 3600:.1f} h")
    from distributed import Client, LocalCluster

    for w in (int(x) for x in a.workers.split(",") if x):
        with LocalCluster(n_workers=w, threads_per_worker=1, processes=True,
                          dashboard_address=None) as lc, Client(lc) as client:
            t0 = time.perf_counter()
            client.run(warm_worker, subset(CHUNK))      # every worker compiles, at once
            t_warm = time.perf_counter() - t0
            t_dask, res = run_study(subset(n), client)
        r = points / t_dask
        report(f"[dask-{w}] {t_dask:.1f} s, {r:.1f} solves/s ({res.failures()} failed), "
               f"{r / r_local:.2f}x local; the workers' warm-up (a chunk each, at once: tracing, "
               f"compilation from the cache) {t_warm:.1f} s; whole study "
               f"{total / r / 3600:.1f} h")
    if a.full:
        t0 = time.perf_counter()
        res = aj.study(system(), full_grid(), question(), store=a.full, chunk=CHUNK,
                       progress=True)
        t_full = time.perf_counter() - t0
        s = res.summary()
        report(f"[full] 10,000 designs x {OMEGAS.size} frequencies into {a.full}: "
               f"{len(res.computed)} chunks computed in {t_full:.0f} s "
               f"({res.rate:.1f} solves/s), {res.reused} read back; {s['failed_points']} failed "
               f"points; band peak {s.get('peak_min', float('nan')):.4g}-"
               f"{s.get('peak_max', float('nan')):.4g} m")
    if a.out:
        with open(a.out, "w") as f:
            f.write("\n".join(LINES) + "\n")


if __name__ == "__main__":
    main()
