"""Plots of a material fit: measured vs fitted traces, residuals, relaxation modulus.

- `traces.png` (measured vs fitted), `residuals.png` (residuals in noise units over
  time and their histogram against N(0, 1)), `relaxation.png` (E(t) with a 95 %
  confidence band from draws of the log-space covariance).
"""

from pathlib import Path

import numpy as np

from ._plots import new_figure, save_figure

_MAX_PLOTTED_CHANNELS = 8


def plot_fit(result, out_dir) -> dict:
    """traces.png, residuals.png and relaxation.png of a `hydrotact.sysid.FitResult`
    in out_dir; returns their paths (the `plot` of `sysid.write_fit_outputs`)."""
    from ..sysid import calc_relaxation_band

    out_dir = Path(out_dir)
    paths = {"traces_png": out_dir / "traces.png", "residuals_png": out_dir / "residuals.png", "relaxation_png": out_dir / "relaxation.png"}
    predictions = result.predictions()
    logs = result.problem.logs
    infos = result.problem.infos

    # Measured vs fitted: the channels that move most, per log.
    figure, axes = new_figure(len(logs), 1, figsize=(10, 3.6 * len(logs)), squeeze=False)
    for axis, log, info, prediction in zip(axes[:, 0], logs, infos, predictions):
        observed = np.asarray(log.observed)
        times = np.asarray(log.times)
        masked = np.asarray(log.weights) <= 0.0  # readings the fit left out (clipped at the part's range)
        count = log.num_channels
        spread = observed[:, :count].max(axis=0) - observed[:, :count].min(axis=0)
        marked = False
        for c in np.argsort(spread)[::-1][:_MAX_PLOTTED_CHANNELS]:
            base = observed[0, c]
            shown = np.where(masked[:, c], np.nan, observed[:, c])  # a masked stretch breaks the measured line
            line = axis.plot(times, (shown - base) / 1e3, lw=0.8, alpha=0.6)[0]
            axis.plot(times, (prediction[:, c] - base) / 1e3, "--", lw=1.0, color=line.get_color(), label=info.channels[c])
            if masked[:, c].any():
                label = None if marked else "masked: not fitted"
                axis.plot(times[masked[:, c]], (observed[masked[:, c], c] - base) / 1e3, "x", ms=3, mew=0.6, color=line.get_color(), alpha=0.8, label=label)
                marked = True
        axis.set_ylabel("reading − first sample [kPa]")
        title = f"{info.source}: measured (solid) and fitted (dashed)"
        if marked:
            title += f"; {int(masked[:, :count].sum())} readings masked (x: at the part's range, left out of the fit)"
        axis.set_title(title, fontsize=9)
        axis.legend(ncol=4, fontsize=7)
    axes[-1, 0].set_xlabel("time [s]")
    figure.tight_layout()
    save_figure(figure, paths["traces_png"])

    # Residuals in noise units.
    figure, (left, right) = new_figure(1, 2, figsize=(11, 3.6), gridspec_kw={"width_ratios": [3, 1]})
    everything = []
    for log, info, prediction in zip(logs, infos, predictions):
        normalised = (np.asarray(log.observed) - prediction) * np.asarray(log.weights)
        everything.append(normalised[np.asarray(log.weights) > 0.0])  # not the clipped readings a fit masked
        for c, name in enumerate((info.channels + info.force_columns)[:_MAX_PLOTTED_CHANNELS]):
            left.plot(np.asarray(log.times), normalised[:, c], lw=0.4, alpha=0.7, label=name)
    left.set_xlabel("time [s]")
    left.set_ylabel("residual / noise σ")
    left.set_title(f"residuals (reduced χ² = {result.reduced_chi_square:.3f})", fontsize=9)
    everything = np.concatenate(everything)
    grid = np.linspace(-5, 5, 201)
    right.hist(np.clip(everything, -5, 5), bins=60, density=True, alpha=0.6)
    right.plot(grid, np.exp(-0.5 * grid**2) / np.sqrt(2 * np.pi), "k", lw=1, label="N(0, 1)")
    right.set_xlabel("residual / noise σ")
    right.legend(fontsize=7)
    figure.tight_layout()
    save_figure(figure, paths["residuals_png"])

    # Relaxation modulus with its confidence band.
    span = max(float(log.times[-1] - log.times[0]) for log in logs)
    step = min(float(np.min(np.diff(np.asarray(log.times)))) for log in logs)
    times = np.logspace(np.log10(step / 2), np.log10(span * 2), 200)
    modulus, low, high = calc_relaxation_band(result, times)
    unit, label = 1e3, "E(t) [kPa]"
    figure, axis = new_figure(figsize=(6.5, 4))
    axis.fill_between(times, low / unit, high / unit, alpha=0.3, label="95 % band")
    axis.semilogx(times, modulus / unit, "k", lw=1.2, label="fitted")
    for _, tau in result.terms:
        axis.axvline(tau.value, color="grey", lw=0.6, ls=":")
    axis.set_xlabel("time [s]")
    axis.set_ylabel(label)
    axis.set_title(f"relaxation modulus, {result.layout.num_terms} Prony terms", fontsize=9)
    axis.legend(fontsize=8)
    figure.tight_layout()
    save_figure(figure, paths["relaxation_png"])
    return {key: str(path) for key, path in paths.items()}
