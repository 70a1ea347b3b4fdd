"""Plots of an estimator's training (PNG, written atomically)."""

import numpy as np
from matplotlib.ticker import FuncFormatter, MaxNLocator

from ._plots import new_figure, save_figure

_METRICS = (
    ("force", ("fx_rmse", "fy_rmse", "fz_rmse", "fn_rmse"), "RMSE (N)"), ("position", ("x_rmse", "y_rmse", "depth_rmse"), "RMSE (m)"),
    ("angles", ("theta_rmse", "phi_rmse"), "RMSE (rad)"), ("contact", ("contact_bce",), "BCE"),
)


def plot_training_curve(history: list, path, best_epoch: int | None = None, title: str = "") -> None:
    """Training and validation loss per epoch (log scale), and the validation Table I
    metrics per epoch: force RMSEs, angle RMSEs (where the sensor has angles), contact BCE."""
    epochs = np.array([entry["epoch"] for entry in history])
    panels = [panel for panel in _METRICS if any(name in history[0]["validation_metrics"] for name in panel[1])]
    figure, axes = new_figure(1, 1 + len(panels), figsize=(4.2 * (1 + len(panels)), 3.6), squeeze=False)
    axis = axes[0, 0]
    axis.plot(epochs, [entry["train_loss"] for entry in history], label="training")
    axis.plot(epochs, [entry["validation_loss"] for entry in history], label="validation")
    if best_epoch is not None and best_epoch >= 0:
        axis.axvline(best_epoch, color="0.5", linestyle=":", label=f"best (epoch {best_epoch})")
    axis.set_yscale("log")
    # plain numbers on the log axis, majors and minors alike (a loss within one decade has
    # only minor ticks, which matplotlib labels 1.36×10^1)
    plain = FuncFormatter(lambda value, _: f"{value:.3g}")
    axis.yaxis.set_major_formatter(plain)
    axis.yaxis.set_minor_formatter(plain)
    axis.set_xlabel("epoch")
    axis.set_ylabel("loss")
    axis.set_title(title or "loss")
    axis.legend(fontsize=8)
    for axis, (label, names, unit) in zip(axes[0, 1:], panels):
        for name in names:
            if name in history[0]["validation_metrics"]:
                axis.plot(epochs, [entry["validation_metrics"][name] for entry in history], label=name.removesuffix("_rmse").removesuffix("_bce"))
        axis.set_xlabel("epoch")
        axis.set_ylabel(f"validation {unit}")
        axis.set_title(label)
        axis.legend(fontsize=8)
    for axis in axes[0]:
        axis.xaxis.set_major_locator(MaxNLocator(integer=True))  # epochs are whole
    figure.tight_layout()
    save_figure(figure, path)
