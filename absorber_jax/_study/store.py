"""A study's store on disk: a zarr store laid out before the first chunk is computed, each
chunk's answer written into its region as it completes, then flagged done.

Layout: dimension ``design`` (every design, in the study's order; each named parameter a
coordinate on it), the question's own dimensions, and ``chunk`` (the computation's
chunks, ``chunk_done`` flags which are complete).  A chunk's values are written before its
flag, so a chunk cut short by a crash is computed again and never read half-written.  The
store's ``fingerprint`` attribute identifies the study (system, designs, question and chunk
size); a store with another one is refused and left untouched.
"""

from __future__ import annotations

import hashlib
import json
import os

import equinox as eqx
import jax
import numpy as np

FILL = {"f8": np.nan, "i4": -1, "bool": False}


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
        import zarr  # noqa: F401
    except ImportError:
        raise ImportError("a study's store needs xarray and zarr: pip install "
                          "'absorber_jax[study]'") from None
    return xr


class Store:
    """The zarr store at ``path`` (a directory)."""

    def __init__(self, path):
        self.path = os.fspath(path)

    def exists(self) -> bool:
        return os.path.exists(self.path)

    def check(self, fp: str) -> None:
        """Refuse (``ValueError``) a store that is not a study's, or another study's."""
        xr = _xr()
        try:
            attrs = xr.open_zarr(self.path, consolidated=False).attrs
        except Exception as err:          # noqa: BLE001 (any unreadable store is refused)
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
        """Lay the store out (``skeleton``: the dataset with its fill values)."""
        encoding = {}
        for name, var in skeleton.data_vars.items():
            chunks = tuple(chunk if d == "design" else (1 if d == "chunk" else n)
                           for d, n in zip(var.dims, var.shape))
            encoding[name] = {"chunks": chunks}
        skeleton.to_zarr(self.path, mode="w-", encoding=encoding, consolidated=False)

    def done(self) -> np.ndarray:
        """Per chunk: whether it is complete."""
        return np.asarray(self._group()["chunk_done"][:], dtype=bool)

    def write(self, c: int, start: int, values: dict, dims: dict) -> None:
        """Chunk ``c``'s answer ``values`` (``{name: (p, ...)}``) into designs
        ``start, start + p``, then its flag (zarr arrays written in place: the store's
        layout is fixed when it is created)."""
        group = self._group()
        p = int(next(iter(values.values())).shape[0])
        for k, v in values.items():
            group[k][start:start + p] = np.asarray(v, dtype=group[k].dtype)
        group["chunk_done"][c:c + 1] = True

    def _group(self):
        if getattr(self, "_open", None) is None:
            import zarr

            self._open = zarr.open_group(self.path, mode="r+")
        return self._open

    def load(self):
        """The whole store as an in-memory dataset."""
        xr = _xr()
        with xr.open_zarr(self.path, consolidated=False) as ds:
            return ds.load()


def skeleton(table, coords, variables, chunk, attrs):
    """The study's dataset before anything is computed: fill values everywhere."""
    xr = _xr()
    P = int(next(iter(table.values())).shape[0])
    C = -(-P // chunk)
    data = {}
    for name, (dims, unit, description, dtype) in variables.items():
        shape = (P,) + tuple(len(coords[d]) for d in dims)
        data[name] = xr.Variable(("design",) + tuple(dims),
                                 np.full(shape, FILL[dtype], dtype=np.dtype(dtype)),
                                 attrs={"units": unit, "long_name": description})
    data["chunk_done"] = xr.Variable(("chunk",), np.zeros(C, bool),
                                     attrs={"long_name": "chunk computed and written"})
    crd = {"design": np.arange(P)}
    crd.update({k: ("design", v) for k, v in table.items()})
    # text coordinates (degree-of-freedom names) as variable-length strings
    crd.update({k: np.asarray(v, dtype=object if np.asarray(v).dtype.kind == "U" else None)
                for k, v in coords.items()})
    ds = xr.Dataset(data, coords=crd, attrs=attrs)
    return ds


def as_json(obj) -> str:
    return json.dumps(obj, sort_keys=True, default=float)
