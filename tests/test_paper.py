"""The paper reproduction runs end to end (small size) and writes every figure."""

import json
import os

import numpy as np

from absorber_jax._cli import main

FIGS = [2, 4, 6, 7, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20]


def test_reproduce_paper_quick(tmp_path):
    out = tmp_path / "figs"
    assert main(["reproduce-paper", "--out", str(out), "--quick"]) == 0
    names = os.listdir(out)
    for n in FIGS:
        assert any(f.startswith(f"fig{n:02d}_") and f.endswith(".png") for f in names), n
    summary = json.loads((out / "summary.json").read_text())
    for name, rec in summary["impact"].items():
        assert 0.1 < rec["x1_amplitude_mm"] < 20, (name, rec)
    for name, rec in summary["friction"].items():
        onset = rec["regime_onset_s"]
        assert onset["jammed"] == 0.0  # starts stuck under a vanishing force
        assert onset["partially gliding"] is not None, name
    assert set(summary["conclusions"]) == {
        "hunt_crossley_attenuates_more_than_linear_and_hertz",
        "stribeck_attenuates_more_than_coulomb", "lugre_attenuates_more_than_dahl",
        "microscopic_vibrate_more_than_macroscopic"}
    assert np.isfinite([r["x1_rms_mm"] for r in summary["friction"].values()]).all()


def test_cli_simulate_writes_csv_and_png(tmp_path):
    csv_path, png = tmp_path / "t.csv", tmp_path / "t.png"
    assert main(["simulate", "--scene", "lugre", "--t1", "0.5", "--out", str(csv_path),
                 "--plot", str(png)]) == 0
    data = np.loadtxt(csv_path, delimiter=",", skiprows=1)
    header = csv_path.read_text().splitlines()[0].split(",")
    assert header[:5] == ["t", "x1", "v1", "x2", "v2"] and "regime" in header
    assert data.shape[0] > 100 and png.stat().st_size > 1000


def test_cli_rejects_bad_scene(capsys):
    assert main(["simulate", "--scene", "nope", "--t1", "0.1"]) == 2
    assert "scene must be one of" in capsys.readouterr().err
