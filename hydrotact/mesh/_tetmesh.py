"""The tetrahedral mesh of an elastomer, with tagged boundary faces.

Conventions. Vertices are in metres, in the sensor frame S (+z along the pad normal,
the PCB in the plane z = 0 for the built-in sensors). A tet (v0, v1, v2, v3) is
positively oriented: det[v1 - v0, v2 - v0, v3 - v0] > 0. Boundary faces are wound
counter-clockwise seen from outside, so (b - a) x (c - a) points out of the body.
Each boundary face carries a tag: `free` (skin that can be touched, strain 0), `core`
(bonded to the PCB or a rigid insert, strain 1) or `insulated` (a symmetry or cut
plane with no boundary condition, i.e. zero normal flux).
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError, where
from .._types import Array, Float, Int

FREE = 0
CORE = 1
INSULATED = 2
TAG_NAMES = {"free": FREE, "core": CORE, "insulated": INSULATED}

# Faces of a positively oriented tet, each wound so that its normal points outwards;
# face k is the one opposite local vertex k.
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)


class TetMesh(eqx.Module):
    """A tetrahedral mesh with tagged, outward-wound boundary faces (a pytree).

    Built on the host by :func:`make_tet_mesh` (which checks it); its arrays then go
    to the device unchanged. `vertices` is the differentiable leaf.

    **Fields:**

    - `vertices`: (num_vertices, 3) positions p_SV in metres.
    - `tets`: (num_tets, 4) vertex indices, positively oriented.
    - `boundary_faces`: (num_faces, 3) vertex indices, outward wound.
    - `face_tags`: (num_faces,) one of FREE, CORE, INSULATED.
    """

    vertices: Float[Array, "num_vertices 3"]
    tets: Int[Array, "num_tets 4"]
    boundary_faces: Int[Array, "num_faces 3"]
    face_tags: Int[Array, " num_faces"]

    @property
    def num_vertices(self) -> int:
        return self.vertices.shape[0]

    @property
    def num_tets(self) -> int:
        return self.tets.shape[0]

    @property
    def num_faces(self) -> int:
        return self.boundary_faces.shape[0]

    def faces_tagged(self, tag: int) -> np.ndarray:
        """The boundary faces (k, 3) with the given tag (host)."""
        return np.asarray(self.boundary_faces)[np.asarray(self.face_tags) == tag]

    def vertices_tagged(self, tag: int) -> np.ndarray:
        """Boolean mask over vertices that lie on a face with the given tag (host)."""
        mask = np.zeros(self.num_vertices, dtype=bool)
        mask[self.faces_tagged(tag).reshape(-1)] = True
        return mask


def calc_signed_volumes(vertices, tets):
    """Signed volume of each tet, det[v1 - v0, v2 - v0, v3 - v0] / 6 (NumPy or JAX)."""
    xp = np if isinstance(vertices, np.ndarray) else jnp
    p = vertices[tets]
    e1, e2, e3 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    return xp.einsum("ij,ij->i", xp.cross(e1, e2), e3) / 6.0


def extract_boundary_faces(tets: np.ndarray, source: str | None = None) -> np.ndarray:
    """Faces that belong to exactly one tet, wound outwards (host).

    Raises if a face is shared by more than two tets (the mesh is not a manifold).
    """
    all_faces = tets[:, TET_FACES].reshape(-1, 3)
    keys = np.sort(all_faces, axis=1)
    _, first, inverse, counts = np.unique(
        keys, axis=0, return_index=True, return_inverse=True, return_counts=True
    )
    if np.any(counts > 2):
        bad = int(np.flatnonzero(counts[inverse.reshape(-1)] > 2)[0] // 4)
        raise HydrotactError(
            f"{where(source)}tet {bad} shares a face with two or more other tets: "
            "the tetrahedral mesh is not a manifold"
        )
    return all_faces[np.sort(first[counts == 1])]


def _reference_length(vertices: np.ndarray, tets: np.ndarray) -> float:
    p = vertices[tets]
    edges = p[:, [1, 2, 3, 2, 3, 3]] - p[:, [0, 0, 0, 1, 1, 2]]
    return float(np.mean(np.linalg.norm(edges, axis=-1)))


def check_vertices(vertices: np.ndarray, source: str | None = None) -> np.ndarray:
    """Vertices as a finite (n, 3) float64 array, or a clear error."""
    vertices = np.asarray(vertices, dtype=np.float64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise HydrotactError(f"{where(source)}vertices must have shape (n, 3), got {vertices.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(vertices), axis=1))
    if bad.size:
        raise HydrotactError(
            f"{where(source)}vertex {int(bad[0])} has a non-finite coordinate "
            f"{vertices[bad[0]].tolist()} ({bad.size} such vertices)"
        )
    return vertices


def make_tet_mesh(
    vertices,
    tets,
    face_tags=None,
    *,
    source: str | None = None,
) -> TetMesh:
    """Check a tetrahedral mesh and build the :class:`TetMesh` (host).

    Unused vertices are dropped. The checks: finite coordinates, indices in range, no
    inverted (negative volume) or degenerate (|volume| below 1e-9 of the mean edge
    cubed) tets, every face shared by at most two tets.

    **Arguments:**

    - `vertices`: (num_vertices, 3) in metres.
    - `tets`: (num_tets, 4) positively oriented.
    - `face_tags`: tags for the boundary faces, as a callable
      `f(boundary_faces, vertices) -> tags`, or None for all `free`.
    - `source`: the file or description to name in error messages.
    """
    vertices = check_vertices(vertices, source)
    tets = np.asarray(tets)
    if tets.ndim != 2 or tets.shape[1] != 4 or tets.shape[0] == 0:
        raise HydrotactError(f"{where(source)}tets must have shape (n, 4) with n > 0, got {tets.shape}")
    tets = tets.astype(np.int64)
    if tets.min() < 0 or tets.max() >= len(vertices):
        raise HydrotactError(
            f"{where(source)}tet vertex indices must lie in [0, {len(vertices)}), "
            f"got [{tets.min()}, {tets.max()}]"
        )
    if np.any(np.sort(tets, axis=1)[:, 1:] == np.sort(tets, axis=1)[:, :-1]):
        bad = int(np.flatnonzero(np.any(np.diff(np.sort(tets, axis=1)) == 0, axis=1))[0])
        raise HydrotactError(f"{where(source)}tet {bad} repeats a vertex: it has zero volume")
    # Drop unused vertices (they would make the Laplace system singular).
    used = np.zeros(len(vertices), dtype=bool)
    used[tets.reshape(-1)] = True
    if not used.all():
        remap = np.cumsum(used) - 1
        vertices, tets = vertices[used], remap[tets]

    volumes = calc_signed_volumes(vertices, tets)
    scale = _reference_length(vertices, tets) ** 3
    degenerate = np.flatnonzero(np.abs(volumes) <= 1e-9 * scale)
    if degenerate.size:
        k = int(degenerate[0])
        raise HydrotactError(
            f"{where(source)}tet {k} is degenerate (volume {volumes[k]:.3g} m^3; "
            f"{degenerate.size} such tets)"
        )
    inverted = np.flatnonzero(volumes < 0)
    if inverted.size:
        k = int(inverted[0])
        raise HydrotactError(
            f"{where(source)}tet {k} is inverted (volume {volumes[k]:.3g} m^3; {inverted.size} such "
            "tets): tets must be positively oriented, det[v1-v0, v2-v0, v3-v0] > 0"
        )
    boundary_faces = extract_boundary_faces(tets, source)
    if face_tags is None:
        tags = np.full(len(boundary_faces), FREE, dtype=np.int64)
    else:
        tags = np.asarray(face_tags(boundary_faces, vertices), dtype=np.int64)
        if tags.shape != (len(boundary_faces),):
            raise HydrotactError(f"{where(source)}face tags have shape {tags.shape}, expected ({len(boundary_faces)},)")
    return TetMesh(
        vertices=vertices,
        tets=tets,
        boundary_faces=boundary_faces,
        face_tags=tags,
    )


def orient_tets(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Swap two vertices of every negatively oriented tet (for meshers' output)."""
    tets = np.array(tets, dtype=np.int64)
    negative = calc_signed_volumes(np.asarray(vertices, dtype=np.float64), tets) < 0
    tets[negative] = tets[negative][:, [0, 2, 1, 3]]
    return tets
