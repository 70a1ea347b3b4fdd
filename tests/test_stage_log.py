"""The stage-session stand-in for real logs: the contact onsets against the closed
form, the clock, the gaps, the lag, the drift, the clipping and the silent channel."""

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

from hydrotact import HydrotactError
from hydrotact.data import LogWarning, read_log, write_log
from hydrotact.sim import StageSession, make_site_grid, simulate_stage_log
from hydrotact.visco import Prony

PROBE_RADIUS = 2e-3
PROBE = "sphere:r=2mm,subdivisions=2"
MATERIAL = Prony(jnp.asarray(150e3), jnp.asarray([18e3, 22e3]), jnp.asarray([0.5, 5.0]))
# sphere8's barometers read the elastomer's pressure 10-14 mm under the skin: a ball of
# 2 mm radius pressed 1-1.6 mm deep moves them by 47-78 Pa. The drift is a tenth of the
# default's (30-300 Pa over the 40 s log; the default is sized for kPa presses) so that
# b0's overload clips around its largest press rather than wherever the drift peaks.
SESSION = StageSession(
    sites=tuple(map(tuple, make_site_grid(2, 3, pitch=1e-3))),
    depth_range=(1.0e-3, 1.6e-3),
    hold_range=(2.0, 4.0),
    rest_range=(0.2, 1.0),
    lead=2.0,
    gap_range=(3.0, 4.0),
    overload="b0",
    silent=("b7",),
    drift_range=(30.0, 300.0),
    seed=5,
)


@pytest.fixture(scope="module")
def stage_log():
    return simulate_stage_log("sphere8", PROBE, MATERIAL, SESSION, num_rays=16)


def test_onsets_are_where_the_sphere_first_touches_the_dome(stage_log):
    """sphere8's skin is a sphere of 10 mm about (0, 0, 5 mm): a ball of radius r
    above (x, y) first touches it when the centres are R + r apart. The meshes are
    faceted (the skin's chords sag by up to ~25 um at this mesh size), hence the
    tolerance; the onsets differ between the sites by more than that."""
    _, truth = stage_log
    sites = truth["sites"]
    rho2 = np.sum(sites**2, axis=1)
    exact = 5e-3 + np.sqrt((10e-3 + PROBE_RADIUS) ** 2 - rho2) - PROBE_RADIUS
    np.testing.assert_allclose(truth["contact_z_m"], exact, atol=40e-6)
    onsets = np.array([press["onset_travel_m"] for press in truth["presses"]])
    assert np.ptp(onsets) > 50e-6
    np.testing.assert_allclose(np.diff(onsets), -np.diff(truth["contact_z_m"]), atol=1e-12)


def test_clock_gaps_and_stage_columns(stage_log):
    log, truth = stage_log
    steps = np.diff(log.times)
    regular = steps[steps < 1.0]
    assert abs(np.median(regular) - 1 / 16) < 0.005
    assert SESSION.jitter_s[0] * 0.8 < np.std(regular) < SESSION.jitter_s[1] * 1.2
    assert 3.0 <= steps.max() <= 4.2 and np.sum(steps > 1.0) == 1  # one gap
    assert log.times[0] >= SESSION.lag_s
    for press in truth["presses"]:
        during = (log.times >= press["start_s"]) & (log.times <= press["end_s"])
        for axis, column in enumerate(("stage_x", "stage_y")):
            np.testing.assert_array_equal(log.columns[column][during], truth["sites"][press["site"], axis])
        deepest = press["onset_travel_m"] + press["depth_m"]
        assert np.max(log.columns["indentation"][during]) == pytest.approx(deepest, abs=1e-12)


def test_lag_clipping_silence_and_drift(stage_log):
    log, truth = stage_log
    channels = list(truth["channels"])
    readings = log.channels
    upper = 125000.0  # BMP388
    clipped = truth["clipped"]
    assert clipped[:, channels.index("b0")].sum() > 3 and clipped.sum() == clipped[:, channels.index("b0")].sum()
    np.testing.assert_array_equal(readings[clipped], upper)
    assert np.all(readings[~clipped] < upper)
    # The silent channel is its baseline, drift and noise only.
    silent = readings[:, channels.index("b7")] - truth["drift"][:, channels.index("b7")]
    assert np.std(silent) == pytest.approx(SESSION.noise_rms, rel=0.2)
    drift = np.ptp(truth["drift"], axis=0)
    assert np.all(drift > 0.5 * SESSION.drift_range[0]) and np.all(drift < 2 * SESSION.drift_range[1])
    # Every reading is the elastomer pressure lag_s earlier, plus baseline, drift and
    # noise; read without the lag, the ramps leave residuals many times the noise.
    times, elastic = truth["elastic"]
    lags = np.linspace(0.0, 0.1, 21)
    misfit = []
    for lag in lags:
        model = np.column_stack([np.interp(log.times - lag, times, elastic[:, c]) for c in range(len(channels))])
        residual = (readings - truth["baseline_pa"] - truth["drift"] - model)[~clipped.any(axis=1)] / SESSION.noise_rms
        misfit.append(np.mean(residual**2))
        if lag == SESSION.lag_s:
            assert 0.8 < np.std(residual) < 1.2
    assert abs(lags[int(np.argmin(misfit))] - SESSION.lag_s) < 0.006, misfit


def test_the_log_reads_back_and_bad_sessions_are_refused(stage_log, tmp_path):
    log, _ = stage_log
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LogWarning)
        again = read_log(write_log(tmp_path / "stage.parquet", log))
    said = " ".join(str(w.message) for w in caught)
    assert "uneven sampling" in said and "1 gap over 3x the median step" in said  # what real logs get too
    assert again.num_samples == log.num_samples and set(again.columns) == set(log.columns)
    with pytest.raises(HydrotactError, match="no channel 'b9' on sensor sphere8"):
        simulate_stage_log("sphere8", PROBE, MATERIAL, StageSession(silent=("b9",)))
    with pytest.raises(HydrotactError, match="site 1 at \\(30, 0\\) mm is not above the skin"):
        simulate_stage_log("sphere8", PROBE, MATERIAL, StageSession(sites=((30e-3, 0.0),)))


def test_presses_and_sites_are_found_as_the_stage_made_them(stage_log):
    from hydrotact.sysid import find_log_presses

    log, truth = stage_log
    presses = find_log_presses(log)
    assert presses.num_presses == len(truth["presses"]) and presses.num_sites == len(truth["sites"])
    np.testing.assert_allclose(presses.positions, truth["sites"], atol=1e-12)
    for k, press in enumerate(truth["presses"]):
        assert presses.sites[k] == press["site"]
        first, last = log.times[presses.starts[k]], log.times[presses.ends[k] - 1]
        # from the last sample at rest before the press to the first one after it
        assert press["start_s"] - 0.25 < first <= press["start_s"] + 0.25 and press["end_s"] - 0.25 <= last < press["end_s"] + 0.25, (k, first, last, press)
        travel = log.columns["indentation"][presses.starts[k] : presses.ends[k]]
        assert travel.max() == pytest.approx(press["onset_travel_m"] + press["depth_m"], abs=1e-12)


def test_presses_without_positions_and_a_stage_that_moves_mid_press():
    from hydrotact.data import BarometerLog
    from hydrotact.sysid import find_log_presses

    t = np.arange(200) * 0.05
    travel = np.where((t % 5.0 > 1.0) & (t % 5.0 < 3.0), 1e-3, 0.0)
    log = BarometerLog(metadata={"channels": ["b0"]}, columns={"time": t, "b0": t, "indentation": travel})
    presses = find_log_presses(log)
    assert presses.num_presses == 2 and presses.num_sites == 2 and presses.positions.shape == (2, 0)
    moving = dict(log.columns, stage_x=np.where(t > 7.0, 1e-3, 0.0))
    with pytest.raises(HydrotactError, match=r"column 'stage_x', row 142: the stage moves during a press \(from row 122\)"):
        find_log_presses(BarometerLog(metadata=log.metadata, columns=moving), source="log.csv")
    with pytest.raises(HydrotactError, match="never moves above its rest level"):
        find_log_presses(BarometerLog(metadata=log.metadata, columns=dict(log.columns, indentation=np.zeros(200))))
    with pytest.raises(HydrotactError, match="--press-threshold: must be between 0 and 1"):
        find_log_presses(log, threshold=5.0)
