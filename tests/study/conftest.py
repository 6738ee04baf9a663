"""The study tests run in a pytest process of their own (tests/test_studies.py starts it
with ABSORBER_JAX_STUDY_TESTS=1), not in the suite's workers: in a worker that had run
them, a later test's compiled program (an attractor map) made JAX abort while
serialising it for the persistent compilation cache (``Fatal Python error: Aborted`` in
``compilation_cache.put_executable_and_time``; three full runs of the suite, never with
these tests left out).  Collected directly (``pytest tests/study``) they run as usual."""

import os
import pathlib

HERE = pathlib.Path(__file__).resolve().parent


def pytest_ignore_collect(collection_path, config):
    if os.environ.get("ABSORBER_JAX_STUDY_TESTS") == "1":
        return None
    # the suite's run (its paths above this folder): leave them to tests/test_studies.py
    args = [pathlib.Path(a).resolve() for a in config.args]
    inside = any(a == HERE or HERE in a.parents for a in args)
    return None if inside else True
