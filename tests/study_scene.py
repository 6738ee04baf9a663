"""The tuned mass damper of the study tests, its closed-form response and peak, and a
question that logs every chunk it computes (imported by tests/study/ and by the Dask
worker processes of tests/study/dask_study.py)."""

from __future__ import annotations

import hashlib
import os
import pathlib
import time

import numpy as np

import absorber_jax as aj

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

    def describe(self):
        return "counting " + self.inner.describe()

    def compute(self, system, params):
        with open(self.log + ".start", "a") as f:
            f.write(f"{os.getpid()} {next(iter(params.values()))[0]!r}\n")
        if self.pause:
            time.sleep(self.pause)
        out = self.inner.compute(system, params)
        with open(self.log, "a") as f:
            f.write(f"{os.getpid()} {next(iter(params.values()))[0]!r}\n")
        stop = pathlib.Path(self.log + ".stop")
        if stop.exists() and len(log_lines(self.log)) >= int(stop.read_text()):
            raise KeyboardInterrupt
        return out


def log_lines(path):
    p = pathlib.Path(path)
    return p.read_text().splitlines() if p.exists() else []


def log_values(path):
    return [line.split()[1] for line in log_lines(path)]


def tree_digest(path):
    h = hashlib.sha256()
    for p in sorted(pathlib.Path(path).rglob("*")):
        if p.is_file():
            h.update(str(p.relative_to(path)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()


GRID = aj.Grid({"tmd1.k": KT * np.linspace(0.9, 1.1, 6), "tmd1.c": CT * np.array([0.5, 1.0])})
QUESTION = aj.questions.FrequencyResponse(OMEGAS, amplitude=F0)
