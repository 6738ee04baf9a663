"""Structural matrices from files: Matrix Market and NumPy formats."""

from __future__ import annotations

import os

import numpy as np
import scipy.io
import scipy.sparse as sp


def read_matrix(path):
    """A matrix from a file, by its extension:

    - ``.mtx`` (Matrix Market, as exported by most finite-element codes; ``symmetric``
      storage expanded): a scipy CSR matrix;
    - ``.npz``: a scipy sparse matrix saved by ``scipy.sparse.save_npz`` (CSR), or a NumPy
      archive holding exactly one array (dense);
    - ``.npy``: a dense NumPy array.

    Units are the file's: mass [kg], stiffness [N/m], damping [N s/m] for the structures
    here.  Feed it to [`structure_from_matrices`][absorber_jax.structure_from_matrices]
    (up to a few thousand degrees of freedom) or to
    [`craig_bampton`][absorber_jax.craig_bampton] (any size)."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ValueError(f"read_matrix.path: no such file {path!r}")
    ext = os.path.splitext(path)[1].lower()
    if ext == ".mtx":
        A = scipy.io.mmread(path)
        return sp.csr_matrix(A) if sp.issparse(A) else np.asarray(A, dtype=float)
    if ext == ".npy":
        return np.asarray(np.load(path, allow_pickle=False), dtype=float)
    if ext == ".npz":
        try:
            return sp.load_npz(path).tocsr()
        except ValueError:
            pass
        with np.load(path, allow_pickle=False) as z:
            if len(z.files) != 1:
                raise ValueError(f"read_matrix.path: {path!r} holds {len(z.files)} arrays "
                                 f"({', '.join(z.files)}); save one matrix per file")
            return np.asarray(z[z.files[0]], dtype=float)
    raise ValueError(f"read_matrix.path: unknown format {ext!r}; use .mtx (Matrix Market), "
                     ".npz or .npy")
