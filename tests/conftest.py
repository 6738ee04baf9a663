import gc
import os

import jax
import pytest

jax.config.update("jax_enable_x64", True)

# Quick mode for notebooks and scripts executed by the tests.
os.environ.setdefault("ABSORBER_JAX_QUICK", "1")


def _memory_maps():
    """The number of memory mappings of this process (Linux; 0 elsewhere)."""
    try:
        with open("/proc/self/maps") as fh:
            return sum(1 for _ in fh)
    except OSError:
        return 0


# Every compiled CPU program keeps memory mappings of its code while it is cached; a pytest
# worker that compiles hundreds of programs approaches the kernel's limit on mappings
# (vm.max_map_count, 65530 by default: workers were seen at 58,000 mid-suite).  A mapping
# that fails at the limit aborts XLA, which fits the aborts seen in workers late in a run
# (Fatal Python error: Aborted, in the compilation cache's serialisation or
# deserialisation), never in a fresh process.  After each test, a worker past MAX_MAPS
# drops JAX's compiled executables (measured: 23,453 mappings down to 1,119) and keeps its
# traced programs: a later test that needs one again lowers it and reads the executable
# back from the persistent cache, without tracing it again (tracing is most of the cost of
# the event-driven programs: tests/integration/test_impacts.py alone, in one process, 239 s
# when every cache was dropped, 195 s when only the executables are, 189 s when none is).
# After each test, not each module: that module compiles enough to reach the limit by
# itself.
MAX_MAPS = 20_000


def _drop_executables():
    """Drop JAX's in-memory compiled executables, keeping its traces (JAX's private caches;
    nothing where this JAX names them otherwise: the caller then drops every cache)."""
    try:
        from jax._src import pjit
        from jax._src.interpreters import pxla
        from jax._src.lib import _jax

        caches = (pxla._cached_compilation.cache_clear, pjit._pjit_lower.cache_clear,
                  pjit._cpp_pjit_cache_fun_only.clear,
                  pjit._cpp_pjit_cache_explicit_attributes.clear,
                  _jax.PjitFunctionCache.clear_all)
    except (ImportError, AttributeError):
        return
    for clear in caches:
        clear()


@pytest.fixture(autouse=True)
def _release_compiled_programs():
    yield
    if _memory_maps() > MAX_MAPS:
        _drop_executables()
        gc.collect()
        if _memory_maps() > MAX_MAPS // 2:     # not released: drop every cache
            jax.clear_caches()
            gc.collect()


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)
    yield


# Tests that run for minutes in a process of their own go first: under pytest-xdist each
# worker takes its share of the tests in collection order, and a two-minute test collected
# last holds one worker alone at the end of the run while the other waits.
FIRST = ("tests/test_studies.py::",)


def pytest_collection_modifyitems(session, config, items):
    items.sort(key=lambda item: not item.nodeid.startswith(FIRST))
