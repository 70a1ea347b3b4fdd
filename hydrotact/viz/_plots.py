"""Matplotlib plots of logs and responses (PNG files, written atomically)."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from .._files import atomic_path


def save_figure(figure, path) -> None:
    with atomic_path(path) as tmp:
        figure.savefig(tmp, dpi=130)
    plt.close(figure)


def plot_log(log, path, title: str = "") -> None:
    """Barometer channels (kPa) over time, and the contact force if the log has it."""
    has_force = all(name in log.columns for name in ("fx", "fy", "fz"))
    figure, axes = plt.subplots(2 if has_force else 1, 1, figsize=(9, 6 if has_force else 3.5), sharex=True, squeeze=False)
    times = log.times
    channels = log.channels / 1e3
    for k, name in enumerate(log.metadata["channels"]):
        axes[0, 0].plot(times, channels[:, k], lw=1, label=name if channels.shape[1] <= 10 else None)
    axes[0, 0].set_ylabel(f"{log.metadata['pressure']} pressure [kPa]")
    if channels.shape[1] <= 10:
        axes[0, 0].legend(ncol=5, fontsize=7)
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
