"""The ``absorber-jax study`` command on a scene file's [study] table: outputs, resumption
and field-named errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from absorber_jax._io.cli import main
from absorber_jax._io.scene import scene_from_dict

pytest.importorskip("xarray")

SCENE = {
    "structure": {"type": "matrices", "mass": [[1.0]], "stiffness": [[1e4]],
                  "damping": [[2.0]]},
    "elements": [{"type": "tmd", "dof": "x1", "name": "tmd", "m": 0.05, "k": 453.5,
                  "c": 1.21}],
    "load": {"dof": "x1", "amplitude": 1.0},
    "sweep": {"omegas": {"start": 80.0, "stop": 120.0, "num": 6}},
    "study": {"question": "frequency_response", "chunk": 2,
              "grid": {"tmd.k": [440.0, 453.5, 470.0], "tmd.c": [1.0, 1.5]}},
}


def test_study_command_writes_outputs_and_resumes(tmp_path):
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(SCENE))
    out = tmp_path / "out"
    assert main(["study", "--file", str(path), "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["designs"] == 6 and summary["chunks_computed"] == 3
    assert summary["failed_points"] == 0
    rows = (out / "designs.csv").read_text().splitlines()
    assert rows[0].startswith("tmd.k [N/m],tmd.c [N s/m],peak [m]") and len(rows) == 7
    # the peak of each row is the largest amplitude of the closed-form receptance on the grid
    w = np.linspace(80.0, 120.0, 6)
    for row in rows[1:]:
        k, c, peak = (float(v) for v in row.split(",")[:3])
        z = k + 1j * w * c
        x = np.abs(1.0 / (1e4 - w**2 + 2j * w + z * (-0.05 * w**2) / (z - 0.05 * w**2)))
        assert abs(peak / x.max() - 1) < 1e-6
    assert (out / "study.png").stat().st_size > 0
    assert main(["study", "--file", str(path), "--out", str(out), "--quiet"]) == 0
    again = json.loads((out / "summary.json").read_text())
    assert again["chunks_computed"] == 0 and again["chunks_reused"] == 3


@pytest.mark.parametrize("study, match", [
    ({"question": "exact_peak", "band": [80.0, 120.0], "grid": {"k9": [1.0]}},
     r"scene\.study\.grid\.k9: unknown parameter"),
    ({"question": "exact_peak", "band": [80.0, 120.0], "grid": {"tmd.k": [1.0]},
      "designs": {"tmd.k": [1.0]}}, "exactly one of"),
    ({"question": "exact_peak", "monte_carlo": {"samples": 4,
                                                "tmd.k": {"uniform": [1.0]}}},
     r"scene\.study\.monte_carlo\.tmd\.k\.uniform must be two numbers"),
    ({"question": "peak", "grid": {"tmd.k": [1.0]}}, r"scene\.study\.question"),
    ({"question": "exact_peak", "grid": {"tmd.k": [1.0]}}, r"scene\.study\.band"),
])
def test_bad_study_tables_name_the_field(study, match):
    with pytest.raises(ValueError, match=match):
        scene_from_dict(dict(SCENE, study=study))
