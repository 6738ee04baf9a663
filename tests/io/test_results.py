"""Results carry their units and labels: CSV headers with SI units that read back to the
result arrays, ``to_xarray`` / ``to_dataframe`` with units, long names and status names, NaN
(not zero) at failed points in the arrays and in the plotted lines, plot labels from the
observable's name and unit, legends whose markers are the plotted ones, a help text for every
CLI option, and a hint of what to try for every failure code."""

import argparse
import csv
import sys

import matplotlib
import numpy as np
import pytest
from builders import HARD, MASSES, RAYLEIGH, STOREYS, TMDS, hardening

import absorber_jax as aj
from absorber_jax._core.status import MEASURED
from absorber_jax._core.units import signals_of, split_column
from absorber_jax._io.cli import build_parser
from absorber_jax._io.plots import RESPONSE_GID

matplotlib.use("Agg")

OMEGAS = np.linspace(40.0, 70.0, 8)


@pytest.fixture(scope="module")
def kv_sweep():
    """Table 1 (Kelvin–Voigt impact absorber) with a step budget so small that the long
    low-frequency periods exhaust it (MAX_STEPS) and the high ones do not; no retry."""
    system, _ = aj.presets.impact("kelvin_voigt")
    frf = aj.frequency_response(system, OMEGAS, amplitude=2.0, max_steps=120, retry=False)
    failed = np.asarray(frf.status) != 0
    assert failed.any() and (~failed).any()
    return system, frf


@pytest.fixture(scope="module")
def building_sweep():
    """A three-storey shear building loaded at floor 1, observed at floor 3, carrying one
    tuned mass damper at floor 3 (linear: every point solves)."""
    dof, m, k, c = TMDS[0]
    st = aj.shear_building(MASSES, STOREYS, rayleigh=RAYLEIGH)
    system = aj.StructuralSystem(st, [aj.TunedMassDamper(dof, m=m, k=k, c=c)], load="floor1",
                                 observe="floor3")
    frf = aj.frequency_response(system, np.linspace(15.0, 25.0, 6), amplitude=1e3)
    assert np.all(frf.status == 0), frf.failures()
    return system, frf


def _read_csv(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def _column(header, rows, name):
    j = header.index(name)
    return np.array([float(r[j]) for r in rows])


def test_csv_headers_carry_si_units_and_read_back_to_the_arrays(kv_sweep, tmp_path):
    _, frf = kv_sweep
    path = tmp_path / "frf.csv"
    frf.to_csv(path)
    header, rows = _read_csv(path)
    assert len(rows) == OMEGAS.size and len(set(header)) == len(header)
    expected = {
        "omega [rad/s]": frf.omegas,
        "amplitude x1 [m]": frf.amplitude,
        "rms x1 [m]": frf.rms,
        "harmonic x1 [m]": frf.harmonic,
        "amplitude x2 - x1 [m]": frf.absorber_amplitude,      # the relative motion
        "rms x2 - x1 [m]": frf.absorber_rms,
        "dof amplitude x1 [m]": frf.dof("x1"),
        "dof amplitude x2 [m]": frf.dof("x2"),                # the absorber's own motion
        "dof harmonic x2 [m]": frf.dof("x2", "harmonic"),
        "impacts per period [1]": frf.impacts,
        "status": frf.status,
        "stable": frf.stable,
        "period multiple [1]": frf.period_multiple,
    }
    for name, values in expected.items():
        got = _column(header, rows, name)
        np.testing.assert_array_equal(got, np.asarray(values, dtype=float), err_msg=name)
    # every header of a physical quantity names its unit; lengths are metres (SI)
    units = {split_column(h)[0]: split_column(h)[1] for h in header}
    assert units["omega"] == "rad/s"
    assert all(u == "m" for n, u in units.items() if "amplitude" in n or "rms" in n)
    text = [r[header.index("status text")] for r in rows]
    assert text[0] == "integrator reached max_steps" and text[-1] == "success"


def test_stroke_is_the_relative_motion_and_dof_x2_the_absolute_one(kv_sweep):
    """What the columns claim, against an independent integration of one solved orbit over
    a period: ``absorber_amplitude`` is half the peak-to-peak of ``x2 - x1``,
    ``dof amplitude x2`` that of ``x2`` itself."""
    system, frf = kv_sweep
    i = int(np.flatnonzero(np.asarray(frf.status) == 0)[0])
    w = float(frf.omegas[i])
    T = 2 * np.pi / w
    tr = aj.simulate(system, aj.Harmonic(amplitude=2.0, omega=w), T, y0=frf.states[i],
                     ts=np.linspace(0.0, T, 4001), rtol=1e-10, atol=1e-14)
    x1, x2 = np.asarray(tr.x1), np.asarray(tr.x2)
    half = lambda y: 0.5 * (y.max() - y.min())  # noqa: E731
    np.testing.assert_allclose(frf.absorber_amplitude[i], half(x2 - x1), rtol=1e-4)
    np.testing.assert_allclose(frf.dof("x2")[i], half(x2), rtol=1e-4, atol=1e-12)
    np.testing.assert_allclose(frf.amplitude[i], half(x1), rtol=1e-4)
    # on this orbit the absorber floats at rest: its own motion ~0, its stroke ~x1's
    assert frf.dof("x2")[i] < 1e-3 * frf.absorber_amplitude[i]


def test_failed_points_are_nan_in_the_arrays_and_break_the_plotted_line(kv_sweep):
    _, frf = kv_sweep
    failed = np.asarray(frf.status) != 0
    for field in MEASURED:
        a = np.asarray(getattr(frf.steady, field))
        assert np.all(np.isnan(a[failed])), field
        assert np.all(np.isfinite(a[~failed])), field
    assert not np.any(np.asarray(frf.amplitude)[failed] == 0.0)
    ax = aj.plot_frequency_response(frf)
    line = [ln for ln in ax.lines if ln.get_gid() == RESPONSE_GID]
    assert len(line) == 1
    y = np.asarray(line[0].get_ydata(), dtype=float)
    assert np.all(np.isnan(y[failed])) and np.all(np.isfinite(y[~failed]))
    np.testing.assert_allclose(y[~failed], 1e3 * frf.amplitude[~failed])      # shown in mm
    # failed points: red crosses at their frequencies, on the bottom edge of the axes
    crosses = [ln for ln in ax.lines if ln.get_marker() == "x"]
    assert len(crosses) == 1 and crosses[0].get_color() == "red"
    np.testing.assert_array_equal(crosses[0].get_xdata(), frf.omegas[failed])
    assert crosses[0].get_transform() == ax.get_xaxis_transform()
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("failed" in t for t in labels)
    assert not any("parallel" in t for t in labels)            # no sweep jargon
    _legend_matches_artists(ax)
    matplotlib.pyplot.close(ax.figure)


def _legend_matches_artists(ax):
    """Every legend entry's marker, face, colour and line style are its artist's."""
    leg = ax.get_legend()
    by_label = {a.get_label(): a for a in ax.lines}
    for handle, text in zip(leg.legend_handles, leg.get_texts()):
        artist = by_label[text.get_text()]
        for prop in ("marker", "markerfacecolor", "color", "linestyle"):
            assert matplotlib.artist.getp(handle, prop) == matplotlib.artist.getp(artist, prop), (
                text.get_text(), prop)


def test_to_xarray_and_to_dataframe_hold_the_arrays_with_units_and_names(kv_sweep, tmp_path):
    system, frf = kv_sweep
    ds = frf.to_xarray()
    np.testing.assert_array_equal(ds["omega"].values, frf.omegas)
    assert ds["omega"].attrs["units"] == "rad/s"
    for field in ("amplitude", "rms", "harmonic", "absorber_amplitude", "residual"):
        np.testing.assert_array_equal(ds[field].values, np.asarray(getattr(frf, field)))
    assert ds["amplitude"].attrs["units"] == "m" and "x1" in ds["amplitude"].attrs["long_name"]
    stroke = ds["absorber_amplitude"].attrs["long_name"]
    assert "x2 - x1" in stroke and "relative" in stroke
    assert list(ds["dof"].values) == ["x1", "x2"]
    np.testing.assert_array_equal(ds["dof_amplitude"].sel(dof="x2").values, frf.dof("x2"))
    assert "absolute" in ds["dof_amplitude"].attrs["long_name"]
    np.testing.assert_array_equal(ds["state"].values, np.asarray(frf.states))
    assert list(ds["component"].values) == ["x1", "v1", "x2", "v2"]
    assert list(ds["component_unit"].values) == ["m", "m/s", "m", "m/s"]
    np.testing.assert_array_equal(ds["status"].values, frf.status)
    assert "max_steps" in ds["status"].attrs["flag_meanings"].split()
    names = ds["status_name"].values
    assert set(names[np.asarray(frf.status) != 0]) == {"MAX_STEPS"}
    assert set(names[np.asarray(frf.status) == 0]) == {"SUCCESS"}
    # the batched SteadyState on its own, named after its system
    ss = frf.steady.to_xarray(system)
    assert ss["amplitude"].dims == ("point",) and ss["state"].dims == ("point", "component")
    np.testing.assert_array_equal(ss["absorber_amplitude"].values, frf.absorber_amplitude)
    assert ss["absorber_amplitude"].attrs == ds["absorber_amplitude"].attrs
    # the data frame is the CSV's table
    df = frf.to_dataframe()
    path = tmp_path / "frf.csv"
    frf.to_csv(path)
    header, rows = _read_csv(path)
    assert list(df.columns) == header
    np.testing.assert_array_equal(df["amplitude x1 [m]"].to_numpy(),
                                  _column(header, rows, "amplitude x1 [m]"))


def test_design_grid_dataset_has_design_and_omega_coordinates():
    system, _ = aj.presets.impact("kelvin_voigt")
    om = np.array([55.0, 60.0, 65.0, 70.0])
    gaps = np.array([1e-3, 2e-3])
    frf = aj.frequency_response(system, om, amplitude=2.0, params={"gap": gaps})
    ds = frf.to_xarray()
    assert ds["amplitude"].dims == ("design", "omega")
    np.testing.assert_array_equal(ds["gap"].values, gaps)
    assert ds["gap"].attrs["units"] == "m" and ds["gap"].dims == ("design",)
    np.testing.assert_array_equal(ds["amplitude"].values, frf.amplitude)
    df = frf.to_dataframe()
    assert len(df) == gaps.size * om.size
    np.testing.assert_array_equal(df["gap [m]"].to_numpy(), np.repeat(gaps, om.size))
    np.testing.assert_array_equal(df["omega [rad/s]"].to_numpy(), np.tile(om, gaps.size))


def test_structure_labels_come_from_the_observed_floor(building_sweep, tmp_path):
    system, frf = building_sweep
    sig = frf.signals
    assert (sig.observable, sig.observable_unit, sig.stroke) == ("floor3", "m", "tmd1 - floor3")
    ax = aj.plot_frequency_response(frf)
    ylabel = ax.get_ylabel()
    assert "floor3" in ylabel and "[mm]" in ylabel and "primary" not in ylabel
    assert "[rad/s]" in ax.get_xlabel()
    matplotlib.pyplot.close(ax.figure)
    ax = aj.plot_frequency_response(frf, dof="floor1", field="harmonic")
    assert "floor1" in ax.get_ylabel() and "[mm]" in ax.get_ylabel()
    matplotlib.pyplot.close(ax.figure)
    path = tmp_path / "b.csv"
    frf.to_csv(path)
    header, rows = _read_csv(path)
    np.testing.assert_array_equal(_column(header, rows, "amplitude floor3 [m]"), frf.amplitude)
    np.testing.assert_array_equal(_column(header, rows, "dof amplitude tmd1 [m]"),
                                  frf.dof("tmd1"))
    np.testing.assert_array_equal(_column(header, rows, "amplitude tmd1 - floor3 [m]"),
                                  frf.absorber_amplitude)
    # a weighted observable (an inter-storey drift) and a rotation are named as such
    drift = aj.StructuralSystem(system.structure, system.elements, load="floor1",
                                observe={"floor3": 1.0, "floor2": -1.0})
    assert signals_of(drift).observable == "floor3 - floor2"
    beam = aj.cantilever_beam(2, length=1.0, EI=1e3, rho_A=1.0, rayleigh=(0.1, 1e-4))
    tip = aj.StructuralSystem(beam, load="w2", observe="th2")
    assert (signals_of(tip).observable, signals_of(tip).observable_unit) == ("th2", "rad")
    assert signals_of(tip).dof_unit("w2") == "m"


def test_trajectory_dataset_and_csv_carry_time_and_state_units(tmp_path):
    system, forcing = aj.presets.impact("kelvin_voigt")
    tr = aj.simulate(system, forcing, 0.2)
    ds = tr.to_xarray()
    np.testing.assert_array_equal(ds["time"].values, tr.ts)
    assert ds["time"].attrs["units"] == "s"
    for j, (name, unit) in enumerate((("x1", "m"), ("v1", "m/s"), ("x2", "m"), ("v2", "m/s"))):
        np.testing.assert_array_equal(ds[name].values, np.asarray(tr.ys)[:, j])
        assert ds[name].attrs["units"] == unit
    np.testing.assert_array_equal(ds["coupling_force"].values, tr.coupling_force)
    assert ds["coupling_force"].attrs["units"] == "N"
    np.testing.assert_allclose(ds["dof_displacement"].sel(dof="x2").values, tr.x2, atol=1e-15)
    assert ds.attrs["status_name"] == "SUCCESS" and int(ds["status"]) == 0
    path = tmp_path / "t.csv"
    tr.to_csv(path)
    header, rows = _read_csv(path)
    assert header[:5] == ["t [s]", "x1 [m]", "v1 [m/s]", "x2 [m]", "v2 [m/s]"]
    np.testing.assert_array_equal(_column(header, rows, "x2 [m]"), tr.x2)
    np.testing.assert_array_equal(_column(header, rows, "coupling force [N]"),
                                  tr.coupling_force)
    assert len(tr.to_dataframe()) == tr.ts.shape[0]


def test_branch_and_attractor_map_datasets_and_branch_plot():
    system = hardening()
    br = aj.continuation(system, aj.Harmonic(amplitude=HARD["F0"], omega=0.8), "omega",
                         bounds=(0.8, 1.6))
    ds = br.to_xarray()
    np.testing.assert_array_equal(ds["omega"].values, br.values)
    assert ds["omega"].dims == ("point",) and ds["omega"].attrs["units"] == "rad/s"
    np.testing.assert_array_equal(ds["amplitude"].values, br.amplitude)
    assert ds["amplitude"].attrs["units"] == "m"
    assert list(ds["bifurcation_kind"].values) == [b.kind for b in br.bifurcations]
    np.testing.assert_array_equal(ds["bifurcation_value"].values,
                                  [b.value for b in br.bifurcations])
    df = br.to_dataframe()
    np.testing.assert_array_equal(df["omega [rad/s]"].to_numpy(), br.values)
    np.testing.assert_array_equal(df["amplitude x1 [m]"].to_numpy(), br.amplitude)
    ax = aj.plot_branches(br)
    assert "x1" in ax.get_ylabel() and "[mm]" in ax.get_ylabel()
    assert ax.get_xlabel() == "forcing frequency ω [rad/s]"
    _legend_matches_artists(ax)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "fold" in labels and "period-1 stable" in labels and "period-1 unstable" in labels
    matplotlib.pyplot.close(ax.figure)

    amap = aj.attractors(system, aj.Harmonic(amplitude=HARD["F0"], omega=1.15), samples=4,
                         max_periods=200, window=10)
    ds = amap.to_xarray()
    np.testing.assert_array_equal(ds["initial_state"].values, amap.initial_states)
    np.testing.assert_array_equal(ds["section"].values, amap.section)
    np.testing.assert_array_equal(ds["label"].values, amap.label)
    np.testing.assert_array_equal(ds["lyapunov"].values, amap.lyapunov)
    assert ds["lyapunov"].attrs["units"] == "1/s" and ds["peak"].attrs["units"] == "m"
    assert float(ds["omega"]) == 1.15 and list(ds["component"].values) == ["q1", "qd1"]
    assert list(ds["attractor_kind"].values) == [a.kind for a in amap.attractors]
    df = amap.to_dataframe()
    assert len(df) == 4
    np.testing.assert_array_equal(df["y0 q1 [m]"].to_numpy(), amap.initial_states[:, 0])


def test_describe_says_what_to_try_for_every_failure_code(kv_sweep):
    assert aj.describe(0) == "success"
    for code in aj.Status:
        if code == aj.Status.SUCCESS:
            continue
        text = aj.describe(code)
        hint = text.split("; try: ", 1)
        assert len(hint) == 2 and len(hint[1]) > 20, code
        assert "try" not in aj.describe(code, hint=False)
    assert "max_steps" in aj.describe(aj.Status.MAX_STEPS).split("try:")[1]
    assert "Marching" in aj.describe(aj.Status.NO_CONVERGENCE)
    assert "attractors" in aj.describe(aj.Status.NOT_PERIODIC)
    _, frf = kv_sweep
    failures = frf.failures()
    assert len(failures) == int(np.sum(np.asarray(frf.status) != 0))
    assert all("raise max_steps" in text for _, text in failures)


def test_every_cli_option_has_a_help_text_and_shows_its_default():
    parser = build_parser()
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)][0]
    assert set(subs.choices) >= {"simulate", "sweep", "tune", "scene", "continue",
                                 "attractors", "reproduce-paper", "work-precision"}
    for name, sub in subs.choices.items():
        assert sub.description, name
        text = " ".join(sub.format_help().split())
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            assert action.help and action.help != argparse.SUPPRESS, (name, action.dest)
            shown = action.default not in (None, False, True) and not action.required
            if shown:
                assert f"(default: {action.default})" in text, (name, action.dest)
    help_simulate = " ".join(subs.choices["simulate"].format_help().split())
    assert "final time [s] (default: 2.0)" in help_simulate


def test_missing_optional_dependency_says_how_to_install_it(kv_sweep, monkeypatch):
    _, frf = kv_sweep
    monkeypatch.setitem(sys.modules, "xarray", None)
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match="pip install xarray"):
        frf.to_xarray()
    with pytest.raises(ImportError, match="pip install pandas"):
        frf.to_dataframe()
