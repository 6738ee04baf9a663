"""Scene files: the TOML/JSON loader against the physics it describes
(a closed-form receptance), the two formats against each other, the ``absorber-jax scene``
command's outputs, and field-named errors for bad files.

The sweeps here use 8 frequencies each so that the loaded building and the CLI's run share
one compilation (same system layout, same chunk shape)."""

import csv
import json
import os
import pathlib

import equinox as eqx
import numpy as np
import pytest
from builders import MASSES, RAYLEIGH, STOREYS, TMDS

import absorber_jax as aj
from absorber_jax._io.cli import main
from absorber_jax._io.scene import SceneSettings, load_scene, scene_from_dict, toml_loads

EXAMPLES = os.path.join(pathlib.Path(__file__).resolve().parents[2], "examples")
BUILDING = os.path.join(EXAMPLES, "building_tmds.toml")
BEAM = os.path.join(EXAMPLES, "beam_friction_damper.json")
N_FREQ = 8


def _closed_form(om, tmds=TMDS, amplitude=1.0):
    """Displacement amplitudes of the three floors of the same building with the dampers as
    coordinates of their own, under the base-excitation load (floor masses as weights)."""
    full = aj.shear_building(MASSES, STOREYS, rayleigh=RAYLEIGH).with_tuned_mass_dampers(tmds)
    H = np.asarray(full.receptance(om))[:, :3, :3]
    return np.abs(H @ np.asarray(MASSES)) * amplitude


def test_building_scene_sweep_equals_the_closed_form_receptance():
    system, settings = load_scene(BUILDING)
    # what the file says: the building and the Den Hartog dampers of test_structure
    ref = aj.shear_building(MASSES, STOREYS, rayleigh=RAYLEIGH)
    for f in ("mass", "stiffness", "damping", "dof_map"):
        np.testing.assert_allclose(getattr(system.structure, f), getattr(ref, f), rtol=1e-14)
    assert system.element_names == ("tmd1", "tmd2", "tmd3")
    for e, (dof, m, k, c) in zip(system.elements, TMDS):
        assert e.dof == dof
        np.testing.assert_allclose([e.m, e.k, e.c], [m, k, c], rtol=1e-14)
    assert settings.amplitude == 1.0 and settings.direction == "parallel"
    assert settings.omegas[0] == 10.0 and settings.omegas[-1] == 80.0
    # its sweep (every 8th frequency of the file's grid) against the closed form
    om = settings.omegas[::8][:N_FREQ]
    fr = aj.frequency_response(system, om, amplitude=settings.amplitude)
    assert fr.ok.all() and fr.stable.all()
    X = _closed_form(om)
    for j in range(3):
        np.testing.assert_allclose(fr.dof(f"floor{j + 1}", "harmonic"), X[:, j], rtol=1e-6)
    np.testing.assert_allclose(fr.amplitude, X[:, 2], rtol=1e-6)     # observe = floor3


MATRICES_TOML = """
title = "two masses, every element kind"
[structure]
type = "matrices"
mass = [[1.0, 0.0], [0.0, 0.5]]
stiffness = [[2.0e3, -1.0e3], [-1.0e3, 1.0e3]]
rayleigh = [0.1, 1e-4]
dof_names = ["a", "b"]
modal = {n_modes = 2, dofs = ["b", "a"]}
[[elements]]
type = "impact"
dof = "b"
m = 0.05
gap = 1e-3
contact = {law = "hunt_crossley", stiffness = 1e5, damping = 50.0, eps = 1e-6}
[[elements]]
type = "friction"
dof = "a"
m = 0.02
k = 30.0
c = 0.1
normal_force = 0.5
friction = {law = "lugre", mu_c = 0.3, mu_s = 0.4, v_s = 0.01, sigma0 = 1e4, sigma1 = 10.0}
name = "brake"
[[elements]]
type = "contact"
dof = "a"
other = "b"
gap = 2e-3
sides = "two"
direction = -1
contact = {law = "hertz", stiffness = 1e6, damping = 5.0, adhesive = false}
[[elements]]
type = "friction_contact"
dof = "b"
normal_force = 0.1
friction = {law = "stribeck", mu_c = 0.2, mu_s = 0.3, v_s = 0.01, eps = 1e-4}
[[elements]]
type = "tmd"
dof = "b"
m = 0.1
k = 40.0
c = 0.2
[load]
dofs = {a = 1.0, b = 0.5}
amplitude = 2.0
[observe]
dofs = {b = 1.0, a = -1.0}
[sweep]
omegas = [20.0, 30.0, 45.0]
direction = "up"
method = "marching"
[simulate]
omega = 31.0
periods = 12
"""

MATRICES_JSON = """{
  "title": "two masses, every element kind",
  "structure": {"type": "matrices", "mass": [[1, 0], [0, 0.5]],
                "stiffness": [[2000, -1000], [-1000, 1000]], "rayleigh": [0.1, 0.0001],
                "dof_names": ["a", "b"], "modal": {"n_modes": 2, "dofs": ["b", "a"]}},
  "elements": [
    {"type": "impact", "dof": "b", "m": 0.05, "gap": 0.001,
     "contact": {"law": "hunt_crossley", "stiffness": 100000, "damping": 50, "eps": 1e-6}},
    {"type": "friction", "dof": "a", "m": 0.02, "k": 30, "c": 0.1, "normal_force": 0.5,
     "name": "brake", "friction": {"law": "lugre", "mu_c": 0.3, "mu_s": 0.4, "v_s": 0.01,
                                   "sigma0": 10000, "sigma1": 10}},
    {"type": "contact", "dof": "a", "other": "b", "gap": 0.002, "sides": "two",
     "direction": -1,
     "contact": {"law": "hertz", "stiffness": 1e6, "damping": 5, "adhesive": false}},
    {"type": "friction_contact", "dof": "b", "normal_force": 0.1,
     "friction": {"law": "stribeck", "mu_c": 0.2, "mu_s": 0.3, "v_s": 0.01, "eps": 1e-4}},
    {"type": "tmd", "dof": "b", "m": 0.1, "k": 40, "c": 0.2}
  ],
  "load": {"dofs": {"a": 1, "b": 0.5}, "amplitude": 2},
  "observe": {"dofs": {"b": 1, "a": -1}},
  "sweep": {"omegas": [20, 30, 45], "direction": "up", "method": "marching"},
  "simulate": {"omega": 31, "periods": 12}
}"""


def _same(a, b):
    (sa, ta), (sb, tb) = a, b
    assert type(sa) is type(sb)
    assert bool(eqx.tree_equal(sa, sb)), "systems differ"
    assert ta == tb, (ta, tb)


def test_toml_and_json_give_identical_systems(tmp_path):
    # hand-written twins, covering every structure option and element kind used here
    (tmp_path / "m.toml").write_text(MATRICES_TOML)
    (tmp_path / "m.json").write_text(MATRICES_JSON)
    a, b = load_scene(tmp_path / "m.toml"), load_scene(tmp_path / "m.json")
    _same(a, b)
    system, settings = a
    assert system.element_names == ("impact1", "brake", "contact1", "friction_contact1",
                                    "tmd1")
    assert system.structure.dof_names == ("b", "a")       # the modal dofs' order
    assert system.parameter_names()[:3] == ["impact1.m", "impact1.gap", "impact1.stiffness"]
    np.testing.assert_allclose(system.load, [0.5, 1.0])
    np.testing.assert_allclose(system.observe, [1.0, -1.0])
    assert settings == SceneSettings(amplitude=2.0, omegas=np.array([20.0, 30.0, 45.0]),
                                     direction="up", method="marching", simulate_omega=31.0,
                                     simulate_periods=12,
                                     title="two masses, every element kind")
    # the shipped examples, converted to the other format, load to the same systems
    with open(BUILDING, encoding="utf-8") as fh:
        (tmp_path / "b.json").write_text(json.dumps(toml_loads(fh.read())))
    _same(load_scene(BUILDING), load_scene(tmp_path / "b.json"))
    with open(BEAM) as fh:
        beam = json.load(fh)
    _same(load_scene(BEAM), scene_from_dict(beam))
    bsys, bset = load_scene(BEAM)
    assert bsys.structure.dof_names == ("w4", "w8") and bsys.structure.num_coords == 3
    assert bsys.element_names == ("friction1",) and len(bset.omegas) == 24


def test_cli_scene_writes_dof_named_csv_summary_and_figures(tmp_path, capsys):
    out = tmp_path / "out"
    k_new = 5.0e4
    rc = main(["scene", BUILDING, "--out", str(out), "--set", f"tmd1.k={k_new}",
               "--omega", f"15:25:{N_FREQ}", "--simulate"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "floor3" in printed and "peak" in printed
    for f in ("frequency_response.csv", "frequency_response.png", "summary.json",
              "trajectory.csv", "trajectory.png"):
        assert (out / f).stat().st_size > 0, f
    with open(out / "frequency_response.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == N_FREQ
    for name in ("floor1", "floor2", "floor3", "tmd1", "tmd2", "tmd3"):
        assert f"dof amplitude {name} [m]" in rows[0] and f"dof harmonic {name} [m]" in rows[0]
    # --set went through replace_params: the closed form with the changed damper
    om = np.linspace(15.0, 25.0, N_FREQ)
    tmds = [("floor3", TMDS[0][1], k_new, TMDS[0][3])] + list(TMDS[1:])
    X = _closed_form(om, tmds)
    got = np.array([float(r["dof harmonic floor3 [m]"]) for r in rows])
    np.testing.assert_allclose(got, X[:, 2], rtol=1e-6)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["parameters"]["tmd1.k"] == k_new and summary["set"] == {"tmd1.k": k_new}
    assert summary["failed"] == 0 and summary["failures"] == []
    i = int(np.argmax(X[:, 2]))
    assert summary["observable_peak"]["omega"] == pytest.approx(om[i])
    assert summary["observable_peak"]["amplitude"] == pytest.approx(X[i, 2], rel=1e-6)
    assert set(summary["dof_peaks"]) == {"floor1", "floor2", "floor3", "tmd1", "tmd2", "tmd3"}
    assert summary["timing_s"]["sweep"] > 0
    sim = summary["simulation"]
    assert sim["omega"] == pytest.approx(om[i])
    with open(out / "trajectory.csv") as fh:
        header = next(csv.reader(fh))
    assert header == ["t [s]", "floor1 [m]", "floor2 [m]", "floor3 [m]", "tmd1 [m]", "tmd2 [m]",
                      "tmd3 [m]", "force tmd1 [N]", "force tmd2 [N]", "force tmd3 [N]"]


def _building_dict():
    with open(BUILDING, encoding="utf-8") as fh:
        return toml_loads(fh.read())


def _impact(**over):
    e = {"type": "impact", "dof": "floor2", "m": 10.0, "gap": 2e-3,
         "contact": {"law": "kelvin_voigt", "stiffness": 1e6, "damping": 100.0}}
    e.update(over)
    return {k: v for k, v in e.items() if v is not None}


def _edit(fn):
    d = _building_dict()
    fn(d)
    return d


BAD = [
    ("unknown element type",
     lambda d: d["elements"][1].update(type="tuned_mass"),
     r"scene\.elements\[1\]\.type must be one of tmd, impact, friction"),
    ("missing gap",
     lambda d: d["elements"].append(_impact(gap=None)),
     r"scene\.elements\[3\]\.gap is required"),
    ("unknown dof",
     lambda d: d["elements"][0].update(dof="floor9"),
     r"scene\.elements\[0\]\.dof must be a degree of freedom, one of floor1, floor2, floor3"),
    ("unknown element key",
     lambda d: d["elements"][2].update(mass=3.0),
     r"scene\.elements\[2\]\.mass: unknown key; allowed here: type, dof, m, k, c, name"),
    ("unknown top-level key",
     lambda d: d.update(sweeps={}),
     r"scene\.sweeps: unknown key"),
    ("unknown structure type",
     lambda d: d["structure"].update(type="frame"),
     r"scene\.structure\.type must be one of shear_building, cantilever_beam"),
    ("structure key of another type",
     lambda d: d["structure"].update(n_elements=4),
     r"scene\.structure\.n_elements: unknown key"),
    ("missing structure field",
     lambda d: d["structure"].pop("masses"),
     r"scene\.structure\.masses is required"),
    ("storeys do not match floors",
     lambda d: d["structure"].update(storey_stiffnesses=[1e6, 1e6]),
     r"scene\.structure\.storey_stiffnesses must hold one value per floor"),
    ("two damping models",
     lambda d: d["structure"].update(modal_damping=0.02),
     r"scene\.structure: give at most one of rayleigh, modal_damping"),
    ("negative mass",
     lambda d: d["elements"][0].update(m=-1.0),
     r"scene\.elements\[0\]\.m must be in \(0, inf\)"),
    ("string for a number",
     lambda d: d["elements"][0].update(k="stiff"),
     r"scene\.elements\[0\]\.k must be a finite number"),
    ("unknown contact law",
     lambda d: d["elements"].append(_impact(contact={"law": "kelvin", "stiffness": 1.0,
                                                     "damping": 0.0})),
     r"scene\.elements\[3\]\.contact\.law must be one of kelvin_voigt, hertz, hunt_crossley"),
    ("Coulomb without eps",
     lambda d: d["elements"].append({"type": "friction_contact", "dof": "floor1",
                                     "normal_force": 1.0,
                                     "friction": {"law": "coulomb", "mu": 0.5}}),
     r"scene\.elements\[3\]\.friction\.eps is required"),
    ("load on an unknown dof",
     lambda d: d["load"]["dofs"].update(roof=1.0),
     r"scene\.load\.dofs\.roof: not a degree of freedom"),
    ("load both dof and dofs",
     lambda d: d["load"].update(dof="floor1"),
     r"scene\.load: give exactly one of dof"),
    ("missing load amplitude",
     lambda d: d["load"].pop("amplitude"),
     r"scene\.load\.amplitude is required"),
    ("no observe for a distributed load",
     lambda d: d.pop("observe"),
     r"scene\.observe is required"),
    ("sweep not increasing",
     lambda d: d["sweep"].update(omegas=[30.0, 20.0]),
     r"scene\.sweep\.omegas must be strictly increasing"),
    ("sweep range",
     lambda d: d["sweep"]["omegas"].update(num=1),
     r"scene\.sweep\.omegas\.num must be an integer >= 2"),
    ("bad direction",
     lambda d: d["sweep"].update(direction="sideways"),
     r"scene\.sweep\.direction must be one of parallel, up, down, both"),
    ("modal reduction at an unknown dof",
     lambda d: d["structure"].update(modal={"n_modes": 2, "dofs": ["roof"]}),
     r"scene\.structure\.modal\.dofs\[0\] must be a degree of freedom"),
    ("element named like a dof",
     lambda d: d["elements"][0].update(name="floor1"),
     r"scene\.elements\[0\]\.name must differ from the degrees of freedom"),
]


@pytest.mark.parametrize("fmt", ["toml", "json"])
@pytest.mark.parametrize("what, edit, match", BAD, ids=[b[0] for b in BAD])
def test_bad_scene_files_raise_a_value_error_naming_the_field(tmp_path, what, edit, match, fmt):
    d = _edit(edit)
    path = tmp_path / f"bad.{fmt}"
    if fmt == "json":
        path.write_text(json.dumps(d))
    else:
        path.write_text(_to_toml(d))
    with pytest.raises(ValueError, match=match):
        load_scene(path)


def _to_toml(d):
    """Just enough of a TOML writer for these scenes (inline tables throughout)."""
    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, (int, float)):
            return repr(v)
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return "{" + ", ".join(f"{json.dumps(k)} = {val(x)}" for k, x in v.items()) + "}"

    lines = [f"{json.dumps(k)} = {val(v)}" for k, v in d.items()
             if not isinstance(v, (dict, list)) or (isinstance(v, list) and not v)]
    for k, v in d.items():
        if isinstance(v, dict):
            lines += [f"[{k}]"] + [f"{json.dumps(kk)} = {val(x)}" for kk, x in v.items()]
        elif isinstance(v, list) and v:
            for item in v:
                lines += [f"[[{k}]]"] + [f"{json.dumps(kk)} = {val(x)}" for kk, x in item.items()]
    return "\n".join(lines) + "\n"


def test_unreadable_files_and_the_cli_report_the_problem(tmp_path, capsys):
    (tmp_path / "broken.toml").write_text("[structure\ntype = 1\n")
    with pytest.raises(ValueError, match="not valid TOML"):
        load_scene(tmp_path / "broken.toml")
    with pytest.raises(ValueError, match=r"must end in \.toml or \.json"):
        load_scene(tmp_path / "scene.yaml")
    with pytest.raises(ValueError, match="cannot read scene file"):
        load_scene(tmp_path / "missing.json")
    bad = _edit(lambda d: d["elements"][0].update(gapp=1e-3))
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    assert main(["scene", str(tmp_path / "bad.json"), "--out", str(tmp_path / "o")]) == 2
    assert "scene.elements[0].gapp: unknown key" in capsys.readouterr().err
    # --set with a parameter the scene does not have: named, with the known ones
    assert main(["scene", BUILDING, "--out", str(tmp_path / "o"), "--set", "tmd4.k=1"]) == 2
    err = capsys.readouterr().err
    assert "tmd4.k" in err and "tmd1.k" in err
    # a scene without [sweep] needs --omega
    nosweep = _edit(lambda d: d.pop("sweep"))
    (tmp_path / "nosweep.json").write_text(json.dumps(nosweep))
    assert main(["scene", str(tmp_path / "nosweep.json"), "--out", str(tmp_path / "o")]) == 2
    assert "--omega" in capsys.readouterr().err
