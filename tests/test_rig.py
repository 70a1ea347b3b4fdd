"""Full-mode fits of stage logs through a rig: the probe placed from the stage's
columns, the rig's offsets, home, slope and lag fitted with the material on a drifting
baseline (known truth, on the stand-in), the table's gradients against finite
differences, the command line, and the rig file's errors."""

import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_one_line_error, run_main

from hydrotact import HydrotactError
from hydrotact.data import LogWarning, Rig, RigParameter, read_log, read_rig, write_log
from hydrotact.sim import StageSession, simulate_stage_log
from hydrotact.sim._stage import FINGERTIP_SENSOR
from hydrotact.sysid import fit_problem, label_rig_log, make_fit_problem
from hydrotact.sysid._model import calc_residuals
from hydrotact.visco import Prony

MATERIAL = Prony(jnp.asarray(2e5), jnp.asarray([1e5]), jnp.asarray([2.0]))
PROBE = "sphere:r=2mm,subdivisions=2"  # test_press_fit's stand-in probe: its kernels compile once for both files
SHIFT = 0.3e-3  # the stage's x = 0 sits this far along the sensor's x: the rig must find it
# Three presses 1 mm apart across the fingertip's crown (each touching at its own
# height: the skin is curved), holds of 5-8 s, 16 Hz with 7-20 ms jitter, a 0.05 s
# lag, 100-300 Pa of drift per channel; the stage's x axis not level with the sensor
# (the tip's height at travel 0 rises 60 um per mm of stage x: the rig fits the slope).
SLOPE = 0.06
SESSION = StageSession(
    sites=((-1e-3, 0.0), (0.0, 0.0), (1e-3, 0.0)), hold_range=(5.0, 8.0), rest_range=(1.0, 2.0), num_gaps=0, drift_range=(100.0, 300.0), slope_x=SLOPE, seed=3,
)
# Each barometer's own sensitivity (its potting and port): geometric mean 1, so E keeps
# its scale and the fit's relative gains must find these.
GAINS = {"f0": 0.8, "f1": 1.25, "f2": 1.1, "f3": 1.0 / 1.1}


def with_gains(log):
    """The stand-in as barometers of these sensitivities read it: each channel's
    excursion from its first reading scaled (the contact, its drift and noise alike;
    scaling ~100 kPa of atmosphere would push it past the part's range)."""
    for name, gain in GAINS.items():
        readings = np.asarray(log.columns[name])
        log.columns[name] = readings[0] + gain * (readings - readings[0])
    return log


def rig_home(truth):
    """The tip's height at travel 0 over the log's stage x = 0 (the session's height
    over its own x = 0, moved along the slope by the stage's shift)."""
    return truth["home_m"] + truth["slope_x"] * SHIFT


@pytest.fixture(scope="module")
def stand_in():
    log, truth = simulate_stage_log(str(FINGERTIP_SENSOR), PROBE, MATERIAL, SESSION, num_rays=16)
    log = with_gains(log)
    log.metadata["sensor"] = str(FINGERTIP_SENSOR)
    log.columns["stage_x"] = np.asarray(log.columns["stage_x"]) - SHIFT
    home = rig_home(truth)
    rig = Rig(
        probe=PROBE, columns={"travel": "indentation", "x": "stage_x", "y": "stage_y"},
        offset_x=RigParameter(0.0, -0.6e-3, 0.6e-3), offset_y=RigParameter.at(0.0),
        home=RigParameter(home + 0.1e-3, home - 0.4e-3, home + 0.4e-3), lag_s=RigParameter(0.02, 0.0, 0.15), slope_x=RigParameter(0.0, -0.15, 0.15),
        xy_step=0.2e-3, height_step=0.025e-3,  # at 0.05 mm the table's interpolation biased E by 4 % (5 standard errors)
    )
    problem = make_fit_problem([log], rig=rig, drift=30.0, num_rays=16, sources=["stand-in"])
    return log, truth, home, rig, problem


def test_a_stage_log_gives_back_its_material_offset_home_and_lag(stand_in):
    """The stand-in's truth within three standard errors, from starts 0.3 mm, 0.1 mm,
    30 ms and a level stage off (a table 0.025 mm apart in height: at 0.05 mm its
    linear interpolation biased E by 4.2 % and the home by 8.5 µm, 5 standard errors;
    at 0.025 mm 0.4 % and 0.9 µm, 2026-12-06)."""
    _, truth, home, _, problem = stand_in
    result = fit_problem(problem, 1)
    assert result.converged and result.reduced_chi_square < 1.5
    rig = result.rig_parameters()
    for name, true in (("offset_x", SHIFT), ("home[1]", home), ("lag_s", truth["lag_s"]), ("slope_x[1]", SLOPE)):
        assert rig[name].value == pytest.approx(true, abs=3 * rig[name].std), (name, rig[name], true)
    assert rig["offset_x"].std < 10e-6 and rig["home[1]"].std < 5e-6 and rig["lag_s"].std < 2e-3 and rig["slope_x[1]"].std < 5e-3
    assert rig["offset_y"].std == 0.0 and rig["offset_y"].value == 0.0  # fixed
    (modulus, tau), = result.terms
    for estimate, true in ((result.long_term_modulus, 2e5), (modulus, 1e5), (tau, 2.0)):
        assert estimate.value == pytest.approx(true, abs=3 * estimate.std) and estimate.std < 0.02 * true, (estimate, true)
    assert result.unidentified() == []
    # the baselines drift: a spline per channel, the first sample's value reported
    assert result.layout.drifts[0] > 1 and set(result.offsets()[0]) == {"f0", "f1", "f2", "f3"}
    # each barometer's relative gain (their geometric mean 1: the last follows from the others)
    gains = result.gains
    assert problem.relative_gains and list(gains) == [f"{FINGERTIP_SENSOR}/{name}" for name in GAINS]
    for name, truth_gain in GAINS.items():
        estimate = gains[f"{FINGERTIP_SENSOR}/{name}"]
        assert 0.0 < estimate.std < 0.02 and estimate.value == pytest.approx(truth_gain, abs=max(4 * estimate.std, 0.01)), (name, estimate)
    np.testing.assert_allclose(np.prod([g.value for g in gains.values()]), 1.0, rtol=1e-12)


def test_a_barometer_that_barely_reads_is_fitted_outside_the_gains_mean(stand_in):
    """f3 reading a twentieth of what it should (a barometer gone dead in its pocket):
    its gain is fitted on its own, and the other three's geometric mean sets E's
    scale, as if f3 were not there; the fit says which channel it set apart."""
    log, _, _, rig, _ = stand_in
    weak = dataclasses.replace(log, columns=dict(log.columns))
    readings = np.asarray(log.columns["f3"])
    weak.columns["f3"] = readings[0] + 0.05 * (readings - readings[0])
    # The slope fixed and the home started at the truth: from the fixture's starts this
    # fit stopped with every press on a node of the response table in x (offset_x
    # 0.2 mm, reduced χ² 12-16, 2026-12-06): the table's linear interpolation has a
    # kink at each node, and with one channel silent the others did not pull it off.
    _, _, home, _, _ = stand_in
    start = dataclasses.replace(rig, slope_x=RigParameter.at(SLOPE), home=RigParameter(home, rig.home.low, rig.home.high))
    problem = make_fit_problem([weak], rig=start, drift=30.0, num_rays=16, sources=["weak"])
    assert problem.num_reference_gains == 3 and problem.gain_names[-1].endswith("/f3")
    result = fit_problem(problem, 1)
    assert result.converged and result.reduced_chi_square < 1.5
    assert result.gains_outside_the_mean() == [f"{FINGERTIP_SENSOR}/f3"]
    mean = np.prod([GAINS[name] for name in ("f0", "f1", "f2")]) ** (1 / 3)  # the reference's scale passes into E
    assert result.long_term_modulus.value == pytest.approx(2e5 * mean, rel=0.03)
    gains = result.gains
    for name in ("f0", "f1", "f2"):
        assert gains[f"{FINGERTIP_SENSOR}/{name}"].value == pytest.approx(GAINS[name] / mean, rel=0.01), name
    assert gains[f"{FINGERTIP_SENSOR}/f3"].value == pytest.approx(0.05 * GAINS["f3"] / mean, rel=0.05)


def test_the_rig_parameters_gradients_match_finite_differences(stand_in):
    """The residuals' derivatives in each fitted rig parameter (through the table's
    interpolation and the lagged travel) against central differences, away from
    the table's nodes (the start's offset puts every press on a node: the
    interpolation has a kink there, and forward mode takes one side's slope; so
    does the deepest hold, the table's lowest layer, at the start's home)."""
    *_, problem = stand_in
    from hydrotact.sysid._fit import make_initial_guess

    layout, x0 = make_initial_guess(problem, 1)
    x0[layout.names(problem).index("rig[offset_x]")] = np.arctanh(0.05 / 0.6)  # 0.05 mm: a quarter of a table step off the nodes
    x0[layout.names(problem).index("rig[home[1]]")] = np.arctanh(0.1123 / 0.4)  # 12.3 um (a quarter step) above the start
    x0 = jnp.asarray(x0)
    fn = lambda x: calc_residuals(x, problem.without_infos(), layout)
    for name in ("rig[offset_x]", "rig[home[1]]", "rig[lag_s]", "rig[slope_x[1]]"):
        k = layout.names(problem).index(name)
        derivative = np.asarray(jax.jvp(fn, (x0,), (jnp.zeros_like(x0).at[k].set(1.0),))[1])
        h = 1e-6
        difference = (np.asarray(fn(x0.at[k].add(h))) - np.asarray(fn(x0.at[k].add(-h)))) / (2 * h)
        scale = np.max(np.abs(difference))
        assert scale > 1.0, name  # the parameter moves the readings
        # piecewise linear in the table: a difference straddling a node differs there alone
        close = np.abs(derivative - difference) <= 1e-4 * scale
        assert close.mean() > 0.99, (name, close.mean())


def test_the_command_line_fits_a_stage_log_and_predicts_a_held_out_one(stand_in, tmp_path, capsys):
    """`fit --rig` on the stand-in, then `compare`: a second session of the same rig
    (another home, drift and holds) predicted from the fit, its home found within
    10 µm and each channel within 2 noise stds RMS (1.01-1.21 measured)."""
    log, truth, home, _, _ = stand_in
    path = tmp_path / "stage.parquet"
    write_log(path, log)
    rig = {
        "format": "hydrotact.rig", "version": 1, "units": {"length": "mm"}, "probe": PROBE,
        "offset_x": {"start": 0.0, "min": -0.6, "max": 0.6}, "home": {"start": 1e3 * home + 0.1, "min": 1e3 * home - 0.4, "max": 1e3 * home + 0.4},
        "lag_s": {"start": 0.02, "min": 0.0, "max": 0.15}, "slope_x": {"start": 0.0, "min": -0.15, "max": 0.15}, "table_step": {"xy": 0.2, "height": 0.05},
    }
    (tmp_path / "rig.json").write_text(json.dumps(rig))
    result = run_main(capsys, "fit", path, "--rig", tmp_path / "rig.json", "--terms", "1", "--rays", "16", "-o", tmp_path / "fit", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["rig"]["offset_x"]["value"] == pytest.approx(SHIFT, abs=10e-6) and report["rig"]["offset_x"]["identified"]
    assert report["rig"]["offset_y"] == {"value": 0.0, "std": 0.0, "identified": True, "fitted": False}
    assert report["rig"]["slope_x[1]"]["value"] == pytest.approx(SLOPE, abs=5e-3)
    assert report["drift_columns"][0] > 1 and report["gains_relative"]
    assert report["gains"][f"{FINGERTIP_SENSOR}/f0"]["value"] == pytest.approx(0.8, rel=0.03)
    assert (tmp_path / "fit" / "material.json").is_file() and (tmp_path / "fit" / "rig_table.npz").is_file()
    held_out, held_truth = simulate_stage_log(str(FINGERTIP_SENSOR), PROBE, MATERIAL, dataclasses.replace(SESSION, seed=11, hold_range=(8.0, 10.0)), num_rays=16)
    held_out = with_gains(held_out)
    held_out.metadata["sensor"] = str(FINGERTIP_SENSOR)
    held_out.columns["stage_x"] = np.asarray(held_out.columns["stage_x"]) - SHIFT
    write_log(tmp_path / "held_out.parquet", held_out)
    run = run_main(capsys, "compare", tmp_path / "fit", tmp_path / "held_out.parquet", "--labels", "-o", tmp_path / "compare", "--json")
    assert run.returncode == 0, run.stderr
    entry = json.loads(run.stdout)["logs"][0]
    held_home = rig_home(held_truth)
    assert entry["home_shift_m"]["value"] == pytest.approx(held_home - report["rig"]["home[1]"]["value"], abs=10e-6)
    for name, numbers in entry["channels"].items():
        assert numbers["rms_Pa"] < 2.0 * numbers["noise_Pa"], (name, numbers)
        assert numbers["r2"] > 0.99
    assert (tmp_path / "compare" / "held_out_predicted.parquet").is_file()
    # The labels: the command's (a dataset's 0.1 N contact: the stand-in's presses reach 6 mN) and the function's at 1 mN.
    with pytest.warns(LogWarning, match="uneven sampling"):  # the stand-in's 16 Hz clock jitters, as the strip's
        written = read_log(tmp_path / "compare" / "held_out_labelled.parquet")
    for name, values in label_rig_log(tmp_path / "fit", held_out, "held-out").columns.items():
        np.testing.assert_array_equal(written.columns[name], values, err_msg=name)
    _check_labels(label_rig_log(tmp_path / "fit", held_out, "held-out", contact_force=1e-3), held_out, held_truth)
    assert_one_line_error(run_main(capsys, "compare", tmp_path / "fit", tmp_path / "held_out.parquet", "--labels", "--tare", "first:0", "-o", tmp_path / "c2"), "--tare")
    # a lumped fit has no sensor to place the probe on
    assert_one_line_error(run_main(capsys, "fit", path, "--rig", tmp_path / "rig.json", "--lumped", "-o", tmp_path / "f2"), "--rig", "--lumped")
    assert not (tmp_path / "f2").exists()
    # free gains need force columns (a gain and E are not separable from pressures); a lumped fit has no gains
    free = run_main(capsys, "fit", path, "--rig", tmp_path / "rig.json", "--gains", "free", "-o", tmp_path / "f3")  # after the log's jitter warning
    assert free.returncode == 2 and "Traceback" not in free.stderr
    assert free.stderr.strip().splitlines()[-1].startswith("hydrotact: error: --gains free: no log has force columns")
    assert_one_line_error(run_main(capsys, "fit", path, "--lumped", "--gains", "relative", "-o", tmp_path / "f4"), "--gains", "--lumped")
    assert not (tmp_path / "f3").exists() and not (tmp_path / "f4").exists()


def _check_labels(labelled, log, truth):
    """The labels `compare --labels` wrote against the stand-in's truth: the log's own
    columns unchanged; on contact samples the tip's x is the stage's plus the true
    shift (10 µm: the fitted offset's error), and at the crown site, where the sphere
    first touches straight below its tip, the depth is the true travel past the
    touch (15 µm: the home's and the lag's errors); no contact label without the tip
    below the skin, and one run of contact per press."""
    for name, values in log.columns.items():
        np.testing.assert_array_equal(labelled.columns[name], values)
    contact = labelled.columns["contact"] > 0
    times, travel = np.asarray(log.columns["time"]), np.asarray(log.columns["indentation"])
    x, depth = labelled.columns["contact_x"], labelled.columns["depth"]
    assert np.all(np.isnan(x[~contact])) and np.all(np.isnan(depth[~contact])) and np.all(np.isfinite(depth[contact]))
    np.testing.assert_allclose(x[contact], np.asarray(log.columns["stage_x"])[contact] + SHIFT, atol=10e-6)
    assert np.all(depth[contact] > 0.0)
    crown = contact & (np.abs(np.asarray(log.columns["stage_x"]) + SHIFT) < 1e-9)
    true_depth = truth["contact_z_m"][1] - (truth["home_m"] - np.interp(times - truth["lag_s"], times, travel))  # the crown site: the session's x = 0
    assert crown.sum() > 50
    np.testing.assert_allclose(depth[crown], true_depth[crown], atol=15e-6)
    runs = np.flatnonzero(np.diff(np.concatenate([[0], contact.astype(int), [0]])) == 1)
    assert len(runs) == len(truth["presses"])


RIG = {"format": "hydrotact.rig", "version": 1, "units": {"length": "mm"}, "probe": PROBE, "home": {"start": 5.0, "min": 4.0, "max": 6.0}}


@pytest.mark.parametrize(
    "change, fragments",
    [
        ({"home": {"start": 5.0, "min": 6.0, "max": 4.0}}, ("home", "min", "below max")),
        ({"home": {"start": 7.0, "min": 4.0, "max": 6.0}}, ("home", "start 7", "outside")),
        ({"lag_s": {"start": 0.0, "min": -0.1, "max": 0.1}}, ("lag_s", "negative")),
        ({"probe": "cone:r=1"}, ("probe",)),
        ({"units": {"length": "inch"}}, ("units.length",)),
        ({"home": {"value": 5.0, "start": 5.0}}, ("home",)),
        ({"table_step": {"height": 1e-6}}, ("table_step.height",)),
        ({"max_travel": 0.0}, ("max_travel",)),
        ({"slope_x": {"value": 5.0}}, ("slope_x", "steeper than 0.3", "not an angle")),  # 5 degrees given as a slope
        ({"slope_x": {"start": 0.0, "min": 0.1, "max": -0.1}}, ("slope_x", "below max")),
    ],
)
def test_a_bad_rig_file_is_one_line_naming_the_field(tmp_path, change, fragments):
    path = tmp_path / "rig.json"
    path.write_text(json.dumps({**RIG, **change}))
    with pytest.raises(HydrotactError) as error:
        read_rig(path)
    message = str(error.value)
    assert message.startswith(str(path)) and "\n" not in message
    for fragment in fragments:
        assert fragment in message, message


def read_rig_default_travel(folder):
    (folder / "plain.json").write_text(json.dumps(RIG))
    return read_rig(folder / "plain.json").max_travel


def test_a_log_without_the_rigs_columns_is_refused_naming_it(tmp_path):
    path = tmp_path / "rig.json"
    path.write_text(json.dumps({**RIG, "columns": {"travel": "z"}, "max_travel": 6.0}))
    rig = read_rig(path)
    assert rig.home == RigParameter(5e-3, 4e-3, 6e-3) and rig.offset_x.fixed and rig.lag_s == RigParameter.at(0.0)
    assert rig.max_travel == pytest.approx(6e-3) and read_rig_default_travel(tmp_path) is None

    class Log:
        columns = {"indentation": np.zeros(3), "stage_x": np.zeros(3)}
        num_samples = 3

    with pytest.raises(HydrotactError, match=r"^a\.csv: the rig .* column 'z'"):
        rig.stage_columns(Log(), "a.csv")
