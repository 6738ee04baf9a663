import os

import jax
import pytest

jax.config.update("jax_enable_x64", True)

# Quick mode for notebooks and scripts executed by the tests.
os.environ.setdefault("ABSORBER_JAX_QUICK", "1")


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)
    yield
