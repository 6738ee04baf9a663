"""Design studies: sets of designs, the questions asked of each, and their persistent,
resumable computation, locally or on a Dask cluster."""
