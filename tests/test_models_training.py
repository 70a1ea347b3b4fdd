"""Estimator training: the loss terms against direct NumPy sums, the arc length against
the paper's Eq. 2, sequences with burn-in against the paper's windows; a short training
on a tiny generated dataset (every loss term falls, every metric beats a constant
predictor), resumption, saving, and `hydrotact train`."""

import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_one_line_error, run_cli, run_main

from hydrotact import HydrotactError
from hydrotact.datasets import load_dataset
from hydrotact.models import (
    Normaliser,
    StreamingEstimator,
    TrainConfig,
    calc_arc_length,
    calc_detection,
    calc_estimator_sequence,
    calc_loss,
    calc_loss_terms,
    calc_skin_radius,
    calc_table_metrics,
    evaluate_estimator,
    export_c_header,
    load_estimator,
    make_estimator_spec,
    make_sequences,
    predict_recording,
    save_estimator,
    train_estimator,
)
from hydrotact.sensors import load_sensor


def _targets(rng, n):
    contact = (rng.random(n) < 0.6).astype(float)
    theta = np.where(contact > 0, rng.uniform(-0.7, 0.7, n), np.nan)
    phi = np.where(contact > 0, rng.uniform(-2.2, 0.7, n), np.nan)
    return {"values": rng.normal(size=(n, 4)), "theta": theta, "phi": phi, "contact": contact, "mask": (rng.random(n) < 0.8).astype(float)}


def test_loss_terms_equal_direct_sums():
    rng = np.random.default_rng(0)
    for binned in (True, False):
        spec = make_estimator_spec(load_sensor("sphere8"), "gru", binned)
        raw = rng.normal(size=(200, spec.num_outputs))
        t = _targets(rng, 200)
        terms = calc_loss_terms(spec, jnp.asarray(raw), {k: jnp.asarray(v) for k, v in t.items()})
        m = t["mask"] > 0
        np.testing.assert_allclose(terms["force"], np.mean(np.mean((raw[:, :4] - t["values"]) ** 2, axis=1)[m]), rtol=1e-12)
        p = 1 / (1 + np.exp(-raw[:, spec.outputs["contact"].start]))
        bce = -(t["contact"] * np.log(p) + (1 - t["contact"]) * np.log(1 - p))
        np.testing.assert_allclose(terms["contact"], bce[m].mean(), rtol=1e-10)
        touching = m & (t["contact"] > 0)
        if binned:
            ce = 0.0
            for name, bins in (("theta", spec.theta_bins), ("phi", spec.phi_bins)):
                logits = raw[:, spec.outputs[name]]
                log_p = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
                k = np.clip(np.floor((np.nan_to_num(t[name]) - bins.start) / bins.width), 0, bins.count - 1).astype(int)
                ce = ce - log_p[np.arange(200), k]
            np.testing.assert_allclose(terms["angle"], ce[touching].mean(), rtol=1e-10)
        else:
            err = (raw[:, 4] - np.nan_to_num(t["theta"])) ** 2 + (raw[:, 5] - np.nan_to_num(t["phi"])) ** 2
            np.testing.assert_allclose(terms["angle"], err[touching].mean(), rtol=1e-12)


def test_arc_length_is_eq_2_with_latitude_and_longitude():
    rng = np.random.default_rng(1)
    t1, t2 = rng.uniform(-0.7, 0.7, (2, 100))
    p1, p2 = rng.uniform(-2.3, 0.7, (2, 100))
    eq2 = 0.01 * np.arccos(np.clip(np.sin(t1) * np.sin(t2) + np.cos(t1) * np.cos(t2) * np.cos(p1 - p2), -1, 1))  # θ the latitude
    np.testing.assert_allclose(calc_arc_length(t1, p1, t2, p2, 0.01), eq2, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(calc_arc_length(t1, p1, t1, p1, 0.01), 0.0, atol=2e-9)


def test_table_metrics_of_a_perfect_estimate():
    rng = np.random.default_rng(2)
    spec = make_estimator_spec(load_sensor("sphere8"), "rnn", False)
    t = _targets(rng, 50)
    raw = np.zeros((50, spec.num_outputs))
    raw[:, :4] = t["values"]
    raw[:, 4], raw[:, 5] = np.nan_to_num(t["theta"]), np.nan_to_num(t["phi"])
    raw[:, 6] = np.where(t["contact"] > 0, 40.0, -40.0)
    metrics = calc_table_metrics(spec, jnp.asarray(raw), {k: jnp.asarray(v) for k, v in t.items()}, radius=0.01)
    for name, value in metrics.items():
        assert float(value) < 1e-8, name
    # A recording without contact has no angle error to report: NaN, not a perfect 0.
    untouched = t | {"contact": np.zeros(50)}
    metrics = calc_table_metrics(spec, jnp.asarray(raw), {k: jnp.asarray(v) for k, v in untouched.items()}, radius=0.01)
    assert np.isnan(metrics["theta_rmse"]) and np.isnan(metrics["phi_rmse"]) and np.isnan(metrics["arc_length_mean"]) and float(metrics["fx_rmse"]) < 1e-8


def test_sequences_with_burn_in_cover_each_label_once_and_windows_match_the_paper():
    rng = np.random.default_rng(3)
    n = 230
    arrays = {"time": np.arange(n) / 100, "contact": (rng.random(n) < 0.5).astype(np.int8), "block_starts": np.array([0, 97])}
    for name in ("b0", "b1", "fx", "fy", "fz", "fn", "theta", "phi"):
        arrays[name] = rng.normal(size=n)
    norm = Normaliser.fit(np.column_stack([arrays["b0"], arrays["b1"]]))
    inputs, targets = make_sequences(arrays, ["b0", "b1"], norm, length=20, burn_in=8, dtype=np.float64)
    labelled = targets["values"][targets["mask"] > 0][:, 0]
    np.testing.assert_array_equal(np.sort(labelled), np.sort(arrays["fx"]))  # every label exactly once
    assert inputs.shape[1] == 28
    # No context crosses a block edge: the second block's first sequence starts with its own first sample.
    second = np.flatnonzero(np.isclose(targets["values"][:, 8, 0], arrays["fx"][97]))[0]
    np.testing.assert_allclose(inputs[second, :9], np.repeat(norm(np.column_stack([arrays["b0"], arrays["b1"]]))[97:98], 9, axis=0))
    # The paper's windows: one label per 512-step history, the label last.
    inputs, targets = make_sequences(arrays, ["b0", "b1"], norm, length=1, burn_in=15, dtype=np.float64)
    assert inputs.shape == (n, 16, 2) and np.all(targets["mask"][:, :-1] == 0) and np.all(targets["mask"][:, -1] == 1)


# --- training on a tiny generated dataset ------------------------------------------

TINY = ["--sensor", "sphere8", "--probe", "sphere:r=3mm,subdivisions=1", "--events", "16", "--seed", "5", "--rays", "8", "--hold-range", "0.3,0.8", "--gap-range", "0.2,0.4",
        "--speed-range", "0.01,0.02", "--force-range", "0.2,4", "--noise", "2", "--no-plots", "--json"]
QUICK = dict(hidden=(8, 8), sequence_length=64, burn_in=32, batch_size=8, learning_rate=1e-2, max_epochs=80, patience=80)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A 16-event sphere8 dataset (about 1.5 min of session), generated in this process."""
    from hydrotact.cli import main

    folder = tmp_path_factory.mktemp("tiny") / "dataset"
    assert main(["generate", *TINY, "-o", str(folder)]) == 0
    return load_dataset(folder)


@pytest.fixture(scope="module")
def trained(tiny):
    return train_estimator(tiny, load_sensor("sphere8"), TrainConfig(**QUICK))


def test_training_lowers_every_loss_term_and_beats_a_constant_predictor(tiny):
    """On the data it was trained on, with the last epoch's parameters (a dozen presses
    cannot teach the places of the held-out ones, so the best validation epoch is an
    early one; generalisation is the ablation's to show): every loss term is lower than
    at the initialisation, and every Table I metric beats the constant predictor (the
    training means of the forces and, over contact, the angles; the contact rate)."""
    from hydrotact.models import init_estimator

    trained = train_estimator(tiny, load_sensor("sphere8"), TrainConfig(**(QUICK | {"restore_best": False})))
    assert trained.best_epoch < len(trained.history) - 1
    spec, config = trained.spec, trained.config
    train = tiny.arrays("train")
    inputs, targets = make_sequences(train, trained.channels, trained.normaliser, config.sequence_length, config.burn_in)
    targets = {k: jnp.asarray(v) for k, v in targets.items()}
    terms = {}
    for name, params in (("initial", init_estimator(spec, jax.random.PRNGKey(config.seed))), ("trained", trained.params)):
        raw = jax.vmap(lambda x, params=params: calc_estimator_sequence(spec, params, x)[1])(jnp.asarray(inputs))
        terms[name] = {k: float(v) for k, v in calc_loss(spec, raw, targets, dict(config.weights))[1].items()}
    assert terms["initial"]["position"] == terms["trained"]["position"] == 0.0  # the forces' model has no position target
    for name in ("force", "angle", "contact"):
        assert terms["trained"][name] < terms["initial"][name], (name, terms["trained"][name], terms["initial"][name])
    metrics = evaluate_estimator(trained, tiny.blocks("train"), tiny.manifest["config"]["rate_hz"])["metrics"]
    constant = {f"{name}_rmse": np.sqrt(np.mean((train[name] - train[name].mean()) ** 2)) for name in ("fx", "fy", "fz", "fn")}
    touching = train["contact"] > 0
    for name in ("theta", "phi"):
        constant[f"{name}_rmse"] = np.sqrt(np.mean((train[name][touching] - train[name][touching].mean()) ** 2))
    rate = train["contact"].mean()
    constant["contact_bce"] = -np.mean(train["contact"] * np.log(rate) + (1 - train["contact"]) * np.log(1 - rate))
    for name, value in constant.items():
        assert metrics[name] < value, (name, metrics[name], value)


def test_an_interrupted_training_resumes_to_the_same_parameters(tiny, trained, tmp_path):
    def stop_after_the_third(entry):
        if entry["epoch"] == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train_estimator(tiny, load_sensor("sphere8"), TrainConfig(**QUICK), folder=tmp_path, on_epoch=stop_after_the_third)
    resumed = train_estimator(tiny, load_sensor("sphere8"), TrainConfig(**QUICK), folder=tmp_path)
    assert [e["validation_loss"] for e in resumed.history] == [e["validation_loss"] for e in trained.history]
    for a, b in zip(jax.tree_util.tree_leaves(resumed.params), jax.tree_util.tree_leaves(trained.params)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # Another training into the same folder is refused, the checkpoint untouched.
    before = (tmp_path / "checkpoint.npz").read_bytes()
    with pytest.raises(HydrotactError, match="another training"):
        train_estimator(tiny, load_sensor("sphere8"), TrainConfig(**(QUICK | {"seed": 1})), folder=tmp_path)
    assert (tmp_path / "checkpoint.npz").read_bytes() == before


def test_a_saved_model_reads_back_the_same(trained, tmp_path):
    save_estimator(trained, tmp_path, "sphere8")
    loaded = load_estimator(tmp_path)
    assert loaded.spec == trained.spec and loaded.channels == trained.channels and loaded.config == trained.config
    for a, b in zip(jax.tree_util.tree_leaves(loaded.params), jax.tree_util.tree_leaves(trained.params)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b, dtype=np.float32))
    np.testing.assert_array_equal(loaded.normaliser.mean, trained.normaliser.mean)
    with pytest.raises(HydrotactError, match="not all finite"):  # no header with `nanf` in it
        export_c_header(dataclasses.replace(trained, params=jax.tree_util.tree_map(lambda leaf: leaf.at[0].set(jnp.nan) if leaf.ndim == 1 else leaf, trained.params)), tmp_path / "model.h")
    assert not (tmp_path / "model.h").exists()
    with np.load(tmp_path / "weights.npz") as saved:
        damaged = {name: saved[name] for name in saved.files}
    damaged["w1"] = damaged["w1"].copy()
    damaged["w1"].flat[0] = np.nan
    np.savez(tmp_path / "weights.npz", **damaged)
    with pytest.raises(HydrotactError, match="weights.npz: w1 holds 1 values that are not finite"):
        load_estimator(tmp_path)
    (tmp_path / "weights.npz").write_bytes(b"not a zip")
    with pytest.raises(HydrotactError, match="weights.npz"):
        load_estimator(tmp_path)


def test_compressed_inputs_are_the_asinh_of_the_reading_above_rest(tiny, tmp_path):
    """With `asinh_scale`, the inputs are z-scores of asinh((y - rest) / scale), the
    rest each channel's median over the training split's no-contact samples; the model
    saves, reads back and predicts the same; a scale that is not a positive pressure
    is refused."""
    trained = train_estimator(tiny, load_sensor("sphere8"), TrainConfig(**(QUICK | {"max_epochs": 2, "asinh_scale": 20.0})))
    train = tiny.arrays("train")
    readings = np.column_stack([train[name] for name in trained.channels])
    rest = np.median(readings[train["contact"] <= 0], axis=0)
    compressed = np.arcsinh((readings - rest) / 20.0)
    normaliser = trained.normaliser
    assert normaliser.scale == 20.0 and trained.config.asinh_scale == 20.0
    np.testing.assert_allclose(normaliser.rest, rest, rtol=0, atol=0)
    np.testing.assert_allclose(normaliser(readings), (compressed - compressed.mean(axis=0)) / compressed.std(axis=0), rtol=1e-12, atol=1e-12)
    # A 0.1 N press and an 8 N one differ by a few units of input, not by a factor of 80.
    assert np.ptp(normaliser(readings), axis=0).max() < 20.0
    save_estimator(trained, tmp_path, "sphere8")
    loaded = load_estimator(tmp_path)
    assert loaded.normaliser.scale == 20.0 and loaded.config == trained.config
    np.testing.assert_array_equal(loaded.normaliser.rest, rest)
    block = tiny.blocks("test")[0]
    recording = np.column_stack([block[name] for name in trained.channels])
    a, b = predict_recording(trained, recording), predict_recording(loaded, recording)
    for name in ("fx", "fn", "theta", "phi", "contact_probability"):
        np.testing.assert_allclose(a[name], b[name], rtol=1e-6, atol=1e-7, err_msg=name)
    for bad in (0.0, -5.0, float("nan"), True):
        with pytest.raises(HydrotactError, match=r"asinh-scale: must be a positive pressure in Pa"):
            TrainConfig(asinh_scale=bad)


def test_burn_in_sequences_give_the_window_methods_loss(tiny, trained):
    """The same labels, the loss of the trained GRU: from sequences of 64 labels after a
    32-sample burn-in, and from the paper's windows (each label after its own 511
    samples of history): equal within a few per cent (the GRU's memory is short)."""
    held_out = tiny.arrays("test")
    spec, weights = trained.spec, dict(trained.config.weights)
    losses = []
    for length, burn_in in ((64, 32), (1, 511)):
        inputs, targets = make_sequences(held_out, trained.channels, trained.normaliser, length, burn_in)
        raw = jax.vmap(lambda x: calc_estimator_sequence(spec, trained.params, x)[1])(jnp.asarray(inputs))
        losses.append(float(calc_loss(spec, raw, {k: jnp.asarray(v) for k, v in targets.items()}, weights)[0]))
    np.testing.assert_allclose(losses[0], losses[1], rtol=0.03)


def test_train_command_writes_the_model_and_its_curve(tiny, tmp_path):
    result = run_cli("train", tiny.folder, "--hidden", "6,6", "--sequence-length", "64", "--burn-in", "16", "--batch-size", "8", "--max-epochs", "2", "-o", tmp_path / "model", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["epochs"] == 2 and report["parameters"] < 6000 and report["binned"] is True
    for name in ("model.json", "weights.npz", "checkpoint.npz", "training_curve.png"):
        assert (tmp_path / "model" / name).stat().st_size > 0, name
    assert load_estimator(tmp_path / "model").spec.hidden == (6, 6)
    assert_one_line_error(run_cli("train", tmp_path / "nowhere", "-o", tmp_path / "m2"), "nowhere")


def test_streaming_one_sample_at_a_time_equals_the_batched_prediction(tiny, trained):
    block = tiny.blocks("test")[0]
    readings = np.column_stack([block[name] for name in trained.channels])[:300]
    batched = predict_recording(trained, readings)
    stream = StreamingEstimator(trained)
    streamed = [stream.update(reading) for reading in readings]
    for name, values in batched.items():
        np.testing.assert_array_equal(np.array([s[name] for s in streamed], dtype=values.dtype), values, err_msg=name)
    stream.reset()
    assert stream.update(readings[0]) == streamed[0]


def test_contact_detection_latencies_on_known_edges():
    truth = np.zeros(1000, bool)
    truth[100:200] = truth[500:700] = True
    detected = np.zeros(1000, bool)
    detected[103:205] = detected[510:702] = True  # late by 3 and 10 samples; released 5 and 2 late
    result = calc_detection(truth, detected, 100.0)
    assert result["onset_latency"]["count"] == 2 and result["release_latency"]["count"] == 2
    np.testing.assert_allclose(result["onset_latency"]["median_s"], 0.065)
    np.testing.assert_allclose(result["release_latency"]["median_s"], 0.035)
    np.testing.assert_allclose(result["accuracy"], 1 - 20 / 1000)
    assert result["missed_contacts"] == 0
    assert calc_detection(truth, np.zeros(1000, bool), 100.0)["missed_contacts"] == 2


def test_evaluation_on_the_held_out_blocks(tiny, trained):
    result = evaluate_estimator(trained, tiny.blocks("test"), tiny.manifest["config"]["rate_hz"], radius=0.01)
    assert set(result["metrics"]) >= {"fx_rmse", "fy_rmse", "fz_rmse", "fn_rmse", "theta_rmse", "phi_rmse", "contact_bce", "arc_length_mean"}
    assert all(np.isfinite(v) for v in result["metrics"].values())
    truth = np.concatenate([block["contact"] for block in tiny.blocks("test")])
    assert result["detection"]["contact_head"]["accuracy"] > max(truth.mean(), 1 - truth.mean())  # better than always one answer
    assert len(result["predictions"]) == len(tiny.blocks("test"))


C_MAIN = r"""
#include <stdio.h>
#include "model.h"
int main(void) {
  int count; if (scanf("%d", &count) != 1) return 1;
  hydrotact_state state = {0}; hydrotact_output out; float readings[HYDROTACT_NUM_INPUTS];
  for (int t = 0; t < count; ++t) {
    for (int j = 0; j < HYDROTACT_NUM_INPUTS; ++j) if (scanf("%f", &readings[j]) != 1) return 1;
    hydrotact_step(&state, readings, &out);
    printf("%.9g %.9g %.9g %.9g %.9g %.9g %.9g %.9g %.9g %.9g\n", out.force[0], out.force[1], out.force[2], out.force[3], out.x, out.y, out.depth, out.theta, out.phi, out.contact);
  }
  return 0;
}
"""


@pytest.mark.parametrize("variant", ["gru binned (trained)", "gru binned (trained), asinh inputs", "gru plain", "rnn binned", "mlp plain"])
def test_the_c_export_compiles_and_matches_jax(tiny, trained, tmp_path, variant):
    import dataclasses

    from hydrotact.models import init_estimator

    model = trained
    if variant.endswith("asinh inputs"):  # the trained weights on compressed inputs: the C code must compress as the model does
        train = tiny.arrays("train")
        readings = np.column_stack([train[name] for name in trained.channels])
        model = dataclasses.replace(trained, normaliser=Normaliser.fit(readings, 20.0, train["contact"] <= 0))
    elif variant != "gru binned (trained)":
        architecture, binned = variant.split()
        spec = make_estimator_spec(load_sensor("sphere8"), architecture, binned == "binned")
        model = dataclasses.replace(trained, spec=spec, params=init_estimator(spec, jax.random.PRNGKey(3)))
    _check_c_export(model, tiny.blocks("test")[0], tmp_path)


def _check_c_export(model, block, folder):
    """Export `model`, compile the header with the system's C compiler, stream 400
    samples of `block` through it: every output matches JAX to 1e-5 (NAN where the
    model does not estimate it)."""
    import shutil
    import subprocess

    compiler = shutil.which("cc") or shutil.which("gcc")
    assert compiler, "no C compiler on this machine"
    summary = export_c_header(model, folder / "model.h", "sphere8")
    bins = model.spec.theta_bins.count + model.spec.phi_bins.count if model.spec.binned else 0
    normalisation = 5 * 8 + 1 if model.normaliser.scale is not None else 3 * 8  # mean (two parts), 1 / std; rest (two parts), 1 / scale
    assert summary["flash_bytes"] == 4 * (summary["parameters"] + normalisation + bins)
    (folder / "main.c").write_text(C_MAIN)
    build = subprocess.run([compiler, "-std=c99", "-O2", "-Wall", "-Werror", "-o", str(folder / "step"), str(folder / "main.c"), "-lm"], capture_output=True, text=True, cwd=folder)
    assert build.returncode == 0, build.stderr
    readings = np.column_stack([block[name] for name in model.channels])[:400].astype(np.float32)
    text = f"{len(readings)}\n" + "\n".join(" ".join(f"{v!r}" for v in row.tolist()) for row in readings) + "\n"
    run = subprocess.run([str(folder / "step")], input=text, capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    c = np.loadtxt(run.stdout.splitlines())
    jax_out = predict_recording(model, readings.astype(np.float64))
    missing = np.full(len(readings), np.nan)
    expected = np.column_stack([jax_out.get(name, missing) for name in ("fx", "fy", "fz", "fn", "x", "y", "depth", "theta", "phi", "contact_probability")])
    assert np.array_equal(np.isnan(c), np.isnan(expected))
    np.testing.assert_allclose(c, expected, rtol=1e-5, atol=1e-5)


def test_position_and_depth_targets_train_save_load_stream_and_export(tiny, tmp_path):
    """An estimator of the contact position and the indentation depth (the targets of
    a strip pressed by a stage) besides the normal force: its loss terms are the direct
    sums (z-scores of the training split's contact samples), it learns them (on the
    training data, each RMSE under the constant predictor's), and it saves, loads,
    streams and exports to C as the force estimator does."""
    from hydrotact.models import init_estimator, load_estimator

    sensor = load_sensor("sphere8")
    config = TrainConfig(**(QUICK | {"targets": ("fn", "x", "y", "depth"), "restore_best": False, "max_epochs": 40}))
    trained = train_estimator(tiny, sensor, config)
    spec = trained.spec
    assert spec.targets == ("fn", "x", "y", "depth") and list(spec.outputs)[:5] == ["fn", "x", "y", "depth", "theta"]
    train = tiny.arrays("train")
    touching = train["contact"] > 0
    for k, column in enumerate(("cop_x", "cop_y", "depth")):
        assert spec.offsets[k + 1] == pytest.approx(np.mean(train[column][touching]), rel=1e-12)
        assert spec.scales[k + 1] == pytest.approx(np.std(train[column][touching]), rel=1e-12)
    # The position term by hand: each target's mean squared z-score over its contact samples, averaged.
    inputs, targets = make_sequences(train, trained.channels, trained.normaliser, 64, 32, targets=spec.targets)
    raw = np.asarray(jax.vmap(lambda x: calc_estimator_sequence(spec, init_estimator(spec, jax.random.PRNGKey(1)), x)[1])(jnp.asarray(inputs)), dtype=np.float64)
    counted = (targets["mask"] > 0) & (targets["contact"] > 0)
    by_hand = np.mean([np.mean((raw[..., 1 + k][counted] - (targets["values"][..., 1 + k][counted] - spec.offsets[1 + k]) / spec.scales[1 + k]) ** 2) for k in range(3)])
    terms = calc_loss(spec, jnp.asarray(raw), {k: jnp.asarray(v) for k, v in targets.items()})[1]
    np.testing.assert_allclose(float(terms["position"]), by_hand, rtol=1e-5)
    # It learns them: on the training blocks, each RMSE (m) under the constant predictor's.
    metrics = evaluate_estimator(trained, tiny.blocks("train"), tiny.manifest["config"]["rate_hz"])["metrics"]
    for name, column in (("x", "cop_x"), ("y", "cop_y"), ("depth", "depth")):
        assert metrics[f"{name}_rmse"] < np.std(train[column][touching]), name
    assert "fx_rmse" not in metrics
    # Saved and loaded; streamed one sample at a time as batched; exported to C.
    save_estimator(trained, tmp_path / "model", "sphere8")
    loaded = load_estimator(tmp_path / "model")
    assert loaded.spec == spec and loaded.config.targets == spec.targets
    block = tiny.blocks("test")[0]
    readings = np.column_stack([block[name] for name in loaded.channels])[:60]
    batched = predict_recording(loaded, readings)
    stream = StreamingEstimator(loaded)
    streamed = [stream.update(row) for row in readings]
    for name in ("fn", "x", "y", "depth", "theta", "phi", "contact_probability"):
        np.testing.assert_allclose([row[name] for row in streamed], batched[name], rtol=1e-6, atol=1e-9, err_msg=name)
    _check_c_export(loaded, block, tmp_path)


def test_fine_tuning_a_pretrained_model_beats_training_from_scratch_on_a_few_recordings(trained, tmp_path):
    """A stand-in for a real sensor: sphere8 with another, much softer viscoelastic
    material (E(0) 2.2 MPa against the pretraining's 10 MPa), its own channel gains and
    offsets (its barometers where sphere8's are: jittered, their eight elastic fields
    are solved anew, minutes; tests/test_elastic.py checks the jitter); a few of its
    recordings, written and read back as logs. Fine-tuning the model pretrained on the
    synthetic dataset reaches a lower validation loss than the same model trained from
    scratch on the same recordings for the same epochs."""
    import dataclasses

    from hydrotact.cli import main
    from hydrotact.data import BarometerLog, make_material_document, read_log, write_log, write_material
    from hydrotact.models import fine_tune_estimator, init_estimator

    material = write_material(tmp_path / "material.json", make_material_document(1.2e6, [1.0e6], [1.5], name="another silicone"))
    folder = tmp_path / "real"
    other = [*TINY, "--events", "10", "--seed", "9", "--gain-spread", "0.1", "--offset-spread", "300", "--material", str(material)]
    assert main(["generate", *other, "-o", str(folder)]) == 0
    real = load_dataset(folder)
    metadata = {"format": "hydrotact.barometer_log", "version": 1, "sensor": "sphere8", "source": "simulated", "pressure": "absolute", "channels": list(real.channels)}
    names = ("time", *real.channels, "fx", "fy", "fz", "fn", "theta", "phi", "contact")
    logs = {split: [read_log(write_log(tmp_path / f"{split}-{k}.parquet", BarometerLog(metadata, {name: block[name] for name in names}))).columns
                    for k, block in enumerate(real.blocks(split))] for split in ("train", "test")}
    # Validated on every held-out recording (three, about 2.5 s): one recording of a
    # second holds a sequence or two, and its loss says more about the sequence than the model.
    assert len(logs["test"]) >= 3
    config = TrainConfig(**(QUICK | {"max_epochs": 6, "learning_rate": 3e-3}))
    tuned = fine_tune_estimator(trained, logs["train"], logs["test"], config)
    best = lambda run: min(entry["validation_loss"] for entry in run.history)
    for seed in (1, 2):  # against more than one initialisation: not a lucky or unlucky draw
        scratch = fine_tune_estimator(dataclasses.replace(trained, params=init_estimator(trained.spec, jax.random.PRNGKey(seed))), logs["train"], logs["test"], config)
        assert best(tuned) < best(scratch), (seed, best(tuned), best(scratch))


def test_the_error_map_is_the_arc_length_error_per_cell(tiny, trained):
    """calc_error_map (the paper's Fig. 5) against a loop over the contact samples: each
    cell's mean arc length, by the true θ and φ, over π/16 cells of sphere8's ranges;
    a contact labelled past a range's edge counts in the edge cell; the cells together
    give the Table I arc-length mean."""
    from hydrotact.models import calc_error_map

    sensor = load_sensor("sphere8")
    result = evaluate_estimator(trained, tiny.blocks("test"), tiny.manifest["config"]["rate_hz"], radius=0.01)
    errors = result["location_errors"]
    error_map = calc_error_map(errors, sensor.theta_range, sensor.phi_range)
    assert error_map["mean"].shape == (8, 16) and error_map["unit"] == "m"
    expected_sum, expected_count = np.zeros((8, 16)), np.zeros((8, 16), int)
    for theta, phi, error in zip(errors["theta"], errors["phi"], errors["error"]):
        i = min(max(int((theta - sensor.theta_range[0]) // (np.pi / 16)), 0), 7)  # beyond the range: the edge cell
        j = min(max(int((phi - sensor.phi_range[0]) // (np.pi / 16)), 0), 15)
        expected_sum[i, j] += error
        expected_count[i, j] += 1
    np.testing.assert_array_equal(error_map["count"], expected_count)
    assert expected_count.sum() > 50 and np.count_nonzero(expected_count) > 3
    np.testing.assert_allclose(error_map["mean"][expected_count > 0], (expected_sum / np.maximum(expected_count, 1))[expected_count > 0], rtol=1e-12)
    assert np.all(np.isnan(error_map["mean"][expected_count == 0]))
    beyond = (errors["theta"] < sensor.theta_range[0]) | (errors["theta"] > sensor.theta_range[1]) | (errors["phi"] < sensor.phi_range[0]) | (errors["phi"] > sensor.phi_range[1])
    assert error_map["clamped"] == int(np.sum(beyond))
    np.testing.assert_allclose(np.nansum(error_map["mean"] * error_map["count"]) / error_map["count"].sum(), result["metrics"]["arc_length_mean"], rtol=1e-5)


def test_evaluate_predict_and_export_commands(tiny, trained, tmp_path, capsys):
    """`hydrotact evaluate` prints the numbers of evaluate_estimator and writes the
    error map and the detection plot; `hydrotact predict` streams a log (the stream's
    estimates equal the batched ones); `hydrotact export` writes the header; a missing
    model is one line. (In this process, as the tiny dataset is made: the programs are
    compiled already.)"""
    from hydrotact.data import BarometerLog, read_log, write_log
    from hydrotact.models import save_estimator

    def command(*args):
        return run_main(capsys, *args)

    model = save_estimator(trained, tmp_path / "model", "sphere8").parent
    (tmp_path / "copy").mkdir()
    (tmp_path / "copy" / "dataset").symlink_to(tiny.folder, target_is_directory=True)  # a second source of the same name
    result = command("evaluate", model, tiny.folder, tmp_path / "copy" / "dataset", "-o", tmp_path / "evaluation", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    radius = calc_skin_radius(load_sensor("sphere8"))
    expected = evaluate_estimator(trained, tiny.blocks("test"), tiny.manifest["config"]["rate_hz"], radius)["metrics"]
    for name, value in expected.items():
        np.testing.assert_allclose(report[f"{tiny.folder}: {name}"], value, rtol=1e-4)  # the report prints 6 digits; the saved weights are float32
    written = json.loads((tmp_path / "evaluation" / "evaluation.json").read_text())[str(tiny.folder)]
    assert written["metrics"] == pytest.approx(expected, rel=1e-6)
    for name in ("error_map_dataset.png", "contact_detection_dataset.png"):
        assert str(tmp_path / "evaluation" / name) in written["pictures"] and (tmp_path / "evaluation" / name).stat().st_size > 10_000, name
    second = json.loads((tmp_path / "evaluation" / "evaluation.json").read_text())[str(tmp_path / "copy" / "dataset")]
    assert second["pictures"] == [str(tmp_path / "evaluation" / f"{kind}_dataset_2.png") for kind in ("error_map", "contact_detection")]
    block = tiny.blocks("test")[0]
    metadata = {"format": "hydrotact.barometer_log", "version": 1, "sensor": "sphere8", "source": "simulated", "pressure": "absolute", "channels": list(tiny.channels)}
    log = write_log(tmp_path / "log.parquet", BarometerLog(metadata, {name: block[name] for name in ("time", *tiny.channels)}))
    assert command("predict", model, log, "-o", tmp_path / "estimates.parquet").returncode == 0
    estimates = read_log(tmp_path / "estimates.parquet").columns
    batched = predict_recording(trained, np.column_stack([block[name] for name in trained.channels]))
    for name in ("fx", "fn", "theta", "phi"):
        np.testing.assert_allclose(estimates[f"est_{name}"], batched[name], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(estimates["est_contact"], batched["contact_probability"], atol=1e-6)
    result = command("export", model, "-o", tmp_path / "model.h", "--json")
    assert result.returncode == 0, result.stderr
    assert "hydrotact_step" in (tmp_path / "model.h").read_text()
    assert_one_line_error(command("evaluate", tmp_path / "no-model", tiny.folder), "no-model")
