"""Plots of a lumped press fit and of comparisons with held-out logs, readable for one
log or a hundred: one panel per channel with every press overlaid (time from the
press's start, the baseline taken off), each channel in one colour across all plots
and named in a legend; residual histograms over their whole range.

- `traces.png`: measured (dots) and fitted (lines) presses, per channel;
- `residuals.png`: residuals in noise units against the time in the press, and their
  histogram against N(0, 1);
- `relaxation.png`: the fitted E(t)/E∞ with a 95 % band from the identified terms' standard errors;
- `compare_traces.png`, `compare_residuals.png`: the same for held-out logs, the
  errors over √(noise² + the prediction band²).
"""

from pathlib import Path

import numpy as np

from ._plots import new_figure, save_figure

MAX_CHANNEL_PANELS = 8


def _colour(c: int) -> str:
    return f"C{c % 10}"


def _press_panels(channels, series, path, title, ylabel="elastic part [Pa]") -> None:
    """One panel per channel: for each (channel, press) series (t, observed,
    predicted[, band]), observed as dots and predicted as a line; a band (the
    prediction's 1σ from the fit's covariance) is drawn as the model ± 2σ."""
    shown = list(channels)[:MAX_CHANNEL_PANELS]
    figure, axes = new_figure(len(shown), 1, figsize=(9, 2.4 * len(shown) + 0.6), squeeze=False, sharex=True)
    for c, (axis, name) in enumerate(zip(axes[:, 0], shown)):
        banded = False
        for times, observed, predicted, *band in series[c]:
            axis.plot(times, observed, ".", ms=1.5, color=_colour(c), alpha=0.35)
            axis.plot(times, predicted, "-", lw=0.7, color="k", alpha=0.6)
            if band and np.isfinite(band[0]).any():
                axis.fill_between(times, predicted - 2.0 * band[0], predicted + 2.0 * band[0], color="k", alpha=0.15, lw=0)
                banded = True
        axis.plot([], [], ".", color=_colour(c), label=f"{name} measured")
        axis.plot([], [], "-", color="k", label="model")
        if banded:
            axis.fill_between([], [], [], color="k", alpha=0.15, lw=0, label="model ± 2σ (prediction band)")
        axis.set_ylabel(ylabel, fontsize=8)
        axis.legend(loc="upper right", fontsize=7)
    axes[0, 0].set_title(title, fontsize=9)
    axes[-1, 0].set_xlabel("time from the press's start [s]")
    if len(channels) > len(shown):
        figure.text(0.01, 0.005, f"{len(channels) - len(shown)} more channels in the report", fontsize=7)
    figure.tight_layout()
    save_figure(figure, path)


def _residual_panels(channels, residuals, path, title, unit="residual / noise σ") -> None:
    """Residuals/σ against the time in the press per channel, and histograms."""
    figure, (left, right) = new_figure(1, 2, figsize=(11, 3.8), gridspec_kw={"width_ratios": [3, 2]})
    everything = []
    for c, name in enumerate(channels):
        times = np.concatenate([t for t, _ in residuals[c]]) if residuals[c] else np.zeros(0)
        values = np.concatenate([r for _, r in residuals[c]]) if residuals[c] else np.zeros(0)
        left.plot(times, values, ".", ms=1.0, alpha=0.4, color=_colour(c), label=name)
        everything.append(values)
    left.set_xlabel("time from the press's start [s]")
    left.set_ylabel(unit)
    left.set_title(title, fontsize=9)
    left.legend(fontsize=7, markerscale=6, ncol=2)
    values = np.concatenate(everything) if everything else np.zeros(0)
    values = values[np.isfinite(values)]
    if values.size:
        low, high = min(values.min(), -4.0), max(values.max(), 4.0)  # the whole range: nothing clipped
        bins = np.linspace(low, high, 81)
        for c, (name, channel_values) in enumerate(zip(channels, everything)):
            channel_values = channel_values[np.isfinite(channel_values)]
            if channel_values.size:
                right.hist(channel_values, bins=bins, density=True, histtype="step", color=_colour(c), label=name)
        grid = np.linspace(low, high, 400)
        right.plot(grid, np.exp(-0.5 * grid**2) / np.sqrt(2 * np.pi), "k--", lw=1.0, label="N(0, 1)")
        right.set_yscale("log")
        # Both limits set: a step histogram's closing edges at 0 density send a log
        # axis' autoscale to 1e12 and beyond.
        right.set_ylim(1e-5, 2.0 * max(0.4, *(np.histogram(v[np.isfinite(v)], bins=bins, density=True)[0].max() for v in everything if np.isfinite(v).any())))
        right.set_xlabel(unit)
        right.legend(fontsize=7)
    figure.tight_layout()
    save_figure(figure, path)


def plot_press_fit(fit, out_dir) -> dict:
    """traces.png, residuals.png and relaxation.png of a `hydrotact.sysid.PressFit`
    in out_dir; returns their paths (the `plot` of `write_press_fit_outputs`)."""
    out_dir = Path(out_dir)
    paths = {"traces_png": out_dir / "traces.png", "residuals_png": out_dir / "residuals.png", "relaxation_png": out_dir / "relaxation.png"}
    channels = list(fit.channels)
    series = [[] for _ in channels]
    residuals = [[] for _ in channels]
    for log, residual, prediction in zip(fit.logs, fit.residuals, fit.predictions()):
        baseline = prediction - _elastic_part(log, residual, prediction)
        for p in range(len(log.onset_start)):
            rows = np.flatnonzero(log.press == p)
            if rows.size == 0:
                continue
            t = log.times[rows] - log.times[rows[0]]
            for c in range(len(channels)):
                used = log.mask[rows, c]
                series[c].append((t[used], (log.observed[rows, c] - baseline[rows, c])[used], (prediction[rows, c] - baseline[rows, c])[used]))
                residuals[c].append((t[used], residual[rows, c][used]))
    _press_panels(channels, series, paths["traces_png"], f"{len(fit.logs)} log(s), {sum(len(log.onset_start) for log in fit.logs)} presses: measured and fitted, baseline off")
    _residual_panels(channels, residuals, paths["residuals_png"], f"residuals (reduced χ² = {fit.reduced_chi_square:.3f})")

    _relaxation_panel(fit, paths["relaxation_png"])
    return {name: str(path) for name, path in paths.items()}


def _relaxation_panel(fit, path) -> None:
    """E(t)/E∞ over the time scales the logs show, and a 95 % band drawn from the
    identified terms' standard errors. The fit's parameters are log Eᵢ/E∞ and log τᵢ,
    so the band is drawn in the logs (first order: σ/value, at most a factor of 20
    either way), never as a value ± σ that crosses zero; a term the logs do not
    identify is drawn at its value and named. The y axis covers the fitted curve and
    the band up to 3 x the curve's top, so that the curve is never a flat line under
    an enormous band."""
    figure, axis = new_figure(figsize=(6, 3.6))
    times = np.geomspace(1e-2, 1e3, 300)
    ratios = np.array([r.value for r in fit.ratios])
    taus = np.array([t.value for t in fit.taus])
    spread = lambda quantities: np.array([min(q.std / max(abs(q.value), 1e-300), 3.0) if q.identified else 0.0 for q in quantities])
    rng = np.random.default_rng(0)
    log_r, log_t = np.log(np.maximum(ratios, 1e-300)), np.log(np.maximum(taus, 1e-300))
    draws = []
    for _ in range(400):
        r = np.exp(log_r + rng.standard_normal(len(ratios)) * spread(fit.ratios))
        t = np.exp(log_t + rng.standard_normal(len(taus)) * spread(fit.taus))
        draws.append(1.0 + (r[None, :] * np.exp(-times[:, None] / t[None, :])).sum(axis=1))
    low, high = np.percentile(draws, [2.5, 97.5], axis=0)
    fitted = 1.0 + (ratios[None, :] * np.exp(-times[:, None] / np.maximum(taus[None, :], 1e-300))).sum(axis=1)
    axis.fill_between(times, low, high, color="C0", alpha=0.25, label="95 % band (identified terms)")
    axis.semilogx(times, fitted, "C0", label="fitted")
    top = float(fitted.max())
    axis.set_ylim(min(0.95, float(low.min())), min(max(1.1 * top, float(high.max())), 3.0 * top))
    unidentified = [f"E{k + 1}/E∞" for k, r in enumerate(fit.ratios) if not r.identified] + [f"τ{k + 1}" for k, t in enumerate(fit.taus) if not t.identified]
    if unidentified:
        axis.text(0.02, 0.04, "not identified: " + ", ".join(unidentified), transform=axis.transAxes, fontsize=7)
    axis.set_xlabel("t [s]")
    axis.set_ylabel("E(t) / E∞")
    axis.set_title("relaxation shape (lumped fit: the scale is not identified)", fontsize=9)
    axis.legend(fontsize=8)
    figure.tight_layout()
    save_figure(figure, path)


def _elastic_part(log, residual, prediction):
    """(T, C) the model's elastic part: the prediction less its baseline, which is
    the prediction between presses (interpolated across them)."""
    between = log.press < 0
    elastic = np.zeros_like(prediction)
    if between.sum() < 2:
        return elastic
    for c in range(prediction.shape[1]):
        baseline = np.interp(log.times, log.times[between], prediction[between, c])
        elastic[:, c] = prediction[:, c] - baseline
    return elastic


def plot_comparisons(comparisons, out_dir) -> dict:
    """compare_traces.png and compare_residuals.png of `hydrotact.sysid.Comparison`s
    (the `plot` of `compare_fit`)."""
    out_dir = Path(out_dir)
    paths = {"traces_png": out_dir / "compare_traces.png", "residuals_png": out_dir / "compare_residuals.png"}
    channels = list(comparisons[0].channels)
    series = [[] for _ in channels]
    residuals = [[] for _ in channels]
    for comparison in comparisons:
        holds = comparison.hold
        for p in np.unique(holds[holds >= 0]):
            rows = np.flatnonzero(holds == p)
            start = max(rows[0] - 40, 0)
            rows = np.arange(start, min(rows[-1] + 40, len(holds)))
            t = comparison.times[rows] - comparison.times[rows[0]]
            for c in range(len(channels)):
                used = comparison.mask[rows, c]
                base = comparison.predicted[rows[0], c]
                band = comparison.predicted_std[rows, c]  # NaN: a fit without its covariance (not drawn)
                series[c].append((t[used], comparison.observed[rows, c][used] - base, comparison.predicted[rows, c][used] - base, band[used]))
                band = np.nan_to_num(band)
                scale = np.sqrt(comparison.noise_pa[c] ** 2 + band**2)
                residuals[c].append((t[used], ((comparison.observed - comparison.predicted)[rows, c] / scale)[used]))
    _press_panels(channels, series, paths["traces_png"], f"{len(comparisons)} held-out log(s): measured and predicted", ylabel="reading − baseline [Pa]")
    _residual_panels(channels, residuals, paths["residuals_png"], "prediction errors", unit="error / √(noise² + band²)")
    return {name: str(path) for name, path in paths.items()}
