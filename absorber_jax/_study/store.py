"""A study's store on disk: a directory in the Zarr version 2 format (one folder per
variable, its metadata in JSON, one file of raw little-endian bytes per chunk), laid out
before the first chunk is computed; each chunk's answer is written as it completes, then
flagged done.

Layout: dimension ``design`` (every design, in the study's order; each named parameter a
coordinate on it), the question's own dimensions, and ``chunk`` (the computation's
chunks; ``chunk_done`` flags which are complete).  A chunk's values are written before
its flag, every file through a temporary name and an atomic rename, so a chunk cut short
by a crash is computed again and never read half-written.  The store's ``fingerprint``
attribute identifies the study (system, designs, question and chunk size); a store with
another one is refused and left untouched.

The library writes and reads the format itself (numpy and JSON only, no compression, no
dependency on the ``zarr`` package); other tools open it as Zarr
(``xarray.open_zarr(path)`` with the ``zarr`` package installed).  Reference: the Zarr
storage specification version 2, https://zarr-specs.readthedocs.io/en/latest/v2/v2.0.html.
"""

from __future__ import annotations

import hashlib
import json
import math
import os

import equinox as eqx
import jax
import numpy as np

# what an answer variable holds where nothing is computed yet, by dtype kind
FILL = {"f": np.nan, "i": -1, "b": False}
DONE = "chunk_done"


def fingerprint(*parts) -> str:
    """A SHA-256 of ``parts`` (pytrees: their structure and static fields as equinox prints
    them, every array leaf's dtype, shape and bytes; dicts of arrays; numbers; strings)."""
    h = hashlib.sha256()

    def add(x):
        if isinstance(x, dict):
            for k in sorted(x):
                h.update(str(k).encode())
                add(x[k])
            return
        leaves = jax.tree_util.tree_leaves(x)
        h.update(eqx.tree_pformat(x, short_arrays=True).encode())
        for leaf in leaves:
            a = np.asarray(leaf) if eqx.is_array_like(leaf) else None
            if a is not None and a.dtype != object:
                h.update(f"{a.dtype}{a.shape}".encode())
                h.update(np.ascontiguousarray(a).tobytes())
            else:
                h.update(repr(leaf).encode())

    for p in parts:
        add(p)
    return h.hexdigest()


def _xr():
    try:
        import xarray as xr
    except ImportError:
        raise ImportError("a study's results need xarray: pip install "
                          "'absorber_jax[study]'") from None
    return xr


def _atomic(path, data: bytes) -> None:
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "wb") as f:
        f.write(data)
    os.replace(tmp, path)


def _json(path, obj) -> None:
    _atomic(path, json.dumps(obj, indent=1, sort_keys=True, default=_plain).encode())


def _plain(v):
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating,)):
        return None if not np.isfinite(v) else float(v)
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


def _dtype(a: np.ndarray) -> np.dtype:
    """The stored (little-endian) dtype of ``a``: text as fixed-length unicode."""
    if a.dtype.kind in "OUT":
        n = max([len(str(x)) for x in a.ravel()] + [1])
        return np.dtype(f"<U{n}")
    return a.dtype.newbyteorder("<") if a.dtype.kind in "fiuc" else a.dtype


def _fill_json(dtype, fill):
    if dtype.kind == "f":
        return "NaN" if math.isnan(fill) else float(fill)
    if dtype.kind == "b":
        return bool(fill)
    if dtype.kind in "iu":
        return int(fill)
    return None


def _fill_value(meta, dtype):
    f = meta["fill_value"]
    if f is None:
        return "" if dtype.kind == "U" else 0
    return np.nan if f == "NaN" else f


class Store:
    """The study store at ``path`` (a directory in the Zarr version 2 format)."""

    def __init__(self, path):
        self.path = os.fspath(path)

    def exists(self) -> bool:
        return os.path.exists(self.path)

    def attrs(self) -> dict:
        with open(os.path.join(self.path, ".zattrs")) as f:
            return json.load(f)

    def check(self, fp: str) -> None:
        """Refuse (``ValueError``) a path that is not a study's store, or another study's."""
        try:
            attrs = self.attrs()
            with open(os.path.join(self.path, DONE, ".zarray")) as f:
                json.load(f)
        except (OSError, ValueError) as err:
            raise ValueError(f"store {self.path!r} exists but is not a study's store "
                             f"({type(err).__name__}: {err}); choose another path") from None
        found = attrs.get("fingerprint")
        if found != fp:
            raise ValueError(
                f"store {self.path!r} holds another study ({attrs.get('study', 'unknown')}; "
                f"fingerprint {str(found)[:12]}, this study's {fp[:12]}): its system, "
                f"designs, question or chunk size differ; it was left untouched: choose "
                f"another path, or delete it to start again")

    def create(self, skeleton, chunk: int) -> None:
        """Lay the store out from ``skeleton`` (the dataset with its fill values): every
        variable's metadata and its values where they are not the fill (the coordinates);
        the answer variables in chunks of ``chunk`` designs, ``chunk_done`` of one."""
        os.makedirs(self.path)
        _json(os.path.join(self.path, ".zgroup"), {"zarr_format": 2})
        _json(os.path.join(self.path, ".zattrs"), dict(skeleton.attrs))
        for name, var in skeleton.variables.items():
            values = np.asarray(var.values)
            dtype = _dtype(values)
            data_var = name in skeleton.data_vars
            chunks = tuple(
                (1 if name == DONE else chunk) if d in ("design", "chunk") and data_var
                else n for d, n in zip(var.dims, var.shape)) or ()
            folder = os.path.join(self.path, name)
            os.makedirs(folder)
            # data variables: their fill value where not computed; coordinates: none
            fill = FILL[dtype.kind] if data_var else None
            _json(os.path.join(folder, ".zarray"), {
                "zarr_format": 2, "shape": list(var.shape), "chunks": list(chunks),
                "dtype": dtype.str, "compressor": None, "filters": None, "order": "C",
                "fill_value": _fill_json(dtype, fill) if data_var else None})
            extra = {"coordinates": " ".join(c for c in skeleton.coords if c not in var.dims
                                             and set(skeleton[c].dims) <= set(var.dims))}
            _json(os.path.join(folder, ".zattrs"),
                  dict(var.attrs, _ARRAY_DIMENSIONS=list(var.dims),
                       **(extra if data_var and extra["coordinates"] else {})))
            if not data_var:                     # coordinates: written whole, once
                self._put(name, (0,) * values.ndim, values.astype(dtype), chunks)

    def _put(self, name, index, block, chunks):
        """Chunk ``index`` of variable ``name``: ``block`` padded to the chunk shape."""
        full = np.asarray(block)
        if chunks and full.shape != tuple(chunks):
            pad = [(0, c - n) for c, n in zip(chunks, full.shape)]
            full = np.pad(full, pad, constant_values=(np.nan if full.dtype.kind == "f"
                                                      else 0))
        key = ".".join(str(i) for i in index) or "0"
        _atomic(os.path.join(self.path, name, key), np.ascontiguousarray(full).tobytes())

    def _meta(self, name):
        with open(os.path.join(self.path, name, ".zarray")) as f:
            return json.load(f)

    def done(self) -> np.ndarray:
        """Per chunk: whether it is complete (its flag's file is written)."""
        meta = self._meta(DONE)
        return np.array([os.path.exists(os.path.join(self.path, DONE, str(c)))
                         for c in range(meta["shape"][0])], dtype=bool)

    def write(self, c: int, start: int, values: dict, dims: dict) -> None:
        """Chunk ``c``'s answer ``values`` (``{name: (p, ...)}``, designs ``start`` on:
        chunk ``c`` of every answer variable), then its flag."""
        for k, v in values.items():
            meta = self._meta(k)
            block = np.asarray(v, dtype=np.dtype(meta["dtype"]))
            self._put(k, (c,) + (0,) * (block.ndim - 1), block, meta["chunks"])
        self._put(DONE, (c,), np.ones(1, bool), [1])

    def _read(self, name):
        meta = self._meta(name)
        dtype = np.dtype(meta["dtype"])
        shape, chunks = tuple(meta["shape"]), tuple(meta["chunks"]) or ()
        out = np.full(shape, _fill_value(meta, dtype), dtype=dtype)
        if not shape:
            return out
        counts = [-(-n // c) for n, c in zip(shape, chunks)]
        for index in np.ndindex(*counts):
            path = os.path.join(self.path, name, ".".join(map(str, index)))
            if not os.path.exists(path):
                continue
            with open(path, "rb") as f:
                block = np.frombuffer(f.read(), dtype=dtype).reshape(chunks)
            sl = tuple(slice(i * c, min((i + 1) * c, n))
                       for i, c, n in zip(index, chunks, shape))
            out[sl] = block[tuple(slice(0, s.stop - s.start) for s in sl)]
        return out

    def load(self):
        """The whole store as an in-memory xarray Dataset."""
        xr = _xr()
        attrs = self.attrs()
        data, coords = {}, {}
        for name in sorted(os.listdir(self.path)):
            folder = os.path.join(self.path, name)
            if not os.path.isdir(folder) or name.startswith("."):
                continue
            with open(os.path.join(folder, ".zattrs")) as f:
                vattrs = json.load(f)
            dims = tuple(vattrs.pop("_ARRAY_DIMENSIONS"))
            vattrs.pop("coordinates", None)
            v = xr.Variable(dims, self._read(name), attrs=vattrs)
            (data if self._meta(name)["fill_value"] is not None else coords)[name] = v
        return xr.Dataset(data, coords=coords, attrs=attrs)


def skeleton(table, coords, variables, chunk, attrs):
    """The study's dataset before anything is computed: fill values everywhere."""
    xr = _xr()
    P = int(next(iter(table.values())).shape[0])
    C = -(-P // chunk)
    data = {}
    for name, (dims, unit, description, dtype) in variables.items():
        shape = (P,) + tuple(len(coords[d]) for d in dims)
        data[name] = xr.Variable(("design",) + tuple(dims),
                                 np.full(shape, FILL[np.dtype(dtype).kind], dtype=np.dtype(dtype)),
                                 attrs={"units": unit, "long_name": description})
    data[DONE] = xr.Variable(("chunk",), np.zeros(C, bool),
                             attrs={"long_name": "chunk computed and written"})
    crd = {"design": np.arange(P)}
    crd.update({k: ("design", v) for k, v in table.items()})
    crd.update({k: np.asarray(v) for k, v in coords.items()})
    return xr.Dataset(data, coords=crd, attrs=attrs)


def as_json(obj) -> str:
    return json.dumps(obj, sort_keys=True, default=float)
