"""Matplotlib plots of logs and responses (PNG files, written atomically).

Figures are made with matplotlib's object interface (`new_figure`), not pyplot: writing
a PNG needs no backend, so importing hydrotact.viz leaves the user's backend (and a
notebook's inline figures) as they were, and no figure lingers in pyplot's list."""

import matplotlib
from matplotlib.figure import Figure

from .._files import atomic_path


def new_figure(nrows: int = 1, ncols: int = 1, **keywords):
    """(figure, axes) as `pyplot.subplots` gives, without pyplot (keywords: figsize
    for the Figure; the rest for `Figure.subplots`). Tick labels carry whole values:
    no "1e-8 + 1.013e5" offset above an axis of absolute pressures."""
    figure = Figure(figsize=keywords.pop("figsize", None))
    with matplotlib.rc_context({"axes.formatter.useoffset": False}):
        return figure, figure.subplots(nrows, ncols, **keywords)


def save_figure(figure, path) -> None:
    with atomic_path(path) as tmp:
        figure.savefig(tmp, dpi=130)


def plot_log(log, path, title: str = "") -> None:
    """Barometer channels (kPa) over time, and the contact force if the log has it."""
    has_force = all(name in log.columns for name in ("fx", "fy", "fz"))
    figure, axes = new_figure(2 if has_force else 1, 1, figsize=(9, 6 if has_force else 3.5), sharex=True, squeeze=False)
    times = log.times
    channels = log.channels / 1e3
    for k, name in enumerate(log.metadata["channels"]):
        axes[0, 0].plot(times, channels[:, k], lw=1, label=name)
    axes[0, 0].set_ylabel(f"{log.metadata['pressure']} pressure [kPa]")
    if channels.shape[1] <= 10:
        axes[0, 0].legend(ncol=5, fontsize=7)
    else:  # every channel named, in columns beside the plot
        axes[0, 0].legend(ncol=-(-channels.shape[1] // 13), fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1.0), title="channel", title_fontsize=7)
    if has_force:
        for axis in "xyz":
            axes[1, 0].plot(times, log.columns[f"f{axis}"], lw=1, label=f"F{axis}")
        if "fn" in log.columns:
            axes[1, 0].plot(times, log.columns["fn"], "k--", lw=1, label="Fn")
        axes[1, 0].set_ylabel("force on sensor [N]")
        axes[1, 0].legend(ncol=4, fontsize=7)
    axes[-1, 0].set_xlabel("time [s]")
    figure.suptitle(title)
    figure.tight_layout()
    save_figure(figure, path)
