"""The design-study tests (tests/study/) in a pytest process of their own: see
tests/study/conftest.py for why."""

import os
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_the_study_tests_pass_in_a_process_of_their_own():
    env = dict(os.environ, ABSORBER_JAX_STUDY_TESTS="1")
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "0", "-p", "no:randomly",
                          str(ROOT / "tests" / "study")], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=1200)
    assert run.returncode == 0, run.stdout[-6000:] + run.stderr[-3000:]
    assert " passed" in run.stdout, run.stdout[-2000:]
