"""Compilation paid once: the time to a first result in a fresh process, with an empty
persistent compilation cache, then again in a second process reading it back, and with the
cache switched off — the README tour's main calls and the Table 1 64-point sweep.

    python scripts/benchmark_cache.py            # prints a table, writes docs/benchmark_cache.json

Each run is a new Python process (imports included in its time); the cache directory is a
fresh temporary one.
"""

import json
import os
import pathlib
import subprocess
import sys
import tempfile
import textwrap

JOBS = {
    "table1_sweep_64": """
        import numpy as np
        system, _ = aj.presets.impact("kelvin_voigt")
        fr = aj.frequency_response(system, np.linspace(20.0, 80.0, 64), amplitude=2.0)
        result = float(np.nanmax(fr.amplitude))
    """,
    "tour": """
        import numpy as np
        system, forcing = aj.presets.impact("kelvin_voigt")
        traj = aj.simulate(system, forcing, 2.0)
        ss = aj.steady_state(system, forcing)
        friction = aj.FrictionAbsorber(m1=1.0, k1=1e4, c1=2.0, m2=0.1, k2=1e3,
                                       normal_force=4.0, friction=aj.Coulomb(mu=0.5))
        ssf = aj.steady_state(friction, aj.Harmonic(amplitude=20.0, omega=70.0))
        result = float(ss.amplitude) + float(ssf.amplitude)
    """,
}


def run(job, env):
    code = "import time\nt0 = time.perf_counter()\nimport absorber_jax as aj\n" + \
        textwrap.dedent(JOBS[job]) + \
        "\nprint('RESULT', time.perf_counter() - t0, result)\n"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=1200)
    if out.returncode != 0:
        raise RuntimeError(out.stderr[-2000:])
    line = [x for x in out.stdout.splitlines() if x.startswith("RESULT")][-1].split()
    return float(line[1]), float(line[2])


def main():
    rows = {}
    for job in JOBS:
        with tempfile.TemporaryDirectory() as cache:
            base = {k: v for k, v in os.environ.items()
                    if k not in ("ABSORBER_JAX_CACHE", "ABSORBER_JAX_CACHE_DIR")}
            on = dict(base, ABSORBER_JAX_CACHE_DIR=cache)
            off = dict(base, ABSORBER_JAX_CACHE="0")
            t_off, r_off = run(job, off)
            t_first, r_first = run(job, on)
            t_second, r_second = run(job, on)
        assert r_first == r_second, (r_first, r_second)
        rows[job] = {"no_cache_s": t_off, "first_process_s": t_first,
                     "second_process_s": t_second, "ratio_first_to_second": t_first / t_second,
                     "same_result": r_first == r_second == r_off}
        print(f"{job}: cache off {t_off:.1f} s, first process {t_first:.1f} s, second "
              f"{t_second:.1f} s ({t_first / t_second:.1f}x), same result: "
              f"{rows[job]['same_result']}")
    out = pathlib.Path(__file__).resolve().parents[1] / "docs" / "benchmark_cache.json"
    out.write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
