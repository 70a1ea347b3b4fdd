"""The notebooks and the experiments run, at smoke size, as a user would run them.

The experiments run in this process (as `python experiments/NAME.py --smoke ...`
would, through runpy): they press the same sensor with the same tiny regime and train
the same small models, so the programs one compiles serve the next.
"""

import json
import runpy
import shutil
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9]*.py"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path, tmp_path, monkeypatch):
    jupytext = pytest.importorskip("jupytext")
    nbclient = pytest.importorskip("nbclient")
    monkeypatch.setenv("HYDROTACT_SMOKE", "1")
    monkeypatch.setenv("HYDROTACT_NOTEBOOK_OUT", str(tmp_path / "out"))
    notebook = jupytext.read(path)
    client = nbclient.NotebookClient(notebook, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}})
    client.execute()
    outputs = [output for cell in notebook.cells if cell.cell_type == "code" for output in cell.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) >= 3, "the notebook should show its renders and plots"


def run_experiment(monkeypatch, name: str, *args) -> None:
    """`python experiments/NAME.py ARGS` in this process; fails unless it ends or exits 0.
    Its HydrotactWarnings (e.g. readings clipped at the barometer's range, which the
    tiny regime's hard presses reach) are shown, as a run from the shell shows them,
    not turned into errors; any other warning still fails the test."""
    from hydrotact import HydrotactWarning

    script = ROOT / "experiments" / f"{name}.py"
    monkeypatch.syspath_prepend(str(script.parent))
    monkeypatch.setattr(sys, "argv", [str(script), *map(str, args)])
    with warnings.catch_warnings():
        warnings.simplefilter("default", HydrotactWarning)
        try:
            runpy.run_path(str(script), run_name="__main__")
        except SystemExit as exit_:
            assert exit_.code in (None, 0), f"{name} exited {exit_.code}"


def test_probe_sweep_smoke(tmp_path, monkeypatch):
    run_experiment(monkeypatch, "probe_sweep_pad5x5", "--smoke", "--output", tmp_path)
    report = json.loads((tmp_path / "probe_sweep_pad5x5.json").read_text())
    assert (tmp_path / "probe_sweep_pad5x5.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob(".*partial*")), "partial files are removed after a finished run"
    for name, sweep in report["sweeps"].items():
        assert sweep["all_converged"], name
        assert sweep["max_force_error_N"] < 1e-6, name
        centre = sweep["cells"]["b22"]
        assert centre["peak_within_0.1mm"], (name, centre)
        assert 1.0 < centre["fwhm_mm"] < 4.0, (name, centre)
        # 16 rays against 64 at the positions both ran (footprint rays: 5 % of the peak at most)
        assert 0.0 < centre["max_difference_from_reference_of_peak"] < 0.08, (name, centre)
    # --barometers elastic: the same layout, every barometer reading the elastomer (its
    # fields take minutes to solve, so the full run alone uses them), and the figure that
    # lays the two models' curves over each other.
    monkeypatch.syspath_prepend(str(ROOT / "experiments"))
    import probe_sweep_pad5x5 as sweep

    disk, elastic = sweep.sensor("disk"), sweep.sensor("elastic")
    assert not disk.is_elastic.any() and elastic.is_elastic.all() and elastic.name == "pad5x5-elastic"
    np.testing.assert_array_equal(elastic.taxel_positions_S, disk.taxel_positions_S)
    traces = sweep.read_traces(tmp_path / "probe_sweep_pad5x5.npz")
    sweep.plot_models(traces, traces, tmp_path / "models.png")
    assert (tmp_path / "models.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_ablation_table1_and_fine_tuning_curve_smoke(tmp_path, monkeypatch):
    run_experiment(monkeypatch, "ablation_table1", "--smoke", "--output", tmp_path)
    report = json.loads((tmp_path / "ablation_table1.json").read_text())
    for name in ("ablation_table1.png", "ablation_table1_error_map_sphere8.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    # Each run's error map (the paper's Fig. 5) pools to its arc-length mean.
    for run in report["runs"]:
        mean, count = np.array(run["error_map"]["mean"], dtype=float), np.asarray(run["error_map"]["count"])
        assert np.isclose(np.nansum(mean * count) / count.sum(), run["metrics"]["arc_length_mean"], rtol=1e-5)
    rows = {(entry["row"], entry["binned"]) for entry in report["table"]}
    assert len(rows) == 8  # four models, binned and plain
    for entry in report["table"]:
        assert entry["parameters"] <= 6000 and all(np.isfinite(entry[name]["mean"]) for name in ("fx_rmse", "fn_rmse", "theta_rmse", "contact_bce"))
    paper_rnn = next(e for e in report["table"] if e["row"] == "RNN (paper)" and e["binned"])
    assert paper_rnn["parameters"] == 4205  # the paper's Binned RNN on the sphere
    assert set(report["ageing"]) >= {"fresh", "aged_untared", "aged_tared"}
    assert "| sphere8 | GRU (budget) | binned |" in (tmp_path / "ablation_table1.md").read_text()
    assert set(report["channel_swing_Pa"]["sphere8"]) == {f"b{k}" for k in range(8)} and "3-9 kPa" in (tmp_path / "ablation_table1.md").read_text()
    # Beside the committed run under the cones, row by row (this run's number first).
    cones = {(e["row"], e["binned"]): e for e in json.loads((ROOT / "experiments" / "results" / "ablation_table1_cones.json").read_text())["table"] if e["sensor"] == "sphere8"}
    row = next(line for line in (tmp_path / "ablation_table1_models.md").read_text().splitlines() if line.startswith("| sphere8 | RNN (paper) | binned |"))
    assert row.split(" | ")[3] == f"{paper_rnn['theta_rmse']['mean']:.3g} / {cones[('RNN (paper)', True)]['theta_rmse']['mean']:.3g}"
    # On a checkout without the work folder's models, the committed records stand in for them.
    shutil.rmtree(tmp_path / "ablation_table1.work" / "sphere8_mlp_plain_0")
    run_experiment(monkeypatch, "ablation_table1", "--smoke", "--output", tmp_path)
    assert not (tmp_path / "ablation_table1.work" / "sphere8_mlp_plain_0").exists()
    again = json.loads((tmp_path / "ablation_table1.json").read_text())
    assert json.dumps(again["runs"]) == json.dumps(report["runs"]) and again["ageing"] == report["ageing"]
    assert len(list((tmp_path / "ablation_table1.runs").glob("*.json"))) == 8 + 1  # four models, binned and plain, one seed; the ageing
    # The fine-tuning curve starts from the ablation's binned GRU (seed 0).
    pretrained = tmp_path / "ablation_table1.work" / "sphere8_gru_binned_0"
    run_experiment(monkeypatch, "fine_tuning_curve", "--smoke", "--pretrained", pretrained, "--output", tmp_path)
    curve = json.loads((tmp_path / "fine_tuning_curve.json").read_text())
    assert curve["settings"]["training_recordings"] >= 2 and curve["settings"]["held_out_recordings"] >= 2
    assert {(e["recordings"], e["start"]) for e in curve["curve"]} == {(1, "pretrained"), (1, "scratch"), (2, "pretrained"), (2, "scratch")}
    assert all(np.isfinite(run["best_validation_loss"]) and np.isfinite(run["metrics"]["fn_rmse"]) for run in curve["runs"])
    assert (tmp_path / "fine_tuning_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_layout_design_smoke(tmp_path, monkeypatch):
    run_experiment(monkeypatch, "layout_design", "--smoke", "--sensor", "sphere8-cones", "--output", tmp_path)
    report = json.loads((tmp_path / "layout_design.json").read_text())
    # The smoke runs the risers design only (layout_design.SMOKE_SKIPS: the D-optimal
    # objective of the other two runs in tests/test_design.py and notebook 05).
    assert set(report["designs"]) == {"risers"}
    risers = report["designs"]["risers"]["scores"]
    assert set(risers) == {"designed", "built-in", "regular", "random start"}
    assert report["designs"]["risers"]["config"]["objective"] == "k" and report["designs"]["risers"]["config"]["balance"] == 4.0
    # The design improves its objective over the sensor's own layout (its climb starts there).
    assert risers["designed"]["score"] > risers["built-in"]["score"]
    assert all(np.isfinite(score["rms_neighbour_error_m"]) and score["rms_neighbour_error_m"] > 0.0 for score in risers.values())
    # On risers no port stands higher than the built-in's highest.
    from hydrotact.sensors import load_sensor

    height = report["designs"]["risers"]["config"]["max_height"]
    assert np.isclose(height, 2e-3) and np.all(load_sensor(tmp_path / "layout_design_sensor.json").taxel_positions_S[:, 2] <= height + 1e-12)
    table = {entry["layout"]: entry for entry in report["table"]}
    assert set(table) == {"designed", "built-in", "regular"}
    for name in table:
        assert all(np.isfinite(table[name][metric]["mean"]) for metric in ("theta_rmse", "phi_rmse", "arc_length_mean", "fn_rmse")), name
    # Every layout's dataset pressed the same events (the probe's path and the force it
    # felt): only the barometers, and so their readings, differ.
    from hydrotact.datasets import load_dataset

    columns = ["probe_x", "probe_y", "probe_z", "fx", "fy", "fz", "b0"]
    designed, regular = (load_dataset(tmp_path / "layout_design.work" / f"{name}_dataset").arrays("train", columns) for name in ("designed", "regular"))
    for name in columns[:-1]:
        np.testing.assert_array_equal(designed[name], regular[name], err_msg=name)
    assert not np.array_equal(designed["b0"], regular["b0"])

    designed = load_sensor(tmp_path / "layout_design_sensor.json")
    assert designed.num_taxels == 8 and designed.name == "sphere8-cones_designed"
    for name in ("layout_design.png", "layout_design_layouts.png", "layout_design_convergence.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert "| designed |" in (tmp_path / "layout_design.md").read_text()
    # On a checkout without the work folder, the committed records stand in for the
    # designs, datasets and models: the same table, nothing designed or trained again.
    shutil.rmtree(tmp_path / "layout_design.work")
    run_experiment(monkeypatch, "layout_design", "--smoke", "--sensor", "sphere8-cones", "--output", tmp_path)
    again = json.loads((tmp_path / "layout_design.json").read_text())
    assert json.dumps(again["table"]) == json.dumps(report["table"]) and json.dumps(again["runs"]) == json.dumps(report["runs"])
    assert not list((tmp_path / "layout_design.work").glob("*_dataset"))


def test_mtl_calibration_refuses_a_folder_without_its_six_logs(tmp_path, monkeypatch):
    """The real-strip experiment has no smoke run (its logs are not in the repository):
    it names the six files it needs when they are not there, reads no other file, and
    lays out its cases as the issue asks (6 alone, 2 groups of three, 6 left out)."""
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "zv1_zd6_t8_20230622_174706.csv").write_text("time,Sensor_0\n")
    script = str(ROOT / "experiments" / "mtl_calibration.py")
    monkeypatch.setattr(sys, "argv", [script, "--data", str(tmp_path), "--output", str(tmp_path / "out")])
    with pytest.raises(SystemExit, match="the six calibration logs .* are not all in logs/"):
        runpy.run_path(script, run_name="__main__")
    assert not (tmp_path / "out").exists()
    module = runpy.run_path(script)
    cases = module["make_cases"]({"single", "group", "leave-one-out"})
    assert [sum(kind == k for _, kind, _, _ in cases) for k in ("single", "group", "leave-one-out")] == [6, 2, 6]
    assert all(left not in fitted and len(fitted) == 2 for _, kind, fitted, left in cases if kind == "leave-one-out")


def test_mtl_strip_builds_its_sensor_from_a_mould_and_a_board(tmp_path, monkeypatch):
    """The real strip's experiment has no smoke run (its data are not in the
    repository); its sensor stage runs on a stand-in: a tray with three pocket formers
    and an Eagle board whose packages sit 6 mm apart, shifted. The pockets are found
    on the cast, the packages matched to them by one translation (a package off its
    pocket is refused), and the sensor file loads with the barometers at the pockets'
    ceilings. A folder without the design files is named, and nothing else read."""
    from helpers import write_mould

    from hydrotact.mesh import make_mould_cavity
    from hydrotact.sensors import load_sensor

    script = ROOT / "experiments" / "mtl_strip.py"
    monkeypatch.setattr(sys, "argv", [str(script), "--data", str(tmp_path), "--output", str(tmp_path / "out")])
    with pytest.raises(SystemExit, match="the mould .* is not there"):
        runpy.run_path(str(script), run_name="__main__")
    assert not (tmp_path / "out").exists()
    strip = runpy.run_path(str(script))
    (tmp_path / "design").mkdir()
    formers = [((3.5 + 6 * k, 4.8, 2.5), (6.5 + 6 * k, 6.0, 7.5)) for k in range(3)]  # 3 x 1.2 x 5 mm, on the floor (y = 6)
    mould = write_mould(tmp_path / "design" / "mould_b_V6.STL", ((0, 0, 0), (22, 7, 10)), [((2, -1, 2), (20, 6, 8))], formers)
    surface, _ = make_mould_cavity(mould, units="mm", board=strip["BOARD_SIDE"])
    pockets = strip["find_pockets"](surface)
    np.testing.assert_allclose(pockets * 1e3, [[-6.0, 0.0, 1.2], [0.0, 0.0, 1.2], [6.0, 0.0, 1.2]], atol=1e-6)
    parts = {f"P{k + 1}": (31.0 + 6.0 * k, 16.0) for k in range(3)}
    elements = "".join(f'<element name="{name}" library="baro" package="MPL3115A2" x="{x}" y="{y}"/>' for name, (x, y) in parts.items())
    board = tmp_path / "design" / "Baro_1D_V1.brd"
    board.write_text(f'<?xml version="1.0"?><eagle><drawing><board><elements>{elements}<element name="R1" x="0" y="0"/></elements></board></drawing></eagle>')
    assert strip["read_board_parts"](board) == parts
    assert strip["find_design"](tmp_path) == (mould, board)
    shift, ports = strip["align_board"](parts, pockets)
    np.testing.assert_allclose(shift * 1e3, [-37.0, -16.0], atol=1e-6)
    np.testing.assert_allclose(ports["P2"] * 1e3, [0.0, 0.0, 1.2], atol=1e-6)
    with pytest.raises(SystemExit, match="P3 is .* mm from its pocket"):
        strip["align_board"]({**parts, "P3": (43.5, 16.0)}, pockets)
    ports["P4"] = ports["P3"]  # the strip logs four channels; the stand-in has three pockets
    document = strip["make_strip_document"](mould, ports, {"kind": "cone", "half_angle": 40.0}, "stand-in")
    (tmp_path / "strip.json").write_text(json.dumps(document))
    spec = load_sensor(tmp_path / "strip.json")
    assert spec.taxel_names == strip["CHANNELS"] and spec.part.name == "MPL3115A2"
    np.testing.assert_allclose(spec.taxel_positions_S[1], [0.0, 0.0, 1.2e-3], atol=1e-9)
    # The estimate stage's real logs: cut between presses (a log sweeps x, so a cut in
    # time would validate where nothing trained), every fourth press validating from
    # the third; each channel tared on its first 20 s onto the simulation's rest.
    contact = np.array(([0] * 3 + [1] * 5) * 9 + [0] * 2)
    block = {"time": np.arange(len(contact)) * 0.5, "contact": contact, "Sensor_0": np.arange(len(contact), dtype=float)}
    training, validation = strip["_split"](block)
    assert len(training) == 7 and len(validation) == 2
    pieces = sorted(training + validation, key=lambda piece: piece["time"][0])
    np.testing.assert_array_equal(np.concatenate([piece["time"] for piece in pieces]), block["time"])
    assert all(np.sum(np.diff(np.concatenate([[0], piece["contact"], [0]])) == 1) == 1 for piece in pieces)
    assert [piece["time"][0] for piece in validation] == [pieces[2]["time"][0], pieces[6]["time"][0]]
    tared = strip["_tared"]({"time": block["time"], **{c: block["Sensor_0"] + 1e5 for c in strip["CHANNELS"]}}, np.full(4, 101325.0))
    np.testing.assert_allclose(tared["Sensor_2"], block["Sensor_0"] - np.median(block["Sensor_0"][:41]) + 101325.0)
