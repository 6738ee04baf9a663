"""Running the parts of a sweep (and the lanes of band_continuation's batches) on the local
devices, and asking JAX for one CPU device per core.

On a CPU JAX has one device and a sweep's compiled calls run on one core: the point solves
are long chains of small operations (a 44 × 44 tangent, a period's 600 steps) that XLA does
not spread over cores.  ``use_cpu_cores`` asks for one CPU device per core; the sweeps
then give each device its own parts (``on_devices``) and the cores run them side by side.
"""

from __future__ import annotations

import contextlib
import functools
import os
import queue
import threading

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.extend.core import jaxpr_as_fun
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .progress import PointProgress


def use_cpu_cores(n=None):
    """Make JAX's CPU backend expose ``n`` devices (default: the cores this process may run
    on), so that [`frequency_response`][absorber_jax.frequency_response] and the other sweeps run
    their parts on ``n`` cores side by side.  Call it before the first JAX computation (JAX fixes
    its devices then); it raises ``RuntimeError`` after.  Returns the number of CPU devices.

    Measured on 2 cores (``scripts/benchmark_structure.py``: the 20-storey building with two
    friction dampers, 256 frequencies): 8.1 s on one device, 4.3 s on two (the Benchmarks
    page of the documentation)."""
    if n is None:
        n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n must be a positive integer (CPU devices), got {n!r}")
    n = int(n)
    from jax._src import xla_bridge

    if xla_bridge.backends_are_initialized():
        have = len(jax.devices("cpu"))
        if have != n:
            raise RuntimeError(
                f"use_cpu_cores({n}): JAX has already started with {have} CPU device(s); call "
                "absorber_jax.use_cpu_cores() before any JAX computation (or set "
                f"XLA_FLAGS=--xla_force_host_platform_device_count={n})")
        return have
    jax.config.update("jax_num_cpu_devices", n)
    return n


def put(x, device):
    """``x`` as an array committed to ``device`` (None: the default device, uncommitted)."""
    x = jax.numpy.asarray(x)
    return x if device is None else jax.device_put(x, device)


def on_devices(solve, jobs, ndev, progress=None):
    """``[solve(job, device) for job in jobs]``, with ``ndev`` local devices working through
    the jobs in turn (``device`` is None with one device: the default, uncommitted).

    Each device has its own thread, which takes the next job as soon as its last one is
    done: the devices keep busy whatever the jobs cost (the chained lanes of a sweep differ
    by 2x).  Threads rather than JAX's asynchronous dispatch from this thread, because that
    does not overlap here: ``eqx.filter_jit`` waits for each call, and a program holding a
    host callback (diffrax's checks of ``SaveAt(ts)`` are) runs on the calling thread.  While
    the devices run, BLAS (OpenBLAS, under XLA's LAPACK calls) is held to one thread: its
    threads spin after each call on the core the other device needs (measured: two devices
    13.5 s with OpenBLAS's 2 threads, 9.9 s with 1; on one device 1 thread costs nothing).
    ``progress(i)``: called once per finished job ``i``.  Exceptions are raised here, after
    the others have stopped."""
    if ndev <= 1:
        out = []
        for i, job in enumerate(jobs):
            out.append(jax.device_get(solve(job, None)))
            if progress is not None:
                progress(i)
        return out
    devices = jax.local_devices()[:ndev]
    todo = queue.SimpleQueue()
    for i in range(len(jobs)):
        todo.put(i)
    out = [None] * len(jobs)
    errors = []
    lock = threading.Lock()

    def work(device):
        while not errors:
            try:
                i = todo.get_nowait()
            except queue.Empty:
                return
            try:
                out[i] = jax.device_get(solve(jobs[i], device))
            except BaseException as e:  # noqa: BLE001 - re-raised in the calling thread
                errors.append(e)
                return
            if progress is not None:
                with lock:
                    progress(i)

    with one_blas_thread(ndev):
        threads = [threading.Thread(target=work, args=(d,), daemon=True) for d in devices]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    if errors:
        raise errors[0]
    return out


def by_parts(rows, size, solve, ndev, progress=False):
    """``solve(padded rows, live, device)`` on the rows of ``rows`` (point indices, one row
    per lane), ``size // ndev`` rows at a time on each of ``ndev`` devices (``size`` a
    multiple of ``ndev``), the last part padded by repeating its last row (one compilation
    serves all; ``live``, a boolean per row, False on the padding: see ``over_lanes``); the
    results of the real rows, concatenated.  The devices work through the parts in
    turn, each taking the next as soon as it is done (``on_devices``); ``progress``: a
    bar over the points (``PointProgress``)."""
    part = size // ndev
    jobs, keep = [], []
    for start in range(0, rows.shape[0], part):
        idx = rows[start:start + part]
        keep.append(idx.shape[0])
        live = np.arange(part) < idx.shape[0]
        if idx.shape[0] < part:
            idx = np.concatenate([idx, np.repeat(idx[-1:], part - idx.shape[0], axis=0)])
        jobs.append((idx, live))
    points = [int(np.size(rows[start:start + part])) for start in range(0, rows.shape[0], part)]
    with PointProgress(sum(points), "sweep", bool(progress)) as bar:
        res = on_devices(lambda job, d: solve(*job, d), jobs, ndev,
                         progress=lambda i: bar.update(points[i]))
    return jax.tree_util.tree_map(lambda *a: np.concatenate(
        [np.asarray(x)[:k] for x, k in zip(a, keep)]), *res)


def over_lanes(fn, serial, masked=False):
    """``fn`` over the leading axis (the lanes) of its arguments: vmapped, or with ``serial``
    one lane after the other (``jax.lax.map``), for lanes whose loops differ in length
    (event-driven integrations and the Newton iterations over them: a vmapped loop runs
    every lane's body until the last lane ends).  The rigid-ball building sweep of
    scripts/benchmark_rigid_impacts.py, cache off: first call 161 s vmapped, 118 s lane
    after lane (its tracing 94 s and 40 s: vmapped, the integration's ``lane_by_lane`` rule
    traces it a second time), 4.1 s and 3.6 s compiled.

    ``masked``: the first argument is a boolean per lane, False for a padding lane (a batch
    filled up to its compiled size); lane after lane, a padding lane is skipped (its outputs
    are zeros, to be discarded), where vmapped it costs nothing extra and is computed.  The
    hard rigid band of scripts/benchmark_rigid_impacts.py ran 3976 corrector lanes for 1840
    requests, the padding more than half of its corrector time."""
    if not serial:
        return jax.vmap((lambda live, *a: fn(*a)) if masked else fn)
    if not masked:
        return lambda *args: jax.lax.map(lambda a: fn(*a), args)

    def run(live, *args):
        # ``fn`` traced once, on one lane's shapes; each live lane evaluates that program,
        # a skipped one gives zeros of its output shapes (tracing it again for the shapes
        # alone cost the rigid building sweep's first call 22 s more)
        lane_args = jax.tree_util.tree_map(lambda a: jax.ShapeDtypeStruct(a.shape[1:], a.dtype),
                                           args)
        program, shapes = jax.make_jaxpr(fn, return_shape=True)(*lane_args)
        run_program = jaxpr_as_fun(program)
        out_tree = jax.tree_util.tree_structure(shapes)

        def lane(a):
            outs = jax.lax.cond(
                a[0], lambda: run_program(*jax.tree_util.tree_leaves(a[1:])),
                lambda: [jnp.zeros(v.shape, v.dtype) for v in program.out_avals])
            return jax.tree_util.tree_unflatten(out_tree, outs)

        return jax.lax.map(lane, (live,) + args)

    return run


def lanes_on_devices(one, shared, *lanes, ndev, serial=False, live=None):
    """``one(shared, *lane)`` vmapped over the lanes (the leading axis of ``lanes``) and the
    lanes split into ``ndev`` equal parts, one on each of the first ``ndev`` local devices,
    inside a jitted function: one SPMD program (``jax.shard_map``; no communication between the
    parts, each device runs its own loops to their own ends), compiled and traced once for
    all the devices, where ``by_parts`` compiles a program per device, each traced
    again under the interpreter lock (the hard Kelvin–Voigt scene's batched continuation
    corrector, 16 lanes on two CPU devices: 8.1 s to the first result against 10.9 s with a
    program per device, 0.84 s a call after against 1.04 s).  ``shared`` (a pytree, its arrays
    replicated) is the same for all lanes; the number of lanes must be a multiple of ``ndev``
    (see ``device_parts``). Call it under ``one_blas_thread``.

    ``serial``: each device runs its lanes one after the other (``over_lanes``), skipping
    those whose ``live`` flag (a boolean per lane, if given) is False.  Event-driven
    integrations through diffrax run on one device (``ndev=1``): their event location's
    implicit derivative (optimistix, lineax) fails to trace inside ``shard_map``, its
    closure conversion cached with the manual mesh's sharding and checked against shapes
    without it; flights in closed form (``_integration.flights``) have none."""
    masked = live is not None
    if masked:
        lanes = (live,) + lanes

    def f(shared, *lanes):
        return over_lanes(lambda *lane: one(shared, *lane), serial, masked)(*lanes)

    if ndev <= 1:
        return f(shared, *lanes)
    mesh = _mesh(ndev)
    dynamic, static = eqx.partition(shared, eqx.is_array)
    split = PartitionSpec("lanes")
    g = jax.shard_map(lambda d, *a: f(eqx.combine(d, static), *a), mesh=mesh,
                      in_specs=(PartitionSpec(),) + (split,) * len(lanes), out_specs=split,
                      check_vma=False)
    return g(dynamic, *lanes)


@functools.cache
def _mesh(ndev):
    return Mesh(np.array(jax.local_devices()[:ndev]), ("lanes",))


def replicated(shared, ndev):
    """``shared``'s arrays replicated on the first ``ndev`` local devices, where
    ``lanes_on_devices`` runs them (one device: as given).  A caller that calls it again
    and again with the same ``shared`` (a continuation's batched corrector, hundreds of
    calls) places it once and saves the copy at every call (the hard rigid band's empty
    corrector call on two CPU devices: 2.7 ms as given, 2.0 ms with ``shared`` placed,
    1.5 ms with the lanes placed by ``split_over`` too)."""
    if ndev <= 1:
        return shared
    dynamic, static = eqx.partition(shared, eqx.is_array)
    return eqx.combine(jax.device_put(dynamic, NamedSharding(_mesh(ndev), PartitionSpec())),
                       static)


def split_over(lanes, ndev):
    """The arrays ``lanes`` (lane axis first) split over the first ``ndev`` local devices
    as ``lanes_on_devices`` splits them, in one transfer (one device: as given)."""
    if ndev <= 1:
        return lanes
    return jax.device_put(lanes, NamedSharding(_mesh(ndev), PartitionSpec("lanes")))


class LaneLayout:
    """Where each leaf of a batch of lanes lies in its packed array (``packed_lanes``): the
    tree's structure, and each leaf's shape past the lane axis, dtype and columns (a
    complex leaf: its real parts, then its imaginary parts), or its value where it is no
    array (a constant of the traced program).  A static output of a jitted function."""

    def __init__(self, treedef, parts):
        self.treedef, self.parts = treedef, parts

    def lanes(self, packed, which):
        """The trees of the lanes ``which`` of ``packed`` (a host array), their leaves numpy
        arrays (each leaf unpacked once for all of them, then indexed)."""
        leaves = []
        for shape, dtype, cols, _ in self.parts:
            if cols is None:
                leaves.append(None)
                continue
            v = packed[:, cols]
            if np.issubdtype(dtype, np.complexfloating):
                half = v.shape[1] // 2
                v = v[:, :half] + 1j * v[:, half:]
            leaves.append(v.astype(dtype).reshape((packed.shape[0],) + tuple(shape)))
        consts = [part[3] for part in self.parts]
        return [self.treedef.unflatten([c if a is None else a[j]
                                        for a, c in zip(leaves, consts)]) for j in which]


def packed_lanes(tree):
    """The array leaves of ``tree`` (a batch of lanes: each leaf's first axis) packed into
    one float64 array of one row a lane, and its ``LaneLayout``: a batch fetched from the
    devices in one transfer, where a transfer a leaf costs ~0.1 ms each (the continuation
    corrector's 27 leaves, split over two CPU devices: 1.6-2.4 ms a call).  Integer and
    boolean leaves are exact in float64 below ``2**53``."""
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    cols, parts, at = [], [], 0
    for a in leaves:
        if not isinstance(a, jax.Array):
            parts.append((None, None, None, a))
            continue
        flat = a.reshape(a.shape[0], -1)
        if jnp.iscomplexobj(flat):
            flat = jnp.concatenate([flat.real, flat.imag], axis=1)
        cols.append(flat.astype(jnp.float64))
        width = flat.shape[1]
        parts.append((a.shape[1:], np.dtype(a.dtype), slice(at, at + width), None))
        at += width
    return jnp.concatenate(cols, axis=1), LaneLayout(treedef, tuple(parts))


def device_parts(size):
    """The local devices a batch of ``size`` lanes is split over by
    ``lanes_on_devices``: all of them where each gets at least two lanes and an equal
    share, else one."""
    ndev = jax.local_device_count()
    return ndev if size % ndev == 0 and size >= 2 * ndev else 1


def one_blas_thread(ndev):
    """A context holding BLAS (OpenBLAS, under XLA's LAPACK calls) to one thread while
    ``ndev > 1`` devices run (see ``on_devices``); a no-op on one device.  The BLAS
    libraries are found once per process (``_blas``): a search of the loaded libraries at
    every call cost 1.3 ms, around each of the hundreds of batched corrector calls of a
    band on two devices."""
    if ndev <= 1:
        return contextlib.nullcontext()
    return _blas().limit(limits=1, user_api="blas")


@functools.cache
def _blas():
    """The process's ``threadpoolctl.ThreadpoolController``, made once SciPy's linear
    algebra (whose OpenBLAS XLA's LAPACK kernels call) is loaded, so that it holds that
    library too."""
    import scipy.linalg  # noqa: F401  (loads the OpenBLAS that XLA's LAPACK calls use)
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()
