"""Off-screen 3-D renders of meshes and fields with pyvista (PNG files)."""

import os

if not os.environ.get("DISPLAY"):
    # No X server: ask VTK for a headless EGL window rather than failing over to it.
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import numpy as np
import pyvista as pv

from .._files import atomic_path
from ..mesh import CORE, FREE, TetMesh, to_pyvista

pv.OFF_SCREEN = True
_WINDOW = (1200, 900)


def _faces_polydata(mesh: TetMesh, tag: int) -> pv.PolyData:
    faces = mesh.faces_tagged(tag)
    cells = np.column_stack([np.full(len(faces), 3), faces]).reshape(-1)
    return pv.PolyData(np.asarray(mesh.vertices, dtype=np.float64) * 1e3, cells)


def _view_from(plotter: pv.Plotter, bounds_mm, elevation: float = 0.5) -> None:
    """Look at the box `bounds_mm` from the -y side, a little from +x, from above
    (elevation > 0) or below (elevation < 0): x runs to the right and z up, as a
    drawing of the sensor shows them, and a half cut away on the +y side shows its
    cut face."""
    lo, hi = np.asarray(bounds_mm[0::2]), np.asarray(bounds_mm[1::2])
    centre, size = 0.5 * (lo + hi), float(np.linalg.norm(hi - lo))
    eye = centre + size * np.array([0.8, -1.5, elevation])
    plotter.camera_position = [tuple(eye), tuple(centre), (0.0, 0.0, 1.0)]


def _nice_step(span: float) -> float:
    """A round tick step (1, 2, 2.5 or 5 x 10^k) giving at most 7 ticks over `span`."""
    for exponent in range(-3, 4):
        for mantissa in (1.0, 2.0, 2.5, 5.0):
            step = mantissa * 10.0**exponent
            if span / step <= 6.0:
                return step
    return span


def _show_axes(plotter: pv.Plotter, bounds_mm) -> None:
    """Axes in mm with round ticks: each axis's range widened to whole steps, so the
    labels read 0, 5, 10, ... (and 0 is 0, not -0.0)."""
    bounds, counts, decimals = [], {}, 0
    for axis, (lo, hi) in zip("xyz", np.reshape(bounds_mm, (3, 2))):
        step = _nice_step(max(hi - lo, 1e-6))
        first, last = np.floor(lo / step + 1e-9) * step, np.ceil(hi / step - 1e-9) * step
        bounds += [first + 0.0, last + 0.0]
        counts[f"n_{axis}labels"] = int(round((last - first) / step)) + 1
        decimals = max(decimals, next(k for k in range(4) if abs(step * 10**k - round(step * 10**k)) < 1e-9 or k == 3))
    plotter.show_bounds(bounds=bounds, xtitle="x [mm]", ytitle="y [mm]", ztitle="z [mm]", font_size=16, fmt=f"%.{decimals}f", location="outer", **counts)


def _save(plotter: pv.Plotter, path) -> None:
    with atomic_path(path) as tmp:
        plotter.screenshot(str(tmp))
    plotter.close()


def render_mesh(mesh: TetMesh, path, title: str = "") -> None:
    """A PNG of the mesh cut in half by the plane y = centre (whole tets, with their
    edges, so the inside shows; the +y half kept, seen from -y), core faces orange;
    lengths in mm."""
    grid = to_pyvista(mesh, scale=1e3)
    centre = np.asarray(grid.center)
    plotter = pv.Plotter(off_screen=True, window_size=_WINDOW)
    kept = grid.clip(normal="y", origin=centre, crinkle=True, invert=False)
    plotter.add_mesh(kept, color="lightgrey", show_edges=True, edge_color="dimgrey")
    core = _faces_polydata(mesh, CORE)
    if core.n_cells:
        plotter.add_mesh(core.clip(normal="y", origin=centre, invert=False), color="orange")
        plotter.add_mesh(_faces_polydata(mesh, FREE).clip(normal="y", origin=centre, invert=False).extract_feature_edges(), color="black")
        title = f"{title}\ncore (bonded) faces in orange" if title else "core (bonded) faces in orange"
    plotter.add_text(title, font_size=12)
    shown = np.array(kept.bounds)
    shown[2] = max(shown[2], centre[1])  # whole tets cross the cut: the axes start at it
    _show_axes(plotter, shown)  # the axes frame the half shown, not the whole mesh in front of it
    _view_from(plotter, shown, elevation=-0.6)  # from below: the bonded base shows
    _save(plotter, path)


def render_field(mesh: TetMesh, values, path, *, label: str, title: str = "") -> None:
    """A PNG of a vertex field on the mesh, clipped by the plane y = centre so the
    inside shows, with a colour bar titled `label` (which should carry the units)."""
    grid = to_pyvista(mesh, scale=1e3)
    grid.point_data[label] = np.asarray(values, dtype=np.float64)
    centre = np.asarray(grid.center)
    clipped = grid.clip(normal="y", origin=centre, crinkle=False, invert=False)
    plotter = pv.Plotter(off_screen=True, window_size=_WINDOW)
    plotter.add_mesh(
        clipped,
        scalars=label,
        cmap="viridis",
        show_edges=False,
        scalar_bar_args={"title": label, "vertical": True, "fmt": "%.3g", "position_x": 0.86, "width": 0.06, "title_font_size": 14},
    )
    plotter.add_mesh(grid.extract_feature_edges(), color="black", line_width=1)
    plotter.add_text(title, font_size=12)
    _show_axes(plotter, clipped.bounds)
    _view_from(plotter, clipped.bounds)  # the kept half is y > centre: its cut faces the camera
    _save(plotter, path)


def _surface_polydata(surface) -> pv.PolyData:
    """The valid contact polygons, fan-triangulated, with pressure at the points (mm)."""
    valid = np.asarray(surface.valid)
    vertices = np.asarray(surface.vertices_S)[valid] * 1e3
    pressures = np.asarray(surface.pressures)[valid]
    counts = np.asarray(surface.counts)[valid]
    points, values, faces = [], [], []
    offset = 0
    for polygon, pressure, count in zip(vertices, pressures, counts):
        points.append(polygon[:count])
        values.append(pressure[:count])
        for k in range(1, count - 1):
            faces.append([3, offset, offset + k, offset + k + 1])
        offset += count
    if not faces:
        return pv.PolyData()
    data = pv.PolyData(np.concatenate(points), np.asarray(faces).reshape(-1))
    data.point_data["pressure [Pa]"] = np.concatenate(values)
    return data


def render_contact(mesh: TetMesh, surface, path, *, probe=None, X_SP=None, title: str = "") -> None:
    """A PNG of a contact surface coloured by pressure over the translucent sensor,
    with the probe's outline; lengths in mm."""
    plotter = pv.Plotter(off_screen=True, window_size=_WINDOW)
    skin = _faces_polydata(mesh, FREE)
    plotter.add_mesh(skin, color="lightgrey", opacity=0.25, smooth_shading=True)
    contact = _surface_polydata(surface)
    if contact.n_cells:
        top = max(float(np.max(contact.point_data["pressure [Pa]"])), 1e-300)  # pressures are >= 0: the bar starts at 0, not at round-off below it
        bar = {"title": "pressure [Pa]", "vertical": True, "fmt": "%.3g", "position_x": 0.86, "width": 0.06}
        plotter.add_mesh(contact, scalars="pressure [Pa]", cmap="inferno", clim=(0.0, top), scalar_bar_args=bar)
    else:
        title = f"{title}\n(no contact)"
    if probe is not None and X_SP is not None and hasattr(probe, "faces"):
        vertices = np.asarray(X_SP.apply(np.asarray(probe.vertices_R))) * 1e3
        faces = np.column_stack([np.full(probe.num_faces, 3), np.asarray(probe.faces)]).reshape(-1)
        outline = pv.PolyData(vertices, faces)
        edges = outline.extract_feature_edges(30.0)
        if edges.n_points:  # a cylinder: its rims
            plotter.add_mesh(edges, color="steelblue", line_width=2)
        else:  # a smooth probe (a sphere) has no feature edges: draw it translucent
            plotter.add_mesh(outline, color="steelblue", opacity=0.2, smooth_shading=True)
    plotter.add_text(title, font_size=12)
    _show_axes(plotter, skin.bounds)
    _view_from(plotter, skin.bounds)
    _save(plotter, path)
