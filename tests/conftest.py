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
# drops JAX's in-memory caches (measured: 19,786 mappings down to 1,251); later tests read
# their programs back from the persistent cache.  After each test, not each module: one
# module of rigid-impact scenes (tests/integration/test_impacts.py) compiles enough to
# reach the limit by itself.
MAX_MAPS = 20_000


@pytest.fixture(autouse=True)
def _release_compiled_programs():
    yield
    if _memory_maps() > MAX_MAPS:
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
