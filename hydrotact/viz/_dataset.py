"""Plots of a generated dataset: coverage of the skin, label histograms, the channels'
swing against the published statistics, and example events with their labels."""

import numpy as np

from ._plots import new_figure, save_figure

PUBLISHED_LABEL = "published real sensors (std 3-9 kPa)"


def _hold_rows(columns: dict) -> np.ndarray:
    """The first hold sample of each event (its contact point and load)."""
    hold = columns["phase"] == 2
    return np.flatnonzero(hold & np.concatenate([[True], ~hold[:-1]]))


def plot_coverage(dataset, path) -> None:
    """Where the events touched: the centre of pressure at each hold, as contact angles
    (curved sensors: θ, φ, with the sensor's ranges) and seen from above (x, y)."""
    columns = dataset.arrays("all", ["event", "phase", "cop_x", "cop_y", "cop_z", *(["theta", "phi"] if "theta" in dataset.columns else [])])
    rows = _hold_rows(columns)
    angles = "theta" in columns
    figure, axes = new_figure(1, 2 if angles else 1, figsize=(11 if angles else 5.5, 4.8), squeeze=False)
    axes = axes[0]
    top = axes[0]
    x, y = 1e3 * columns["cop_x"][rows], 1e3 * columns["cop_y"][rows]
    points = top.scatter(x, y, c=1e3 * columns["cop_z"][rows], s=6, cmap="viridis")
    figure.colorbar(points, ax=top, label="z (mm)")
    top.set_aspect("equal")
    top.set_xlabel("x (mm)")
    top.set_ylabel("y (mm)")
    top.set_title(f"centre of pressure at each hold\n({len(rows)} events), seen from above")
    if angles:
        side = axes[1]
        side.scatter(np.degrees(columns["phi"][rows]), np.degrees(columns["theta"][rows]), s=6, color="C0", label="events")
        document = dataset.manifest["sensor"]["spec"]
        ranges = document.get("contact_angles")
        if ranges:
            scale = 180.0 / np.pi if document.get("units", {}).get("angle", "rad") == "rad" else 1.0
            (t0, t1), (p0, p1) = (scale * np.asarray(ranges[key]) for key in ("theta_range", "phi_range"))
            side.plot([p0, p1, p1, p0, p0], [t0, t0, t1, t1, t0], color="C3", label="the sensor's ranges (deg)")
        side.set_xlabel("φ (deg)")
        side.set_ylabel("θ (deg)")
        side.set_title("contact angles at each hold")
        side.legend(loc="lower left", fontsize=8)
    figure.tight_layout()
    save_figure(figure, path)


def plot_histograms(dataset, path) -> None:
    """Histograms of the hold's normal force (log bins), Fx, Fy (all samples in
    contact) and the hold depth."""
    columns = dataset.arrays("all", ["event", "phase", "fn", "fx", "fy", "depth", "contact"])
    rows = _hold_rows(columns)
    touching = columns["contact"] == 1
    figure, axes = new_figure(2, 2, figsize=(10, 7))
    fn = columns["fn"][rows]
    positive = fn[fn > 0]
    if positive.size:
        axes[0, 0].hist(positive, bins=np.geomspace(positive.min(), positive.max(), 30), color="C0", label="hold onset")
        axes[0, 0].set_xscale("log")
    axes[0, 0].set_xlabel("normal force Fn at the hold's start (N)")
    axes[0, 0].set_title("target forces, log-uniform: low forces over-sampled", fontsize=9)
    for axis, name, colour in ((axes[0, 1], "fx", "C1"), (axes[1, 0], "fy", "C2")):
        axis.hist(columns[name][touching], bins=40, color=colour, label="samples in contact")
        axis.set_xlabel(f"{name[0].upper()}{name[1]} (N), sensor frame")
    axes[1, 1].hist(1e3 * columns["depth"][rows], bins=30, color="C4", label="hold onset")
    axes[1, 1].set_xlabel("depth past the skin point at the hold (mm)")
    for axis in axes.ravel():
        axis.set_ylabel("count")
        if axis.get_legend_handles_labels()[0]:
            axis.legend(fontsize=8)
    figure.tight_layout()
    save_figure(figure, path)


def plot_channel_swing(dataset, path) -> None:
    """Each channel's standard deviation (kPa) next to the published range."""
    stats = dataset.manifest["statistics"]
    names = dataset.channels
    std = 1e-3 * np.asarray(stats["channel_std_Pa"])
    low, high = (1e-3 * v for v in stats.get("published_channel_std_Pa", (3e3, 9e3)))
    figure, axis = new_figure(figsize=(max(5.0, 0.6 * len(names) + 2), 4))
    axis.axhspan(low, high, color="C2", alpha=0.2, label=PUBLISHED_LABEL)
    axis.bar(names, std, color="C0", label="this dataset")
    axis.set_ylabel("reading std. dev. (kPa)")
    axis.set_title("channel swing over the session")
    axis.legend(fontsize=8)
    figure.tight_layout()
    save_figure(figure, path)


def plot_examples(dataset, path, count: int = 3) -> None:
    """A few events: the channels (tared on the session's first sample, kPa), the
    force labels and the contact flag."""
    columns = dataset.arrays("all")
    events = np.unique(columns["event"][columns["event"] >= 0])
    chosen = events[np.linspace(0, len(events) - 1, min(count, len(events))).astype(int)]
    figure, axes = new_figure(2, len(chosen), figsize=(4.5 * len(chosen), 6), squeeze=False, sharex="col")
    baseline = {name: columns[name][0] for name in dataset.channels}
    for k, event in enumerate(chosen):
        rows = np.flatnonzero(columns["event"] == event)
        rows = np.arange(max(rows[0] - 20, 0), min(rows[-1] + 20, len(columns["time"])))
        t = columns["time"][rows]
        for c, name in enumerate(dataset.channels):
            axes[0, k].plot(t, 1e-3 * (columns[name][rows] - baseline[name]), color=f"C{c % 10}", label=name)
        axes[0, k].set_title(f"event {event}")
        axes[0, k].set_ylabel("reading - first sample (kPa)")
        for name, colour in (("fx", "C1"), ("fy", "C2"), ("fz", "C0"), ("fn", "k")):
            axes[1, k].plot(t, columns[name][rows], color=colour, label=name)
        axes[1, k].fill_between(t, 0, np.where(columns["contact"][rows] == 1, np.nanmax(columns["fn"][rows]) or 1.0, 0.0), color="C3", alpha=0.1, step="mid", label="contact")
        axes[1, k].set_ylabel("force (N)")
        axes[1, k].set_xlabel("time (s)")
        axes[0, k].legend(fontsize=7, ncols=2)
        axes[1, k].legend(fontsize=7)
    figure.tight_layout()
    save_figure(figure, path)


def plot_dataset(dataset, folder) -> list:
    """Every plot of a dataset into `folder` (the names of hydrotact.datasets.PLOTS);
    returns their paths."""
    from pathlib import Path

    folder = Path(folder)
    paths = []
    for name, draw in (("coverage.png", plot_coverage), ("histograms.png", plot_histograms), ("channel_swing.png", plot_channel_swing), ("examples.png", plot_examples)):
        draw(dataset, folder / name)
        paths.append(folder / name)
    return paths
