"""The notebooks and the experiments run, at smoke size, as a user would run them."""

import json
import subprocess
import sys
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


def test_probe_sweep_smoke(tmp_path):
    result = subprocess.run(
        [sys.executable, str(ROOT / "experiments" / "probe_sweep_pad5x5.py"), "--smoke", "--output", str(tmp_path)],
        capture_output=True, text=True, timeout=1200,
    )
    assert result.returncode == 0, result.stderr[-3000:]
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


def test_ablation_table1_and_fine_tuning_curve_smoke(tmp_path):
    result = subprocess.run(
        [sys.executable, str(ROOT / "experiments" / "ablation_table1.py"), "--smoke", "--output", str(tmp_path)],
        capture_output=True, text=True, timeout=1800,
    )
    assert result.returncode == 0, result.stderr[-3000:]
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
    # The fine-tuning curve starts from the ablation's binned GRU (seed 0).
    pretrained = tmp_path / "ablation_table1.work" / "sphere8_gru_binned_0"
    result = subprocess.run(
        [sys.executable, str(ROOT / "experiments" / "fine_tuning_curve.py"), "--smoke", "--pretrained", str(pretrained), "--output", str(tmp_path)],
        capture_output=True, text=True, timeout=1800,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    curve = json.loads((tmp_path / "fine_tuning_curve.json").read_text())
    assert curve["settings"]["training_recordings"] >= 2 and curve["settings"]["held_out_recordings"] >= 2
    assert {(e["recordings"], e["start"]) for e in curve["curve"]} == {(1, "pretrained"), (1, "scratch"), (2, "pretrained"), (2, "scratch")}
    assert all(np.isfinite(run["best_validation_loss"]) and np.isfinite(run["metrics"]["fn_rmse"]) for run in curve["runs"])
    assert (tmp_path / "fine_tuning_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
