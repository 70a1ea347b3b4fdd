"""An elastomer from its mould: the cast is the mould's cavity.

Users of a cast sensor have the mould's CAD (an STL per part, in the CAD's
coordinates), not a surface of the elastomer. The cavity is found by boolean
operations in manifold3d: the parts' union, its convex hull less the union, and that
difference's connected pieces. A closed mould (its parts assembled in place) encloses
its cavity: the one piece whose whole boundary is the mould's. An open mould (a tray,
its pour face or parting plane left open) holds its cavity in the largest piece of its
hull less itself; the other pieces are notches of its outside, and one of them as
large as half the cavity is an ambiguity we refuse rather than guess.
"""

from pathlib import Path

import numpy as np
import trimesh

from .._choices import BOARD_FACES
from .._errors import HydrotactError
from .._units import LENGTH_UNITS
from ._surface import check_surface_size

ENCLOSED_SHARE = 0.999
"""A piece of hull − mould whose boundary is this much the mould's is an enclosed void."""

RIVAL_SHARE = 0.5
"""An open mould's second-largest piece larger than this share of the largest makes the
cavity ambiguous (a mould with two cavities, or a cavity the parting plane cuts)."""


def _manifold(surface: trimesh.Trimesh, source: str):
    import manifold3d

    mesh = manifold3d.Mesh64(vert_properties=np.asarray(surface.vertices, dtype=np.float64), tri_verts=np.asarray(surface.faces, dtype=np.uint64))
    solid = manifold3d.Manifold(mesh)
    if solid.status() != manifold3d.Error.NoError:
        reason = str(solid.status()).rsplit(".", 1)[-1]
        raise HydrotactError(f"{source}: the mould is not a closed solid ({reason}): export it as a closed, consistently wound surface")
    return solid


def _read_part(path: Path, scale: float) -> trimesh.Trimesh:
    if not path.is_file():
        raise HydrotactError(f"{path}: no such file")
    try:
        surface = trimesh.load(str(path), force="mesh")
    except Exception as error:  # trimesh raises many kinds for unreadable files
        raise HydrotactError(f"{path}: cannot read as a surface mesh ({str(error)[:100]})") from None
    if not isinstance(surface, trimesh.Trimesh) or len(surface.faces) == 0:
        raise HydrotactError(f"{path}: contains no triangles")
    if not np.all(np.isfinite(surface.vertices)):
        raise HydrotactError(f"{path}: has non-finite vertex coordinates")
    if not surface.is_watertight:
        edges, counts = np.unique(surface.edges_sorted, axis=0, return_counts=True)
        detail = f"{int(np.sum(counts != 2))} edges do not belong to exactly two triangles"
        raise HydrotactError(f"{path}: the mould is not closed ({detail}): export it as a closed surface")
    surface.apply_scale(scale)
    return surface


def _board_rotation(board: str) -> np.ndarray:
    """The rotation taking the mould's `board` direction to −z (the sensor's board lies
    below its elastomer), turning about x where it can, so the mould's x stays x."""
    axis = "xyz".index(board[0])
    sign = 1.0 if board.endswith("max") else -1.0
    if axis == 2:
        return np.eye(3) if sign < 0 else np.diag([1.0, -1.0, -1.0])
    if axis == 1:  # ±y → −z: a quarter turn about x
        c = -sign
        return np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -c], [0.0, c, 0.0]])
    # ±x → −z: a quarter turn about y
    c = -sign
    return np.array([[0.0, 0.0, -c], [0.0, 1.0, 0.0], [c, 0.0, 0.0]])


def make_mould_cavity(paths, *, units: str = "mm", board: str = "zmin") -> tuple[trimesh.Trimesh, np.ndarray]:
    """The cast of a mould: (its closed surface in metres, in the sensor's frame; the 4×4
    transform from the mould's coordinates, in `units`, to that frame, in metres) (host).

    **Arguments:**

    - `paths`: the mould's part files (STL, OBJ, ...), assembled in place as the CAD
      exported them: one open tray, or the parts of a closed mould.
    - `units`: the length unit of the files' coordinates (CAD exports are usually mm).
    - `board`: which side of the cavity lies on the sensor's board (`xmin` … `zmax`: its
      side towards the mould's -x … +z). The sensor frame puts that side down: the cast's lowest
      point at z = 0 and its footprint centred on x = y = 0, the board-side face bonded
      there (the mesh's core plane) and the other faces free.

    Raises a HydrotactError naming the file where a part is not closed, and the mould
    where it has no cavity or its cavity is not one piece.
    """
    import manifold3d

    if units not in LENGTH_UNITS:
        raise HydrotactError(f"--units: unknown length unit {units!r}; use one of {', '.join(LENGTH_UNITS)}")
    if board not in BOARD_FACES:
        raise HydrotactError(f"--board: {board!r} is not a side of the mould; use one of {', '.join(BOARD_FACES)}")
    paths = [Path(p) for p in ([paths] if isinstance(paths, str | Path) else paths)]
    if not paths:
        raise HydrotactError("--mould: give at least one mould file")
    scale = LENGTH_UNITS[units]
    name = paths[0].name if len(paths) == 1 else f"the mould ({', '.join(p.name for p in paths)})"
    mould = manifold3d.Manifold.batch_boolean([_manifold(_read_part(p, scale), str(p)) for p in paths], manifold3d.OpType.Add)
    pieces = sorted((mould.hull() - mould).decompose(), key=lambda p: -p.volume())
    pieces = [p for p in pieces if p.volume() > 1e-9 * mould.volume()]
    if not pieces:
        raise HydrotactError(f"{name}: has no cavity (it is convex): give the part the elastomer is cast in, or all the mould's parts together")
    area = mould.surface_area()
    enclosed = [p for p in pieces if (p.surface_area() + area - (p + mould).surface_area()) / 2.0 >= ENCLOSED_SHARE * p.surface_area()]
    if len(enclosed) > 1:
        volumes = ", ".join(f"{p.volume() / scale**3:.4g}" for p in enclosed)
        raise HydrotactError(f"{name}: the cavity is not one piece: {len(enclosed)} enclosed cavities ({volumes} {units}³); mesh each part's mould on its own")
    if enclosed:
        cavity = enclosed[0]
    else:
        if len(pieces) > 1 and pieces[1].volume() > RIVAL_SHARE * pieces[0].volume():
            volumes = ", ".join(f"{p.volume() / scale**3:.4g}" for p in pieces[:2])
            raise HydrotactError(f"{name}: the cavity is not one piece: the open mould's two largest hollows ({volumes} {units}³) are alike; give all the mould's parts, assembled")
        cavity = pieces[0]
    mesh = cavity.to_mesh64()
    surface = trimesh.Trimesh(np.asarray(mesh.vert_properties[:, :3], dtype=np.float64), np.asarray(mesh.tri_verts, dtype=np.int64), process=True)
    rotation = _board_rotation(board)
    turned = surface.vertices @ rotation.T
    lo, hi = turned.min(axis=0), turned.max(axis=0)
    shift = -np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), lo[2]])
    transform = np.eye(4)
    transform[:3, :3] = rotation * scale
    transform[:3, 3] = shift
    surface.vertices = turned + shift
    if surface.volume < 0:
        surface.invert()
    check_surface_size(surface, name, units)
    return surface, transform
