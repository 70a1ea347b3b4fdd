"""Fitting stage logs with the lumped press model, on the stage-log stand-in
(hydrotact.sim.simulate_stage_log: the fingertip4 sensor pressed at a grid of sites
by a stage at ~16 Hz with jitter, a gap, unknown onsets, 0.05 s lag, drift, a
clipped channel and a dead one), and comparing a fit with held-out logs.

Smoke size: 2 x 3 sites. The calibration logs share their poses (one depth past
the onset everywhere), as do the held-out ones (their homes differ, which moves the
travel column, not the poses), so each set is simulated once and the unit-response
cache serves the rest."""

import json
import warnings
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pyarrow.parquet as pq
import pytest

from hydrotact import HydrotactError, HydrotactWarning
from hydrotact.cli import main
from hydrotact.data import write_log
from hydrotact.sim import FINGERTIP_SENSOR, StageSession, make_site_grid, simulate_stage_log
from hydrotact.sysid import compare_fit, fit_press_logs, write_press_fit_outputs
from hydrotact.sysid.lumped import _press_solve as press_solve_module
from hydrotact.sysid.lumped._press_data import SITE_RESPONSE_SNR, find_kinks, site_responses
from hydrotact.sysid.lumped._press_windows import calc_depths
from hydrotact.visco import Prony

MATERIAL = Prony(jnp.asarray(150e3), jnp.asarray([18e3, 22e3]), jnp.asarray([0.5, 5.0]))
PROBE = "sphere:r=2mm,subdivisions=2"
SITES = tuple(map(tuple, make_site_grid(2, 3, pitch=1e-3)))
# Drift of 100-600 Pa over these ~100 s logs: the rates (up to ~6 Pa/s) of kPa over a real file.
CALIBRATION = dict(
    sites=SITES, depth_range=(0.6e-3, 0.6e-3), hold_range=(5.0, 10.0), rest_range=(0.1, 2.0), lead=2.0, gap_range=(4.0, 5.0), drift_range=(100.0, 600.0),
    home_spread=0.0, overload="f0", silent=("f3",),
)
# Another session: its stage's home (the travel's zero) differs, by 0.1 mm RMS.
HELD_OUT = dict(CALIBRATION, depth_range=(0.35e-3, 0.35e-3), hold_range=(12.0, 16.0), speed=0.5e-3, home_spread=0.1e-3)

# The stage as a real rig logs it (the MTL strip's logs): its travel read on the
# microcontroller's clock in 12.5 um motor steps, the time stamped by the PC on
# receipt (10 ms of jitter), and presses that turn at their deepest point (no hold).
RAW = dict(CALIBRATION, sites=SITES[:4], stamp_jitter_s=0.010, travel_step=12.5e-6, hold_range=(0.0, 0.0), rest_range=(1.0, 2.0), num_gaps=0)
# A session of 20 s holds on a skin with a slow term (tau 40 s, 30 % of E_inf) and a
# drift of 600 Pa over its 144 s, of the rate of a real file's kPa: a drift spline with
# knots 30 s apart could take up the slow relaxation.
LONG_HOLDS = dict(HELD_OUT, hold_range=(20.0, 20.0), num_gaps=0, drift_range=(600.0, 600.0), overload=None)
SLOW = Prony(jnp.asarray(150e3), jnp.asarray([18e3, 45e3]), jnp.asarray([0.5, 40.0]))


# The stand-in's logs are messy by design (a dead channel, a clipped one, uneven
# sampling, presses begun in gaps): the fit and compare warn about each, and the tests
# that check those warnings record them (_warned).
pytestmark = pytest.mark.filterwarnings("ignore::hydrotact.HydrotactWarning")


def _warned(call, *args, **kwargs):
    """(call's result, the messages of the HydrotactWarnings it issued); any other
    warning goes on as before (an error under the suite's settings)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = call(*args, **kwargs)
    for warning in caught:
        if not issubclass(warning.category, HydrotactWarning):
            warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)
    return result, [str(warning.message) for warning in caught if issubclass(warning.category, HydrotactWarning)]


def _session(settings, seed):
    return StageSession(**settings, seed=seed)


@pytest.fixture(scope="module")
def stand_in(tmp_path_factory):
    folder = tmp_path_factory.mktemp("stage_logs")
    logs = {}
    for name, settings, seeds in (("calibration", CALIBRATION, (1, 2, 3)), ("held_out", HELD_OUT, (4, 5, 6))):
        for seed in seeds:
            log, truth = simulate_stage_log(str(FINGERTIP_SENSOR), PROBE, MATERIAL, _session(settings, seed), num_rays=16)
            path = folder / f"{name}{seed}.parquet"
            write_log(path, log)
            logs.setdefault(name, []).append((path, log, truth))
    return logs


@pytest.fixture(scope="module")
def one_log_fit(stand_in):
    path, log, truth = stand_in["calibration"][0]
    fit, messages = _warned(fit_press_logs, [log], [str(path)], terms=2, estimate_lag=True, saturation_pa=125e3)
    return fit, truth, messages


def _true_onsets(fit, log_index, truth):
    log = fit.logs[log_index]
    sites = fit.sites[log.press_site]
    index = [int(np.argmin(np.abs(truth["sites"] - position).sum(axis=1))) for position in sites]
    return np.array([[p["onset_travel_m"] for p in truth["presses"] if p["site"] == s][0] for s in index])


def test_one_log_recovers_the_shape_onsets_and_lag(one_log_fit):
    fit, truth, messages = one_log_fit
    assert fit.converged and 0.8 < fit.reduced_chi_square < 1.25
    ratios = np.asarray(MATERIAL.moduli) / float(MATERIAL.long_term_modulus)
    for k in range(2):
        assert fit.taus[k].identified and fit.ratios[k].identified
        assert abs(fit.taus[k].value - float(MATERIAL.taus[k])) < 3 * fit.taus[k].std
        assert abs(fit.ratios[k].value - ratios[k]) < 3 * fit.ratios[k].std
    step = float(np.median(np.diff(fit.logs[0].times)))
    assert abs(fit.lags[0].value - truth["lag_s"]) < step / 4
    # The onsets against the geometric first touch. With a law of its own per site
    # and one press per site, a press's onset is told only by its first samples of
    # contact, and the cost has several minima ~1 chi2 apart in the onsets: on this
    # stand-in the fit's onsets are 20-210 um off (median ~80 um: 1-2 samples of the
    # 1 mm/s approach), and the fit started at the true onsets ends 5 chi2 higher,
    # 10-290 um off. A press between the barometers' receptive fields reads nothing
    # until its patch grows into one: its law's onset comes later still.
    error = np.abs(fit.onsets[0] - _true_onsets(fit, 0, truth))
    assert np.median(error) < 2e-3 * step and error.max() < 0.3e-3, error
    assert fit.channels == ("f0", "f1", "f2")  # f3 is dead
    assert any("f3" in message and "not fitted" in message for message in messages)
    assert any("clipped" in message and "f0" in message for message in messages)


def test_a_fit_far_from_the_noise_tries_other_shapes(one_log_fit, stand_in, monkeypatch, capsys):
    """starts="auto": a fit that ends above a reduced χ² of RESTART_REDUCED_CHI2 is
    tried from the next relaxation shape, and the lowest χ² is kept. Here a first
    start of τ x 0.05 and Eᵢ/E∞ 0.01 is put before the default ones: from it alone the
    fit ends in a worse local minimum than the default start's (reduced χ² 4.4 on the
    Intel Xeon and the earlier AMD EPYC machines, 1.18 on another AMD EPYC, 2026-12-07:
    which minimum it reaches depends on the machine's round-off, so the threshold is
    put between the two ends as this machine finds them); "auto" goes on to the next
    start, which is the default fit's. (The default starts' own case: notebook 02's
    stage log cut before its gap, 2 presses, 40 % relaxation, ends at 10.8 from the
    first and at 1.01 from the second.)"""
    from hydrotact.cli.fit import print_press_table
    from hydrotact.sysid.lumped._press_report import make_press_report

    default, truth, _ = one_log_fit
    path, log, _ = stand_in["calibration"][0]
    monkeypatch.setattr(press_solve_module, "SHAPE_STARTS", ((0.05, 0.01), *press_solve_module.SHAPE_STARTS))
    alone = fit_press_logs([log], [str(path)], terms=2, estimate_lag=True, saturation_pa=125e3, starts=1)
    # The first three starts, in order: the bad one, the default fit's, the next; each
    # start's own χ² at the end of its solve, before the onset scan.
    every = fit_press_logs([log], [str(path)], terms=2, estimate_lag=True, saturation_pa=125e3, starts=3)
    assert every.num_starts == len(every.start_chi_squares) == 3
    bad_end, default_end = every.start_chi_squares[:2]
    assert default.num_starts == 1 and default.start_chi_squares[0] == pytest.approx(default_end, rel=1e-9)
    assert default_end / default.dof < press_solve_module.RESTART_REDUCED_CHI2
    assert alone.num_starts == 1 and alone.start_chi_squares[0] == pytest.approx(bad_end, rel=1e-9)
    assert bad_end > 1.05 * default_end and alone.chi_square > default.chi_square
    monkeypatch.setattr(press_solve_module, "RESTART_REDUCED_CHI2", float(np.sqrt(bad_end * default_end)) / default.dof)
    again = fit_press_logs([log], [str(path)], terms=2, estimate_lag=True, saturation_pa=125e3)
    assert again.num_starts == 2 and again.start_chi_squares == pytest.approx(every.start_chi_squares[:2], rel=1e-9)
    assert again.chi_square == pytest.approx(default.chi_square, rel=1e-9)
    assert every.chi_square <= again.chi_square * (1 + 1e-9)
    # The report and the command line's table give each start's end.
    report = make_press_report(every)
    assert report["num_starts"] == 3 and report["start_chi_squares"] == list(every.start_chi_squares)
    capsys.readouterr()
    print_press_table(report)
    assert f"fitted from 3 relaxation shapes (--starts; χ² at their ends {bad_end:,.6g}, {default_end:,.6g}," in capsys.readouterr().out
    with pytest.raises(HydrotactError, match="--starts"):
        fit_press_logs([log], [str(path)], terms=2, starts=0)


def test_a_law_is_fitted_only_where_the_channel_responds():
    """Per (channel, site): fitted when the channel moves more than SITE_RESPONSE_SNR
    noise stds in some press there, in some log; where no press measured it (NaN:
    clipped through the hold, or a press begun in a gap), it is fitted."""
    first = SimpleNamespace(noise=np.ones(3), press_site=np.array([0, 1, 0, 2]), responses=np.array([[50.0, 0.5, 2.9], [1.0, np.nan, 0.2], [0.3, 0.1, 0.0], [np.nan] * 3]))
    second = SimpleNamespace(noise=np.ones(3), press_site=np.array([2]), responses=np.array([[0.0, 0.0, SITE_RESPONSE_SNR + 0.1]]))
    expected = np.array([[True, False, False], [False, True, False], [False, False, True]])  # (C, S)
    np.testing.assert_array_equal(site_responses([first, second], 3), expected)


def test_masked_samples_change_nothing(one_log_fit, stand_in):
    """Perturb every sample the fit masked (clipped, at stage kinks): same fit."""
    fit, _, _ = one_log_fit
    path, log, _ = stand_in["calibration"][0]
    masked = ~fit.logs[0].mask
    assert masked.any()
    columns = dict(log.columns)
    for c, name in enumerate(fit.channels):
        columns[name] = np.where(masked[:, c], columns[name] + 5e3 * np.random.default_rng(c).random(len(masked)), columns[name])
    changed = type(log)(metadata=log.metadata, columns=columns)
    # Clipped readings pushed further up stay at or above the part's limit (the
    # stand-in's sensor is not a built-in one: give the limit).
    again = fit_press_logs([changed], [str(path)], terms=2, estimate_lag=True, saturation_pa=125e3)
    np.testing.assert_array_equal(again.logs[0].mask, fit.logs[0].mask)
    assert abs(again.taus[1].value - fit.taus[1].value) < 1e-6 * fit.taus[1].value


@pytest.fixture(scope="module")
def raw_log():
    return simulate_stage_log(str(FINGERTIP_SENSOR), PROBE, MATERIAL, _session(RAW, 7), num_rays=16)


def test_kinks_are_where_the_stage_turns_however_its_clock_jitters(raw_log):
    """The stage's travel as a rig logs it: along a steady ramp the speed between two
    samples swings by a quarter (motor steps, time stamps on receipt). Kinks are
    found only where the stage starts, turns and stops (within two samples of the
    instant), and each of those is found. (Sample by sample, every ramp and every
    peak was masked, and no press had a sample left to measure its response.)"""
    log, truth = raw_log
    times = np.asarray(log.times)
    masked = find_kinks(times, log.columns["indentation"])
    step = float(np.median(np.diff(times)))
    turns = [t for press in truth["presses"] for t in (press["start_s"], press["start_s"] + (press["end_s"] - press["start_s"]) / 2, press["end_s"])]
    nearest = np.min(np.abs(times[:, None] - np.asarray(turns)[None, :]), axis=1)
    assert np.all(nearest[masked] < 2.5 * step), times[masked & (nearest >= 2.5 * step)]
    assert all(np.any(masked & (np.abs(times - turn) < 1.5 * step)) for turn in turns)
    assert masked.sum() <= 4 * len(turns)  # the two samples either side of the instant, and one more on each side


def test_raw_stage_travel_and_presses_without_a_hold_fit_with_the_lag(raw_log):
    """Raw travel (motor steps, stamped on receipt) and presses with no hold, the lag
    estimated: every channel that moves is fitted (no press is measured at a masked
    peak), down to the noise, and the lag comes back. (Refused before: "no channel
    responds to the presses in any log".)"""
    log, truth = raw_log
    fit, messages = _warned(fit_press_logs, [log], ["raw.parquet"], terms=2, estimate_lag=True, saturation_pa=125e3)
    assert fit.channels == ("f0", "f1", "f2"), messages  # f3 is dead
    # Not quite to the noise: a stamp 10 ms off moves the travel the model reads by
    # ~10 um on a 1 mm/s ramp, several times the 2 Pa noise there (1.61 here; 0.94
    # with exact stamps, the same log otherwise).
    assert fit.converged and fit.reduced_chi_square < 2.0, fit.reduced_chi_square
    step = float(np.median(np.diff(fit.logs[0].times)))
    assert abs(fit.lags[0].value - truth["lag_s"]) < step / 3, fit.lags[0]


def test_a_slow_relaxation_over_long_holds_is_told_from_the_drift():
    """The slow term comes back beside a drift that could mimic it, with the baseline
    fitted jointly (the default): the spline cannot follow a relaxation that restarts
    with every press. Learned from the unloaded samples alone (--drift-from
    unloaded) the baseline cannot take up any relaxation, but the model's own misfit
    then passes into the shape instead of the drift: on this log the slow term comes
    back ~3 std low (tau 28 +- 4 s, ratio 0.22 +- 0.03; reduced chi2 1.34 against
    1.13), so it is the check, not the default."""
    log, _ = simulate_stage_log(str(FINGERTIP_SENSOR), PROBE, SLOW, _session(LONG_HOLDS, 7), num_rays=16)
    truth = (float(SLOW.moduli[1] / SLOW.long_term_modulus), float(SLOW.taus[1]))
    for drift_from in ("all", "unloaded"):
        fit = fit_press_logs([log], ["long_holds.parquet"], terms=2, estimate_lag=True, saturation_pa=125e3, drift_from=drift_from)
        slow = int(np.argmax([tau.value for tau in fit.taus]))
        ratio, tau = fit.ratios[slow], fit.taus[slow]
        assert fit.converged and fit.drift_from == drift_from and tau.identified and ratio.identified
        if drift_from == "all":
            assert abs(tau.value - truth[1]) < 3 * tau.std and abs(ratio.value - truth[0]) < 3 * ratio.std, (ratio, tau)
            assert fit.reduced_chi_square < 1.3
        else:
            assert 15.0 < tau.value < 80.0 and 0.1 < ratio.value < 0.6, (ratio, tau)  # a slow term, not taken up by anything


def test_calibrate_on_three_and_compare_three(stand_in, tmp_path):
    calibration = stand_in["calibration"]
    fit = fit_press_logs([log for _, log, _ in calibration], [str(path) for path, _, _ in calibration], terms=2, estimate_lag=True)
    assert fit.converged and fit.reduced_chi_square < 1.3
    # Jointly, the three logs (calibration2 has a press that began in its gap: kept
    # for its memory) give the Prony terms within their standard errors (0.3-1.1
    # sigma here; before that press was kept, tau2 was 2.7 sigma off).
    ratios = np.asarray(MATERIAL.moduli) / float(MATERIAL.long_term_modulus)
    for k in range(2):
        assert abs(fit.taus[k].value - float(MATERIAL.taus[k])) < 3 * fit.taus[k].std
        assert abs(fit.ratios[k].value - ratios[k]) < 3 * fit.ratios[k].std
    # The model's own χ² (compare's) against the projection's the solver minimised:
    # they differ only where the push starts or ends (0.2 % here; 2 % before the
    # amplitudes were polished by more passes, 70 % on the benchmark's log before a
    # channel's law was fixed at 0 where it does not respond).
    assert abs(fit.chi_square / fit.solver_chi_square - 1.0) < 0.05
    report = write_press_fit_outputs(fit, tmp_path / "fit", paths=[str(path) for path, _, _ in calibration])
    material = json.loads((tmp_path / "fit" / "material.json").read_text())
    assert material["modulus_scale"] == "relative" and material["channel_law"]["channels"] == ["f0", "f1", "f2"]
    # The stage's sites, plus one without a position per press begun in a gap (calibration2 has one).
    assert [len(site["position_m"]) for site in material["channel_law"]["sites"]].count(2) == len(SITES)
    assert (tmp_path / "fit" / material["channel_law"]["covariance_file"]).is_file()
    held_out = [path for path, _, _ in stand_in["held_out"]]
    result, messages = _warned(compare_fit, tmp_path / "fit", held_out, tmp_path / "compare")
    assert any("uneven sampling" in message for message in messages)
    assert "lower bound" in result["prediction_band"]
    onset_of_site = {press["site"]: press["onset_travel_m"] for press in calibration[0][2]["presses"]}
    for entry, (_, _, truth) in zip(result["logs"], stand_in["held_out"]):
        # The held-out session's home, fitted: within 2 µm of the truth (0.4-0.7 µm
        # measured, for shifts of 65-106 µm).
        home = np.mean([press["onset_travel_m"] - onset_of_site[press["site"]] for press in truth["presses"]])
        assert abs(entry["home_shift_m"]["value"] - home) < 2e-6, (entry["source"], entry["home_shift_m"], home)
        for name, channel in entry["channels"].items():
            # The relaxation's shape over each hold within 1.5 x the readings' noise,
            # the whole log within 2 x: at depths and speeds the fit never saw, each
            # log's baseline from its own unloaded samples, 1.1-1.5 x; with the band
            # (0.5-1 Pa, noise ~2 Pa), 1.0-1.4 (a first-order band: each site's onset
            # trades against its law along a curved valley).
            assert channel["hold_shape_rms_Pa"] < 1.5 * channel["noise_Pa"], (entry["source"], name, channel)
            assert channel["rms_Pa"] < 2.0 * channel["noise_Pa"], (entry["source"], name, channel)
            assert 0.0 < channel["prediction_std_Pa"] < channel["noise_Pa"], (entry["source"], name, channel)
            assert channel["normalized_rms"] < 1.5, (entry["source"], name, channel)
            assert channel["r2"] > 0.95  # a channel that barely moves has an R² near its noise
    # --tare first:S: each channel's baseline is the mean of its first S seconds (the
    # log starts at rest; before, a NaN-padded mean made every prediction NaN, "R² 1").
    first = compare_fit(tmp_path / "fit", held_out[:1], tmp_path / "first", tare="first:1.5")
    table = pq.read_table(tmp_path / "first" / f"{held_out[0].stem}_predicted.parquet").to_pydict()
    times = np.asarray(table["time"]) - table["time"][0]
    for name, channel in first["logs"][0]["channels"].items():
        rows = (times <= 1.5) & (np.asarray(table[f"{name}_compared"]) == 1)
        np.testing.assert_allclose(np.asarray(table[f"{name}_predicted"])[times <= 1.5], np.mean(np.asarray(table[name])[rows]), rtol=1e-12)
        assert np.isfinite(channel["rms_Pa"]) and channel["r2"] < 1.0
    # compare_log in a float32 session computes in float64 all the same (absolute
    # readings of ~1e5 Pa in float32 are 8 mPa apart, and its normal equations fail).
    from hydrotact.sysid import compare_log, read_fit

    document, fitted_report, covariance = read_fit(tmp_path / "fit")
    with jax.enable_x64(False):
        single = compare_log(document, fitted_report, stand_in["held_out"][0][1], str(held_out[0]), covariance=covariance, drift=fitted_report.get("drift"))
    table = pq.read_table(tmp_path / "compare" / f"{held_out[0].stem}_predicted.parquet").to_pydict()
    assert single.predicted.dtype == np.float64
    np.testing.assert_allclose(single.predicted[:, 0], np.asarray(table[f"{single.channels[0]}_predicted"]), rtol=1e-12)
    # Without the home shift, the onsets are off by 65-106 µm: the prediction misses by far more.
    fixed = compare_fit(tmp_path / "fit", held_out[:1], tmp_path / "fixed", home="fit")
    assert fixed["logs"][0]["home_shift_m"] is None
    assert fixed["logs"][0]["channels"]["f2"]["normalized_rms"] > 5 * result["logs"][0]["channels"]["f2"]["normalized_rms"]
    # On the fit's own logs, with the baseline solved over all their samples (the
    # fit's own baseline, given its laws): the fit's residuals, sample by sample.
    own = compare_fit(tmp_path / "fit", [calibration[0][0]], tmp_path / "own", tare="all")
    fitted = report["residuals"][0]["channels"]
    for name, channel in own["logs"][0]["channels"].items():
        assert channel["rms_Pa"] == pytest.approx(fitted[name]["rms_Pa"], rel=1e-6)
    predicted = pq.read_table(tmp_path / "own" / f"{calibration[0][0].stem}_predicted.parquet").to_pydict()
    log = fit.logs[0]
    for c, name in enumerate(fit.channels):
        error = (np.asarray(calibration[0][1].columns[name]) - np.asarray(predicted[f"{name}_predicted"])) / log.noise[c]
        np.testing.assert_allclose(np.where(log.mask[:, c], error, 0.0), fit.residuals[0][:, c], atol=1e-8)


def test_a_press_deeper_than_any_fitted_is_predicted_past_the_laws_reach(stand_in, tmp_path):
    """Fitted on the three held-out sessions (presses 0.35 mm past the onset), the
    first calibration session (0.6 mm: 70 % deeper than any fitted) is predicted to
    13-35 Pa RMS per channel (noise ~2 Pa; its relaxation and laws seen at 0.35 mm
    only): past each site's reach, the deepest depth past their onsets its laws were
    fitted to, they go on as their value there times (δ / reach)². With the fitted
    sums of powers at any depth (at 7b342f9), 25, 110 and 86 Pa."""
    shallow = stand_in["held_out"]
    paths = [str(path) for path, _, _ in shallow]
    fit = fit_press_logs([log for _, log, _ in shallow], paths, terms=2, estimate_lag=True)
    write_press_fit_outputs(fit, tmp_path / "fit", paths=paths)
    sites = json.loads((tmp_path / "fit" / "material.json").read_text())["channel_law"]["sites"]
    reach = np.zeros(len(sites))
    for log, onsets, lag in zip(fit.logs, fit.onsets, fit.lags):
        depths = np.asarray(calc_depths(log.to_data(len(sites)), jnp.asarray(onsets), lag.value))
        for s in range(len(sites)):
            reach[s] = max(reach[s], depths[(log.press >= 0) & (log.press_site[np.maximum(log.press, 0)] == s)].max(initial=0.0))
    np.testing.assert_allclose([site["reach_m"] for site in sites], reach, rtol=1e-12)
    assert np.all(reach[[len(site["position_m"]) == 2 for site in sites]] > 0.3e-3)
    result = compare_fit(tmp_path / "fit", [stand_in["calibration"][0][0]], tmp_path / "deeper")
    for name, channel in result["logs"][0]["channels"].items():
        assert channel["rms_Pa"] < 40.0, (name, channel)


class _Stopped(Exception):
    pass


def test_a_solver_chosen_by_name_steps_with_the_press_models_xtol(stand_in, tmp_path, monkeypatch):
    """The default or a named Levenberg-Marquardt (the command line's --solver lm)
    stops at PRESS_XTOL, through fit_press_logs and through fit_logs; a solver
    object is used as given."""
    from hydrotact.sysid import LumpedFit, fit_logs, make_solver
    from hydrotact.sysid.lumped import _press_fit as press_fit_module

    seen = []

    def spy(count, logs, num_sites, estimate_lag, lag, solver, *rest, **keywords):
        seen.append(solver)
        raise _Stopped

    monkeypatch.setattr(press_fit_module, "fit_terms", spy)
    path, log, _ = stand_in["calibration"][0]
    own = make_solver("lm")
    for solver in (None, "lm", own):
        with pytest.raises(_Stopped):
            fit_press_logs([log], [str(path)], terms=2, solver=solver)
    with pytest.raises(_Stopped):
        fit_logs([path], tmp_path / "fit", method=LumpedFit(), terms=2, solver="lm")
    assert [s.xtol for s in seen] == [press_fit_module.PRESS_XTOL, press_fit_module.PRESS_XTOL, own.xtol, press_fit_module.PRESS_XTOL]
    assert press_fit_module.PRESS_XTOL != own.xtol


def test_fit_and_compare_from_the_command_line(stand_in, tmp_path, capsys):
    """--terms auto (the default) picks the stand-in's two terms by BIC from fits of
    1-3 (one compiled program, the terms past each count off), and the fit is
    reported in its own layout."""
    path = stand_in["calibration"][1][0]
    code = main(["fit", str(path), "--lumped", "--terms", "auto", "--estimate-lag", "-o", str(tmp_path / "fit")])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "τ2" in out and "E2/E∞" in out and "τ3" not in out and "f3" in err
    report = json.loads((tmp_path / "fit" / "report.json").read_text())
    assert report["num_terms"] == 2 and len(report["prony_terms"]) == 2
    np.testing.assert_allclose(sorted(term["tau_s"]["value"] for term in report["prony_terms"]), [0.5, 5.0], rtol=0.15)
    for name in ("material.json", "report.json", "traces.png", "residuals.png", "relaxation.png"):
        assert (tmp_path / "fit" / name).is_file()
    code = main(["compare", str(tmp_path / "fit"), str(stand_in["held_out"][0][0]), "-o", str(tmp_path / "compare")])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "hold shape RMS" in out and "prediction band" in out and "its home" in out and (tmp_path / "compare" / "compare.json").is_file()
    assert (tmp_path / "compare" / "compare_traces.png").is_file()
    predicted = pq.read_table(tmp_path / "compare" / f"{stand_in['held_out'][0][0].stem}_predicted.parquet").to_pydict()
    assert np.all(np.asarray(predicted["f0_predicted_std"]) > 0.0)
    # A bad --home, or a covariance file that does not match the law: one line, nothing written.
    with pytest.raises(SystemExit) as exit_info:
        main(["compare", str(tmp_path / "fit"), str(stand_in["held_out"][0][0]), "--home", "guess", "-o", str(tmp_path / "bad")])
    assert exit_info.value.code == 2
    assert "--home" in capsys.readouterr().err and not (tmp_path / "bad").exists()
    assert main(["compare", str(tmp_path / "fit"), str(stand_in["held_out"][0][0]), "--labels", "-o", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err
    assert "--labels" in err and "not a fit through a rig" in err and "Traceback" not in err and not (tmp_path / "bad").exists()
    np.savez(tmp_path / "fit" / "channel_law_covariance.npz", qq=np.eye(3), qa=np.zeros((3, 3, 4)), aa=np.zeros((3, 4, 4)))
    assert main(["compare", str(tmp_path / "fit"), str(stand_in["held_out"][0][0]), "-o", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err
    assert "channel_law_covariance.npz" in err and "refit" in err and "Traceback" not in err and not (tmp_path / "bad").exists()


def test_parameters_the_logs_cannot_identify_are_flagged(stand_in):
    """Three terms on a log whose holds are 5-10 s: at least one is not identified,
    and it says so instead of printing it as exact."""
    path, log, _ = stand_in["calibration"][0]
    fit, messages = _warned(fit_press_logs, [log], [str(path)], terms=3, estimate_lag=True)
    flagged = [t for t in fit.taus if not t.identified] + [r for r in fit.ratios if not r.identified]
    assert flagged and any("not identified" in message for message in messages)


def test_a_log_that_does_not_respond_is_skipped(stand_in):
    path, log, _ = stand_in["calibration"][0]
    flat = dict(log.columns)
    rng = np.random.default_rng(0)
    for name in log.metadata["channels"]:
        flat[name] = 101325.0 + 2.0 * rng.standard_normal(log.num_samples)
    other_path, other, _ = stand_in["calibration"][1]
    fit, messages = _warned(fit_press_logs, [type(log)(metadata=log.metadata, columns=flat), other], ["flat.parquet", str(other_path)], terms=2)
    assert "flat.parquet" in fit.skipped and len(fit.logs) == 1
    assert any("flat.parquet: skipped" in message for message in messages)
    with pytest.raises(HydrotactError, match="no channel responds"):
        fit_press_logs([type(log)(metadata=log.metadata, columns=flat)], ["flat.parquet"], terms=2)


def test_the_prediction_band_derivatives_match_finite_differences(one_log_fit, stand_in, tmp_path, monkeypatch):
    """The band's first-order propagation: the elastic part's derivatives in the law's
    parameters (relaxation shape, sites' onsets, lag) and in the home shift, against
    central differences on a held-out log. A step can straddle a kink of the elastic
    part at a sample (one did, in a site's onset, on a new machine whose round-off moved
    the fit: one sample of 1754 off by a third): there the two one-sided differences
    disagree and the derivative must equal one of them (found at 4 of 5262 entries; at
    most 1 % allowed). Where they disagree without a kink, the central difference must
    match: a sample just past its press's onset, where δ^1.5's curvature grows as
    δ^-0.5, has one-sided differences 1.3 % apart at a 20 nm step and the derivative
    their mean to 5 digits (one entry, in a site's onset: the test failed there from
    2026-12-02, marked xfail, until this case was told from a kink)."""
    from hydrotact.sysid.lumped import _compare

    fit, _, _ = one_log_fit
    write_press_fit_outputs(fit, tmp_path / "fit", paths=[str(stand_in["calibration"][0][0])])
    calls = []
    predict = _compare._predict
    monkeypatch.setattr(_compare, "_predict", lambda *args: calls.append(args) or predict(*args))
    compare_fit(tmp_path / "fit", [stand_in["held_out"][0][0]], tmp_path / "compare")
    model, amplitudes, shift = calls[0]

    def check(q_step, shift_step, expected, size):
        """The derivative `expected` (T, C) times the step against the differences of the elastic part."""
        plus, here, minus = (np.asarray(model.elastic(model.q + scale * q_step, amplitudes, shift + scale * shift_step)) for scale in (1.0, 0.0, -1.0))
        forward, backward, central = plus - here, here - minus, (plus - minus) / 2.0
        floor = 1e-6 * np.abs(expected).max() + 1e-12
        kink = np.abs(forward - backward) > 1e-2 * np.maximum(np.abs(forward), np.abs(backward)) + floor
        assert np.count_nonzero(kink) <= 0.01 * kink.size, np.argwhere(kink)
        nearest = np.minimum(np.minimum(np.abs(forward - expected), np.abs(backward - expected)), np.abs(central - expected))
        assert np.all(nearest[kink] <= 1e-3 * np.abs(expected[kink]) + floor), (size, np.argwhere(kink))
        assert np.linalg.norm((central - expected)[~kink]) <= 1e-4 * np.linalg.norm(expected[~kink]) + 1e-9, size

    with jax.enable_x64(True):
        elastic, _, _, by_q, by_shift = predict(model, amplitudes, shift)
        k = model.num_terms
        steps = np.concatenate([np.full(2 * k, 1e-5), np.full(model.data.num_sites, 2e-8), [1e-6]])
        rng = np.random.default_rng(0)
        for direction in [np.eye(len(steps))[i] * steps for i in range(len(steps))] + [steps * rng.standard_normal(len(steps))]:
            check(jnp.asarray(direction), 0.0, np.einsum("tcq,q->tc", np.asarray(by_q), direction), direction)
        check(0.0, 1e-8, 1e-8 * np.asarray(by_shift), "home shift")
    assert float(np.abs(by_shift).max()) > 0.0 and np.asarray(elastic).max() > 0.0
