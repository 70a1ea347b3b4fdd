"""Which boundary faces are `core` (or `insulated`): planes, face sets and predicates."""

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from .._errors import HydrotactError, where
from ._tetmesh import CORE, FREE, INSULATED


class Plane(NamedTuple):
    """The plane through `point_S` with normal `normal_S`; a face lies on it when all
    three of its vertices are within `tolerance` metres of it."""

    point_S: tuple[float, float, float]
    normal_S: tuple[float, float, float] = (0.0, 0.0, 1.0)
    tolerance: float = 1e-7

    def contains(self, points: np.ndarray) -> np.ndarray:
        normal = np.asarray(self.normal_S, dtype=np.float64)
        normal = normal / np.linalg.norm(normal)
        return np.abs((points - np.asarray(self.point_S)) @ normal) <= self.tolerance

    def describe(self) -> str:
        return f"plane through {list(self.point_S)} with normal {list(self.normal_S)}"


# A core (or insulated) selection: a Plane, or a predicate on face centroids (k, 3)
# returning a boolean mask (k,).
FaceSelection = Plane | Callable[[np.ndarray], np.ndarray]


def select_faces(selection: FaceSelection, faces: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Boolean mask over `faces` chosen by `selection` (host)."""
    if isinstance(selection, Plane):
        on_plane = selection.contains(vertices)
        return np.all(on_plane[faces], axis=1)
    centroids = vertices[faces].mean(axis=1)
    mask = np.asarray(selection(centroids), dtype=bool)
    if mask.shape != (len(faces),):
        raise HydrotactError(
            f"the face predicate returned shape {mask.shape}, expected ({len(faces)},)"
        )
    return mask


def make_face_tagger(
    core: FaceSelection | None = None,
    insulated: FaceSelection | None = None,
    *,
    source: str | None = None,
    require_core: bool = True,
):
    """A `face_tags(boundary_faces, vertices)` callable for :func:`make_tet_mesh`.

    Faces selected by `core` are CORE, then those selected by `insulated` are
    INSULATED, the rest FREE. With `require_core`, a selection that matches no face is
    an error (naming the selection).
    """

    def face_tags(boundary_faces: np.ndarray, vertices: np.ndarray) -> np.ndarray:
        tags = np.full(len(boundary_faces), FREE, dtype=np.int64)
        if core is not None:
            is_core = select_faces(core, boundary_faces, vertices)
            if require_core and not is_core.any():
                what = core.describe() if isinstance(core, Plane) else "the core predicate"
                raise HydrotactError(f"{where(source)}no boundary face lies on the core: {what} matches none")
            tags[is_core] = CORE
        if insulated is not None:
            tags[select_faces(insulated, boundary_faces, vertices)] = INSULATED
        return tags

    return face_tags
