"""Compilation paid once: a second process reads the compiled programs of the first back
from the persistent compilation cache (on by default, absorber_jax._core.cache)."""

import json
import os
import subprocess
import sys
import textwrap

PROGRAM = textwrap.dedent("""
    import json, time
    t0 = time.perf_counter()
    import jax
    hits = []
    jax.monitoring.register_event_listener(
        lambda event, **kw: hits.append(event) if event.endswith("cache_hits") else None)
    import numpy as np
    import absorber_jax as aj
    from absorber_jax._core.cache import compilation_cache_dir
    system, forcing = aj.presets.impact("kelvin_voigt")
    ss = aj.steady_state(system, aj.Harmonic(amplitude=2.0, omega=40.0))
    print(json.dumps({"hits": len(hits), "seconds": time.perf_counter() - t0,
                      "amplitude": float(ss.amplitude), "status": int(ss.status),
                      "dir": str(compilation_cache_dir())}))
""")


def _run(env_extra):
    env = {k: v for k, v in os.environ.items()
           if k not in ("ABSORBER_JAX_CACHE", "ABSORBER_JAX_CACHE_DIR", "EQX_ON_ERROR")}
    env.update(env_extra)
    out = subprocess.run([sys.executable, "-c", PROGRAM], env=env, capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_second_process_reuses_the_compilation(tmp_path):
    cache = tmp_path / "cache"
    first = _run({"ABSORBER_JAX_CACHE_DIR": str(cache)})
    written = sorted(p.name for p in cache.iterdir())
    second = _run({"ABSORBER_JAX_CACHE_DIR": str(cache)})
    print(f"first process {first['seconds']:.1f} s, second {second['seconds']:.1f} s "
          f"({second['hits']} programs read back)")
    assert first["dir"] == str(cache) and first["hits"] == 0
    # the steady-state program (it holds equinox's checks: written only if they are not
    # host callbacks) is among the entries written and read back
    assert any("steady" in name or "solve" in name for name in written), written
    assert second["hits"] >= 1
    assert second["status"] == 0 and second["amplitude"] == first["amplitude"]
    assert second["seconds"] < first["seconds"]


def test_the_cache_can_be_switched_off(tmp_path):
    cache = tmp_path / "cache"
    off = _run({"ABSORBER_JAX_CACHE_DIR": str(cache), "ABSORBER_JAX_CACHE": "0"})
    assert off["dir"] == "None" and off["hits"] == 0
    assert not cache.exists()
