"""Pictures of a layout design: the layouts inside the cut-open elastomer, the
optimiser's convergence, and the predicted localisation error over the skin."""

import numpy as np
import pyvista as pv

from ..mesh import to_pyvista
from ._plots import new_figure, save_figure
from ._render import _WINDOW, _save, _show_axes, _view_from

FIELD_LENGTH_MM = 4.0
"""How far a receptive field is drawn from its port (mm)."""


def _field_glyph(position_mm, axis, kind: str, size: float) -> pv.PolyData:
    """A cone of the field's half-angle, or a disk's cylinder of its radius, drawn
    from the port along the axis."""
    if kind == "cone":
        radius = FIELD_LENGTH_MM * np.tan(size)
        centre = position_mm + 0.5 * FIELD_LENGTH_MM * axis
        return pv.Cone(center=centre, direction=-axis, height=FIELD_LENGTH_MM, radius=radius, resolution=32, capping=False)
    return pv.Cylinder(center=position_mm + 0.5 * FIELD_LENGTH_MM * axis, direction=axis, radius=size * 1e3, height=FIELD_LENGTH_MM, resolution=32, capping=False)


def render_layouts(mesh, specs: dict, path, title: str = "") -> None:
    """Side by side, one panel per named spec (e.g. {"built-in": ..., "designed": ...}):
    the elastomer cut in half by the plane y = centre (the -y half removed, so the
    inside shows), each barometer a dot with its channel name and its receptive field
    drawn for FIELD_LENGTH_MM; lengths in mm."""
    grid = to_pyvista(mesh, scale=1e3)
    centre = np.asarray(grid.center)
    clipped = grid.clip(normal="y", origin=centre, crinkle=False, invert=False)
    edges = grid.extract_feature_edges()
    plotter = pv.Plotter(off_screen=True, window_size=(int(_WINDOW[0] * len(specs) / 1.4), _WINDOW[1]), shape=(1, len(specs)))
    for column, (name, spec) in enumerate(specs.items()):
        plotter.subplot(0, column)
        plotter.add_mesh(clipped, color="lightgrey", opacity=0.35)
        plotter.add_mesh(edges, color="dimgrey", line_width=1)
        positions = np.asarray(spec.taxel_positions_S) * 1e3
        for position, axis, kind, size in zip(positions, np.asarray(spec.taxel_axes_S), spec.taxel_field_kinds, spec.taxel_field_sizes, strict=True):
            plotter.add_mesh(_field_glyph(position, axis, kind, float(size)), color="tab:blue", opacity=0.3)
        plotter.add_points(positions, color="crimson", point_size=14, render_points_as_spheres=True)
        plotter.add_point_labels(positions, list(spec.taxel_names), font_size=12, point_size=1, shape_opacity=0.4, always_visible=True)
        plotter.add_text(f"{title}\n{name}" if title else name, font_size=12)
        _show_axes(plotter, grid.bounds)
        _view_from(plotter, grid.bounds)
    _save(plotter, path)


def plot_design_convergence(histories, names, path, objective: str) -> None:
    """The score of the design's contacts against the optimiser's steps, one line per
    start (each history (k, 2) rows of step and score; the best start in bold)."""
    figure, ax = new_figure(figsize=(7, 4))
    best = int(np.argmax([np.max(np.asarray(h)[:, 1]) for h in histories]))
    for index, (history, name) in enumerate(zip(histories, names, strict=True)):
        history = np.asarray(history)
        ax.plot(history[:, 0], history[:, 1], marker=".", lw=2.2 if index == best else 1.0, label=f"{name}{' (best)' if index == best else ''}")
    ax.set_xlabel("step")
    labels = {"d": "mean log det(I + I0)", "a": "-(mean CRB of localisation), mm^2", "k": "-(mean nearest-neighbour error^2), mm^2"}
    ax.set_ylabel(labels[objective])
    ax.set_title("layout design: the score on the design's contacts")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(figure, path)


def plot_localisation_maps(points_S, bounds: dict, spec, path, what: str = "Cramér–Rao bound") -> None:
    """The predicted localisation error (mm; `what`: its model) at each held-out contact,
    one panel per named layout, on one colour scale: over the contact angles (phi,
    theta) where the sensor defines them, over (x, y) otherwise."""
    points = np.asarray(points_S)
    if spec.contact_center_S is not None:
        offset = points - np.asarray(spec.contact_center_S)
        unit = offset / np.linalg.norm(offset, axis=1, keepdims=True)
        x, y = np.degrees(np.arctan2(unit[:, 0], unit[:, 2])), np.degrees(np.arcsin(np.clip(-unit[:, 1], -1.0, 1.0)))
        labels = ("phi [deg]", "theta [deg]")
    else:
        x, y = points[:, 0] * 1e3, points[:, 1] * 1e3
        labels = ("x [mm]", "y [mm]")
    values = {name: np.asarray(value) * 1e3 for name, value in bounds.items()}
    high = max(float(np.percentile(v, 98)) for v in values.values())
    figure, axes = new_figure(1, len(values), figsize=(5 * len(values), 4.2), squeeze=False)
    for ax, (name, value) in zip(axes[0], values.items(), strict=True):
        shown = ax.scatter(x, y, c=value, cmap="magma_r", vmin=0.0, vmax=high, s=40)
        ax.set_title(f"{name}: RMS {np.sqrt(np.mean(value**2)):.3g} mm")
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
        ax.set_aspect("equal")
    figure.colorbar(shown, ax=axes[0].tolist(), label=f"localisation error, {what} [mm]")
    figure.suptitle("predicted localisation error over the skin (held-out contacts)")
    save_figure(figure, path)
