"""Plots of a trained estimator's evaluation (PNG, written atomically): the
localisation error over the skin (the barometric estimation paper's Fig. 5) and the
two contact detectors over a stretch of a recording (its Fig. 7)."""

import numpy as np

from ._plots import new_figure, save_figure


def plot_error_maps(maps: dict, path, title: str = "") -> None:
    """One panel per map (`maps`: label -> :func:`hydrotact.models.calc_error_map`'s
    result, on the same cells), the mean error per cell (mm on a sphere, degrees
    otherwise) on one colour scale, over φ (longitude, across) and θ (latitude, up);
    cells no contact fell in are left blank."""
    labels = list(maps)
    first = maps[labels[0]]
    scale, unit = (1e3, "mm") if first["unit"] == "m" else (180.0 / np.pi, "deg")
    values = [scale * np.asarray(maps[label]["mean"]) for label in labels]
    finite = np.concatenate([v[np.isfinite(v)] for v in values] + [np.zeros(1)])
    top = float(finite.max()) or 1.0
    columns = min(4, len(labels))
    rows = -(-len(labels) // columns)
    width = 3.8 * columns + 1.2
    figure, axes = new_figure(rows, columns, figsize=(width, 2.9 * rows + 0.8), squeeze=False)
    # margins in inches, not fractions: 6 % of a one-panel figure cut the θ label off
    figure.subplots_adjust(left=0.75 / width, right=1.0 - 1.3 / width, bottom=0.12, top=0.82, wspace=0.35, hspace=0.6)
    image = None
    for axis, label, value in zip(axes.flat, labels, values):
        entry = maps[label]
        phi, theta = np.degrees(entry["phi_edges"]), np.degrees(entry["theta_edges"])
        image = axis.pcolormesh(phi, theta, np.ma.masked_invalid(value), vmin=0.0, vmax=top, cmap="viridis")
        mean = float(np.nansum(value * entry["count"]) / max(1, np.sum(entry["count"])))
        axis.set_title(f"{label}\nmean {mean:.3g} {unit}, {int(np.sum(entry['count']))} contact samples", fontsize=8)
        axis.set_xlabel("φ (deg)")
        axis.set_ylabel("θ (deg)")
    for axis in list(axes.flat)[len(labels):]:
        axis.set_visible(False)
    figure.colorbar(image, ax=axes.ravel().tolist(), label=f"mean localisation error ({unit})", shrink=0.85)
    if title:
        figure.suptitle(title, fontsize=9)
    save_figure(figure, path)


def plot_contact_detection(times, force, contact, probability, predicted_force, path, threshold: float = 0.1, title: str = "", signal: str = "|F| (N)") -> None:
    """The true |F| over time with the samples each detector calls contact shaded: the
    contact head (probability over 0.5) above, the predicted |F| over `threshold` N
    below (none where `predicted_force` is None: an estimator without the forces);
    the true contact as a strip along the bottom of each (in the axis' height, not in
    the signal's units: it is a flag, not a force). `signal` names what `force` is (a
    stage log without forces draws its depth: "depth (mm)")."""
    times = np.asarray(times) - float(np.asarray(times)[0])
    force = np.nan_to_num(np.asarray(force, dtype=float))
    panels = [(np.asarray(probability) > 0.5, "contact head (p > 0.5)")]
    if predicted_force is not None:
        panels.append((np.asarray(predicted_force) > threshold, f"predicted |F| > {threshold:g} N"))
    figure, axes = new_figure(len(panels), 1, figsize=(9, 2.5 * len(panels) + 0.5), sharex=True, squeeze=False)
    axes = axes[:, 0]
    for axis, (detected, name) in zip(axes, panels):
        axis.plot(times, force, color="k", linewidth=0.8, label=f"true {signal.split(' (')[0]}")
        top = max(float(np.max(force)), 1e-6) * 1.05
        axis.fill_between(times, 0.0, top, where=detected, color="tab:orange", alpha=0.3, step="mid", label=f"detected: {name}")
        axis.fill_between(times, 0.0, 0.06, where=np.asarray(contact) > 0, transform=axis.get_xaxis_transform(), color="tab:blue", alpha=0.7, step="mid",
                          linewidth=0, label="true contact")
        axis.set_ylim(bottom=0.0)
        axis.set_ylabel(signal)
        axis.legend(fontsize=7, loc="upper right")
    axes[-1].set_xlabel("time (s)")
    if title:
        axes[0].set_title(title, fontsize=9)
    figure.tight_layout()
    save_figure(figure, path)
