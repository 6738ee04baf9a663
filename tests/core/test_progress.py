"""Progress bars count points and say when they are compiling."""

import numpy as np

import absorber_jax as aj
from absorber_jax._core.progress import PointProgress


def test_point_progress_says_compiling_until_the_first_points(capsys):
    with PointProgress(6, "sweep", True) as bar:
        assert bar.bar.desc.startswith("sweep (compiling)")
        bar.update(4)
        assert bar.bar.desc.startswith("sweep") and "compiling" not in bar.bar.desc
        bar.update(2)
        assert bar.bar.n == 6
    assert "6/6" in capsys.readouterr().err


def test_a_sweep_counts_its_points(capsys):
    system, _ = aj.presets.impact("kelvin_voigt")
    aj.frequency_response(system, np.linspace(40.0, 50.0, 5), amplitude=2.0, progress=True,
                          floquet=False)
    err = capsys.readouterr().err
    assert "sweep (compiling)" in err and "5/5" in err and "pt/s" in err
