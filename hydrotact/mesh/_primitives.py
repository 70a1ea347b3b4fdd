"""Deterministic structured meshes of simple solids, and closed surfaces to mesh.

The box is a grid of hexahedra each cut into six tets along its main diagonal (Kuhn
subdivision), which is conforming across the whole grid. The spherical shell is the
same kind of grid on the cube annulus 1/2 <= |x|_inf <= 1 mapped radially onto
r0 <= |p| <= R; its boundary vertices lie exactly on the two spheres, so the
polyhedral boundary error falls as h^2 and P1 convergence orders are not spoiled.
"""

import itertools

import numpy as np

from .._errors import HydrotactError, where
from ._tags import Plane, make_face_tagger
from ._tetmesh import CORE, FREE, INSULATED, TetMesh, make_tet_mesh, orient_tets


def _kuhn_grid(num_cells: tuple[int, int, int], symmetric: bool = False):
    """Unit-cube grid with (nx, ny, nz) cells: integer vertex coordinates (V, 3) and
    tets (6 * cells, 4), plus the cell index (i, j, k) of every tet.

    Each cell is cut into six tets around one of its main diagonals. By default the
    diagonal runs from the cell's lowest corner; with `symmetric`, from the corner
    nearest the grid's centre (so the diagonals point away from it in every octant).
    Either way the face diagonals of neighbouring cells match and the mesh conforms.
    """
    nx, ny, nz = num_cells
    ijk = np.stack(np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1), indexing="ij"), -1)
    grid_vertices = ijk.reshape(-1, 3)

    def index(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k

    cells = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"), -1).reshape(-1, 3)
    if symmetric:
        step = np.where(cells + 0.5 < np.array(num_cells) / 2.0, -1, 1)
    else:
        step = np.ones_like(cells)
    start = cells + (step < 0)
    tets = []
    for perm in itertools.permutations(range(3)):
        corner = start.copy()
        path = [corner]
        for axis in perm:
            corner = corner.copy()
            corner[:, axis] += step[:, axis]
            path.append(corner)
        tets.append(np.stack([index(*p.T) for p in path], axis=1))
    tets = np.stack(tets, axis=1).reshape(-1, 4)
    return grid_vertices, tets, np.repeat(cells, 6, axis=0)


def _check_positive(name: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise HydrotactError(f"{name} must be a positive length in metres, got {value!r}")
    return value


MAX_TETS = 10_000_000
"""The most tets a mesh request may ask for (about 2 GB of mesh and field on the host);
an edge length that would exceed it is refused before any meshing (usually a unit slip)."""

TETS_PER_CUBE = 8.5
"""Tets of a good mesh per cube of its edge length (a regular tet is a^3 / (6 sqrt 2))."""


def check_tet_budget(num_tets: float, edge_length: float, volume: float, what: str, source: str | None = None) -> None:
    """Refuse an edge length that would make more than :data:`MAX_TETS` tets (an
    estimate, `num_tets`, of a body of `volume` m^3), naming the smallest edge allowed."""
    if num_tets > MAX_TETS:
        smallest = (TETS_PER_CUBE * volume / MAX_TETS) ** (1.0 / 3.0)
        raise HydrotactError(
            f"{where(source)}edge length {edge_length:g} m would make about {num_tets:.2g} tets of {what}; "
            f"hydrotact meshes up to {MAX_TETS:.0e} (an edge of at least {smallest:.2g} m; is the unit right?)".replace("e+0", "e")
        )


def make_box(
    size_S: tuple[float, float, float],
    edge_length: float,
    *,
    center_xy: tuple[float, float] = (0.0, 0.0),
    bottom: str = "core",
    top: str = "free",
    sides: str = "free",
    source: str | None = None,
) -> TetMesh:
    """A box [x0, x0 + sx] x [y0, y0 + sy] x [0, sz] centred at `center_xy`, bottom on z = 0.

    Cells are cubes of side at most `edge_length` (rounded so the box is divided
    evenly). `bottom`, `top` and `sides` are tag names: "free", "core" or "insulated".
    `source` names the box in messages.
    """
    size = np.array([_check_positive("box size", s) for s in size_S])
    edge_length = _check_positive("edge length", edge_length)
    cells = np.maximum(1.0, np.ceil(size / edge_length - 1e-9))
    check_tet_budget(6.0 * float(np.prod(cells)), edge_length, float(np.prod(size)), "a {:.3g} x {:.3g} x {:.3g} mm box".format(*(size * 1e3)), source)
    num_cells = tuple(int(n) for n in cells)
    grid_vertices, tets, _ = _kuhn_grid(num_cells)
    origin = np.array([center_xy[0] - size[0] / 2, center_xy[1] - size[1] / 2, 0.0])
    vertices = origin + grid_vertices / np.array(num_cells) * size
    tets = orient_tets(vertices, tets)
    names = {"free": FREE, "core": CORE, "insulated": INSULATED}
    for label, tag in (("bottom", bottom), ("top", top), ("sides", sides)):
        if tag not in names:
            raise HydrotactError(f"box {label} tag must be one of {sorted(names)}, got {tag!r}")

    def face_tags(boundary_faces, vertices_):
        centroids = vertices_[boundary_faces].mean(axis=1)
        tol = 1e-9 * size.max()
        tags = np.full(len(boundary_faces), names[sides], dtype=np.int64)
        tags[np.abs(centroids[:, 2]) <= tol] = names[bottom]
        tags[np.abs(centroids[:, 2] - size[2]) <= tol] = names[top]
        return tags

    return make_tet_mesh(vertices, tets, face_tags, source="box")


def make_spherical_shell(inner_radius: float, outer_radius: float, num_layers: int) -> TetMesh:
    """A shell r0 <= |p| <= R, centred at the origin, with `num_layers` cells through
    its thickness (and 4 * num_layers along each edge of the mapped cube).

    The inner sphere is tagged `core`, the outer `free`: the strain field solving
    Laplace's equation is e(r) = (1/r - 1/R) / (1/r0 - 1/R).
    """
    r0 = _check_positive("inner radius", inner_radius)
    r1 = _check_positive("outer radius", outer_radius)
    if r0 >= r1:
        raise HydrotactError(f"inner radius {r0} must be smaller than outer radius {r1}")
    if num_layers < 1:
        raise HydrotactError(f"num_layers must be >= 1, got {num_layers}")
    n = 4 * int(num_layers)
    grid_vertices, tets, cells = _kuhn_grid((n, n, n), symmetric=True)
    # Keep the cells outside the inner cube |x|_inf < 1/2.
    centres = (cells + 0.5) / n * 2.0 - 1.0
    tets = tets[np.max(np.abs(centres), axis=1) > 0.5]
    x = grid_vertices / n * 2.0 - 1.0
    s = np.max(np.abs(x), axis=1)
    radius = r0 + (r1 - r0) * (2.0 * s - 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        vertices = radius[:, None] * x / np.linalg.norm(x, axis=1, keepdims=True)
    vertices[s < 0.5 - 1e-12] = 0.0  # unused interior grid points (dropped below)
    tets = orient_tets(vertices, tets)
    mid = 0.5 * (r0 + r1)

    def is_core(centroids):
        return np.linalg.norm(centroids, axis=1) < mid

    return make_tet_mesh(vertices, tets, make_face_tagger(core=is_core, source="shell"), source="shell")


def make_ball(radius: float, num_layers: int) -> TetMesh:
    """A ball |p| <= R centred at the origin, all of its skin `free`: the grid on the
    cube [-1, 1]^3 with 2 * num_layers cells a side, mapped by p = R |x|_inf x / |x|
    (its skin vertices lie exactly on the sphere). Give the field solve a core_depth,
    or set a field directly (e.g. E (1 - r / R))."""
    radius = _check_positive("radius", radius)
    if num_layers < 1:
        raise HydrotactError(f"num_layers must be >= 1, got {num_layers}")
    n = 2 * int(num_layers)
    grid_vertices, tets, _ = _kuhn_grid((n, n, n), symmetric=True)
    x = grid_vertices / n * 2.0 - 1.0
    length = np.linalg.norm(x, axis=1, keepdims=True)
    scale = np.divide(np.max(np.abs(x), axis=1, keepdims=True), length, out=np.zeros_like(length), where=length > 0)
    vertices = radius * scale * x
    return make_tet_mesh(vertices, orient_tets(vertices, tets), source="ball")


def make_truncated_ellipsoid_surface(
    semi_axes: tuple[float, float, float],
    center_height: float,
    num_rings: int = 48,
):
    """Closed surface of the ellipsoid with `semi_axes` (a, b, c) centred at
    (0, 0, center_height), cut by the PCB plane z = 0 and closed by a flat base.

    Returns (vertices (n, 3), faces (m, 3)) wound outwards. `num_rings` sets the
    resolution (rings of latitude on the curved part; the base gets as many).
    """
    a, b, c = (_check_positive("semi-axis", s) for s in semi_axes)
    if not -c < center_height < c:
        raise HydrotactError(f"the plane z = 0 must cut the ellipsoid: centre height {center_height} not in (-{c}, {c})")
    polar_max = np.arccos(-center_height / c)  # polar angle (from +z) of the rim
    num_around = 2 * num_rings
    azimuth = np.linspace(0.0, 2 * np.pi, num_around, endpoint=False)
    polar = np.linspace(0.0, polar_max, num_rings + 1)[1:]
    rings = [
        np.stack(
            [a * np.sin(t) * np.cos(azimuth), b * np.sin(t) * np.sin(azimuth), center_height + c * np.cos(t) + 0 * azimuth],
            axis=1,
        )
        for t in polar
    ]
    rings[-1][:, 2] = 0.0  # the rim lies exactly on the PCB plane
    rim = rings[-1]
    num_base_rings = num_rings
    base_rings = [rim[:, :2] * f for f in np.linspace(1.0, 0.0, num_base_rings + 1)[1:-1]]
    base_rings = [np.column_stack([r, np.zeros(len(r))]) for r in base_rings]
    vertices = np.concatenate(
        [[[0.0, 0.0, center_height + c]], *rings, *base_rings, [[0.0, 0.0, 0.0]]]
    )
    faces = []
    nxt = np.roll(np.arange(num_around), -1)
    ring_start = lambda k: 1 + k * num_around
    all_rings = len(rings) + len(base_rings)
    # Fan at the top pole.
    faces.append(np.column_stack([np.zeros(num_around, int), ring_start(0) + np.arange(num_around), ring_start(0) + nxt]))
    for k in range(all_rings - 1):
        upper, lower = ring_start(k) + np.arange(num_around), ring_start(k + 1) + np.arange(num_around)
        upper_next, lower_next = ring_start(k) + nxt, ring_start(k + 1) + nxt
        faces.append(np.column_stack([upper, lower, lower_next]))
        faces.append(np.column_stack([upper, lower_next, upper_next]))
    centre = len(vertices) - 1
    last = ring_start(all_rings - 1)
    faces.append(np.column_stack([last + np.arange(num_around), np.full(num_around, centre), last + nxt]))
    faces = np.concatenate(faces)
    # Wind outwards: check the signed volume, flip if negative.
    tri = vertices[faces]
    volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
    if volume < 0:
        faces = faces[:, [0, 2, 1]]
    return vertices, faces


__all__ = ["Plane", "make_ball", "make_box", "make_spherical_shell", "make_truncated_ellipsoid_surface"]
