"""``study``: every design of a set asked one question, in chunks that share one compiled
program, written to a persistent store as they complete, locally or on a Dask cluster."""

from __future__ import annotations

import time

import numpy as np

from .._core.checks import require_x64
from .._core.progress import PointProgress
from .._core.units import signals_of
from .._systems.base import AbstractSystem
from .._systems.params import get_param, parameter_names, replace_params, resolve
from .designs import AbstractDesigns
from .questions import AbstractQuestion
from .result import StudyResult
from .store import Store, as_json, fingerprint, skeleton

# designs per chunk by default: a frequency response's chunk is then this many designs ×
# its frequencies in one compiled call (256 points for 64 frequencies)
DEFAULT_POINTS_PER_CHUNK = 256


def compute_chunk(system, question, params):
    """One chunk's answer (run where the chunk is computed: here, or on a Dask worker,
    which imports the library, and so enables float64 and the compilation cache, first)."""
    return question.compute(system, params)


def study(system: AbstractSystem, designs: AbstractDesigns, question: AbstractQuestion, *,
          store=None, chunk: int | None = None, client=None, progress: bool = False,
          retries: int = 2) -> StudyResult:
    """Ask ``question`` of every design of ``designs`` (a variant of ``system`` each), in
    chunks of ``chunk`` designs, every chunk the same size (the last one padded), so that
    one compiled program serves them all.

    **Arguments**

    - ``designs``: ``aj.Grid``, ``aj.Designs``, ``aj.MonteCarlo`` or ``aj.LatinHypercube``
      (names as ``aj.parameter_names(system)`` lists them).
    - ``question``: ``aj.questions.FrequencyResponse``, ``ExactPeak``, ``RobustPeak``,
      ``Attractors``, or your own ``aj.questions.AbstractQuestion``.
    - ``store``: a directory path: a store (in the Zarr version 2 format) written chunk by
      chunk as the chunks complete.  Run again on the same store, the study computes only
      the chunks not yet written (after Ctrl-C, a crash or a lost machine nothing done is
      lost or computed twice); a store made for another study (system, designs, question
      or chunk size) is refused with a ``ValueError`` and left untouched.  ``None``: in
      memory only.
    - ``chunk``: designs per chunk (default: about 256 solves a chunk).
    - ``client``: a ``distributed.Client``: the chunks are computed on its workers (a
      ``LocalCluster`` on this machine, a ``dask_jobqueue.SLURMCluster`` on a cluster),
      each compiling once and serving many chunks; a chunk whose worker is lost is computed
      again elsewhere (``retries`` times at most, for chunks that raise).  Results are
      gathered and written here.  ``None``: computed in this process on its devices.
    - ``progress``: a bar over the solves (done of total, rate, time left; it says when
      the first chunk is compiling).

    **Returns** a ``StudyResult``: ``data``, an xarray Dataset (the designs' own dimensions:
    a grid's parameters or ``sample``, then the question's; units and the study's
    description in the attributes), and what this run computed.

    ```python
    import numpy as np, absorber_jax as aj
    system, _ = aj.presets.friction("coulomb")
    res = aj.study(system, aj.Grid(N=np.linspace(1.0, 12.0, 12)),
                   aj.questions.FrequencyResponse(np.linspace(5, 15, 64), amplitude=2.0),
                   store="friction_grid.zarr", progress=True)
    res.data["peak"].plot()
    ```
    """
    require_x64("study")
    if not isinstance(system, AbstractSystem):
        raise ValueError(f"study.system must be a system (ImpactAbsorber, FrictionAbsorber, "
                         f"StructuralSystem ...), got {type(system).__name__}")
    if not isinstance(designs, AbstractDesigns):
        raise ValueError(f"study.designs must be aj.Grid, aj.Designs, aj.MonteCarlo or "
                         f"aj.LatinHypercube, got {type(designs).__name__}")
    if not isinstance(question, AbstractQuestion):
        raise ValueError(f"study.question must be an aj.questions.AbstractQuestion "
                         f"(FrequencyResponse, ExactPeak ...), got {type(question).__name__}")
    known = parameter_names(system)
    for name in designs.names:
        try:
            resolve(system, name)
        except ValueError:
            raise ValueError(f"study.designs: unknown parameter {name!r} of "
                             f"{type(system).__name__}; known: {known}") from None
    table = designs.table(system)
    P = int(next(iter(table.values())).shape[0])
    points = question.points(system)
    if chunk is None:
        chunk = max(1, min(P, DEFAULT_POINTS_PER_CHUNK // max(points, 1)))
    if not isinstance(chunk, int) or isinstance(chunk, bool) or chunk < 1:
        raise ValueError(f"study.chunk must be a positive integer, got {chunk!r}")
    if not isinstance(retries, int) or retries < 0:
        raise ValueError(f"study.retries must be a non-negative integer, got {retries!r}")
    # every design checked (values in range) before anything is computed
    _check_designs(system, table)
    coords = question.coords(system)
    variables = question.variables(system)
    for name, (dims, *_ ) in variables.items():
        missing = [d for d in dims if d not in coords]
        if missing:
            raise ValueError(f"question variable {name!r} has dimensions {missing} that "
                             f"its coords() does not give")
    fp = fingerprint(system, table, question, chunk)
    sig = signals_of(system)
    attrs = dict(
        study=f"{type(question).__name__} of {type(system).__name__} over "
              f"{type(designs).__name__}({', '.join(designs.names)})",
        fingerprint=fp, system=type(system).__name__,
        system_parameters=as_json({k: _nominal(system, k) for k in known}),
        designs=designs.describe(), question=question.describe(), chunk=chunk,
        observable=sig.observable, variables=",".join(variables),
        created=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    )
    sk = skeleton(table, coords, variables, chunk, attrs)
    for name in table:
        sk[name].attrs["units"] = sig.parameter_unit(name)
    C = -(-P // chunk)
    st = None
    if store is not None:
        st = Store(store)
        if st.exists():
            st.check(fp)
        else:
            st.create(sk, chunk)
        done = st.done()
    else:
        done = np.zeros(C, bool)
        memory = {k: np.array(sk[k].values) for k in variables}
    todo = [c for c in range(C) if not done[c]]
    dims = {k: tuple(v[0]) for k, v in variables.items()}

    def params_of(c):
        lo, hi = c * chunk, min((c + 1) * chunk, P)
        pad = chunk - (hi - lo)
        return {k: np.concatenate([v[lo:hi], np.repeat(v[hi - 1:hi], pad)])
                for k, v in table.items()}, lo, hi - lo

    def record(c, values):
        _, lo, n = params_of(c)
        values = {k: np.asarray(values[k])[:n] for k in variables}
        if st is not None:
            st.write(c, lo, values, dims)
        else:
            for k, v in values.items():
                memory[k][lo:lo + n] = v

    computed, failed = [], {}
    t0 = time.perf_counter()
    before = sum(params_of(c)[2] for c in range(C) if done[c]) * points
    with PointProgress(P * points, "study", progress, initial=before) as bar:
        if client is None:
            for c in todo:
                params, _, n = params_of(c)
                try:
                    values = compute_chunk(system, question, params)
                except (KeyboardInterrupt, SystemExit):
                    raise
                except Exception as err:      # noqa: BLE001 (one chunk never loses the rest)
                    failed[c] = err
                    continue
                record(c, values)
                computed.append(c)
                bar.update(n * points)
        else:
            _on_cluster(client, system, question, todo, params_of, record, computed, failed,
                        bar, points, retries)
    elapsed = time.perf_counter() - t0
    if failed:
        c, err = next(iter(failed.items()))
        raise RuntimeError(
            f"study: {len(failed)} of {len(todo)} chunks raised (chunk {c}: "
            f"{type(err).__name__}: {err}); the {len(computed)} others are "
            + (f"in {st.path!r}: run again to compute only the missing ones"
               if st is not None else "lost (give a store= to keep them)")) from err
    data = st.load() if st is not None else _in_memory(sk, memory, C)
    return StudyResult.from_store(data, designs.axes(system), computed=tuple(computed),
                                  reused=int(done.sum()), seconds=elapsed,
                                  store=None if st is None else st.path,
                                  points_per_design=points)


def _on_cluster(client, system, question, todo, params_of, record, computed, failed, bar,
                points, retries):
    """The chunks ``todo`` on ``client``'s workers, written here as they complete."""
    from distributed import as_completed

    [payload] = client.scatter([(system, question)], broadcast=True)
    futures, which = [], {}
    for c in todo:
        params, _, _ = params_of(c)
        fut = client.submit(_remote, payload, params, retries=retries, pure=False,
                            key=f"absorber-study-chunk-{c}-{time.time_ns()}")
        futures.append(fut)
        which[fut.key] = c
    try:
        for fut in as_completed(futures):
            c = which[fut.key]
            try:
                values = fut.result()
            except Exception as err:          # noqa: BLE001
                failed[c] = err
                continue
            record(c, values)
            computed.append(c)
            bar.update(params_of(c)[2] * points)
            fut.release()
    except BaseException:
        client.cancel(futures)
        raise


def _remote(payload, params):
    system, question = payload
    return compute_chunk(system, question, params)


def _check_designs(system, table):
    P = int(next(iter(table.values())).shape[0])
    for name, v in table.items():
        for i in {int(np.argmin(v)), int(np.argmax(v))}:
            try:
                replace_params(system, {name: float(v[i])}, check=True)
            except ValueError as err:
                raise ValueError(f"study.designs: {name} = {v[i]:g} (design {i} of {P}) is "
                                 f"not a valid value: {err}") from None


def _nominal(system, name):
    try:
        return float(np.asarray(get_param(system, name)))
    except (TypeError, ValueError):
        return str(get_param(system, name))


def _in_memory(sk, memory, C):
    ds = sk.copy()
    for k, v in memory.items():
        ds[k] = (ds[k].dims, v, ds[k].attrs)
    ds["chunk_done"] = (("chunk",), np.ones(C, bool), ds["chunk_done"].attrs)
    return ds
