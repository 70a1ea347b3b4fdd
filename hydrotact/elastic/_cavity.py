"""Barometers sealed in air pockets: what the pocket's air reads, by reciprocity.

Many cast sensors do not fill the barometer's port with rubber: the elastomer has a
pocket that fits over the package (the MTL strip's 3 x 5 x 1.2 mm pockets), and the
barometer reads the air trapped in it. A press that bends the pocket's ceiling
squeezes that air; the rubber's stress at the ceiling (an `elastic` port reading) is
tension there, the opposite of what the barometer shows.

The barometer reads the air's pressure p. With K u = f (the contact's loads, the
stiffness at E = 1 Pa) and f_V the consistent nodal loads of a unit pressure on the
pocket's faces (the traction -n, n the elastomer's outward normal), the pocket's
volume grows by dV = f_V . u / E, and a pocket pressure p adds p f_V to the loads. Its
air, V0 at the bulk modulus K_a (isothermal: the ambient pressure), obeys
p = -K_a dV / V0, so

    p = p_stiff / (1 + E V0 / (K_a C)),    p_stiff = -(f_V . K^-1 f) / C,

with C = f_V . K^-1 f_V the pocket's compliance at E = 1 Pa (m^3 / Pa; its own is
C / E). p_stiff is the pressure that keeps the pocket's volume, what stiff air (or a
pocket the package nearly fills: V0 << K_a C / E) reads. By reciprocity (K symmetric)
p_stiff = f . w with w = -K^-1 f_V / C: one solve per pocket gives its receptive
field, the pressure per newton at any node, exactly like a port barometer's
(:mod:`hydrotact.elastic._barometers`), and contact tractions are integrated against it
the same way. Like those, it does not depend on E; the air's factor
(:func:`calc_air_factor`) does: on test_elastic's 2 x 2 x 1 mm pocket in E = 1 MPa
rubber, C / E = 8.7e-15 m^3 / Pa, so K_a C / E = 0.87 mm^3, and the empty pocket's
4 mm^3 of air reads under a fifth of p_stiff. A package that fills all but ~1 mm^3 of its
pocket reads about half.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .._errors import HydrotactError
from .._types import Array, Float
from ..mesh import CORE, TetMesh
from ._barometers import ReceptiveFields, _solve_settings
from ._loads import calc_face_loads, make_face_quadrature
from ._problem import ElasticProblem, solve_reduced

AIR_MODULUS = 101325.0
"""Pa: the isothermal bulk modulus of air at sea level (its pressure), for presses
slower than the pocket's heat exchange (the adiabatic one is 1.4 times it)."""


def calc_air_factor(compliances, modulus, air_volumes, air_modulus=AIR_MODULUS):
    """What share of the stiff-air reading a pocket of air volume `air_volumes` (m^3)
    reads in rubber of Young's modulus `modulus` (Pa): 1 / (1 + E V0 / (K_a C)), C the
    compliances at E = 1 Pa (:class:`CavityFields`); 1 for no air (pure, broadcasts)."""
    return 1.0 / (1.0 + modulus * air_volumes / (air_modulus * compliances))


def find_cavity_faces(mesh: TetMesh, point, fixed_tag: int = CORE) -> np.ndarray:
    """The boundary faces (F, 3) (vertex indices, wound outward) of the pocket a
    barometer at `point` (m) reads: the connected set (faces sharing an edge) of the
    boundary faces that are not fixed to the board, holding the face nearest `point`
    (host). A pocket is closed by the board (its free faces meet the rest only through
    fixed ones) or is a void. Refused where that set encloses rubber, not air
    (:func:`calc_cavity_volume` negative: the barometer is on the elastomer's skin)."""
    faces = np.asarray(mesh.boundary_faces)
    tags = np.asarray(mesh.face_tags)
    vertices = np.asarray(mesh.vertices)
    free = np.flatnonzero(tags != fixed_tag)
    if len(free) == 0:
        raise HydrotactError("the mesh has no free faces: no pocket to read")
    centroids = vertices[faces[free]].mean(axis=1)
    seed = int(np.argmin(np.linalg.norm(centroids - np.asarray(point, dtype=np.float64)[None], axis=1)))
    # Faces sharing an edge are neighbours (scipy's connected components over them).
    edges = np.sort(np.concatenate([faces[free][:, [0, 1]], faces[free][:, [1, 2]], faces[free][:, [2, 0]]]), axis=1)
    owners = np.tile(np.arange(len(free)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, owners = edges[order], owners[order]
    same = np.all(edges[1:] == edges[:-1], axis=1)
    graph = coo_matrix((np.ones(int(same.sum())), (owners[:-1][same], owners[1:][same])), shape=(len(free), len(free)))
    labels = connected_components(graph, directed=False)[1]
    found = np.flatnonzero(labels == labels[seed])
    pocket = faces[free[found]]
    if calc_cavity_volume(mesh, pocket, fixed_tag) <= 0.0:
        at = ", ".join(f"{v * 1e3:g}" for v in np.asarray(point, dtype=np.float64))
        raise HydrotactError(f"the barometer at ({at}) mm is not in a pocket: the free faces nearest it enclose the elastomer (its skin), not air")
    return pocket


def calc_cavity_volume(mesh: TetMesh, cavity_faces, fixed_tag: int = CORE) -> float:
    """The volume (m^3) a pocket's faces enclose with the board (host): the divergence
    theorem over its faces, -1/3 sum of (x - o) . n dA with the elastomer's outward
    normals n and o the mean of the fixed faces' vertices (on a flat board's plane, whose
    own faces add nothing). Positive for a pocket (the faces' normals point into it),
    negative for the elastomer's skin, whose faces enclose rubber."""
    vertices = np.asarray(mesh.vertices)
    fixed = np.asarray(mesh.boundary_faces)[np.asarray(mesh.face_tags) == fixed_tag]
    origin = vertices[fixed].reshape(-1, 3).mean(axis=0) if len(fixed) else np.zeros(3)
    corners = vertices[np.asarray(cavity_faces, dtype=np.int64)] - origin
    return float(-np.sum(np.einsum("fd,fd->f", corners[:, 0], np.cross(corners[:, 1], corners[:, 2]))) / 6.0)


class CavityFields(eqx.Module):
    """Pocket barometers' receptive fields and what they are built from (a pytree).

    **Fields:**

    - `fields`: :class:`ReceptiveFields` whose `responses` (num_nodes, K, 3) are each
      pocket's pressure per newton at each node (the stiff-air limit, Pa / N), to
      integrate contact tractions against with :func:`calc_elastic_readings`.
    - `compliances`: (K,) each pocket's volume per unit pocket pressure at E = 1 Pa,
      m^3 / Pa (divide by E for the elastomer's).
    - `volume_loads`: (K, num_nodes, 3) the consistent loads of a unit pressure on
      each pocket's faces: the pocket's volume grows by volume_loads[k] . u.
    """

    fields: ReceptiveFields
    compliances: Float[Array, " num_cavities"]
    volume_loads: Float[Array, "num_cavities num_nodes 3"]


def calc_cavity_loads(problem: ElasticProblem, cavity_faces) -> jnp.ndarray:
    """(num_nodes, 3) the consistent loads of a unit pressure on the boundary faces
    `cavity_faces` ((F, 3) vertex indices, wound outward; host): the traction -n
    pushing the elastomer away from the pocket."""
    quadrature = make_face_quadrature(problem, np.asarray(cavity_faces, dtype=np.int64))
    return calc_face_loads(problem, quadrature, -jnp.asarray(quadrature.normals_S))


@eqx.filter_jit
def _cavity_fields(problem, loads, vertices, nu, rtol, max_steps, throw, multigrid):
    mask = (~problem.is_fixed).astype(vertices.dtype)[None, :, None]
    params = (vertices, nu, jnp.asarray(1.0, vertices.dtype))
    solve = jax.vmap(lambda rhs: solve_reduced(problem, params, rhs, rtol, max_steps, throw, multigrid))
    solved, num_steps, relative, _ = solve(mask * loads)
    solved = mask * solved  # (K, num_nodes, 3): K^-1 f_V at E = 1 Pa
    compliances = jnp.einsum("knd,knd->k", loads, solved)
    responses = -solved / compliances[:, None, None]
    fields = ReceptiveFields(
        vertices=vertices, tets=problem.tets, tet_nodes=problem.tet_nodes, responses=jnp.moveaxis(responses, 0, 1),
        num_steps=jnp.max(num_steps), relative_residual=jnp.max(relative),
    )
    return CavityFields(fields=fields, compliances=compliances, volume_loads=loads)


def calc_cavity_fields(
    problem: ElasticProblem,
    cavities,
    *,
    poisson_ratio=None,
    rtol: float | None = None,
    max_steps: int | None = None,
    throw: bool = True,
    multigrid=None,
) -> CavityFields:
    """Each pocket's receptive field, one solve each (host around a jitted solve).

    **Arguments:** `problem` from :func:`make_elastic_problem`; `cavities` a list of
    each pocket's boundary faces ((F, 3), as :func:`find_cavity_faces` gives them);
    the rest as :func:`solve_elasticity`'s.
    """
    if len(cavities) == 0:
        raise HydrotactError("calc_cavity_fields: no cavities given")
    vertices, nu, rtol, max_steps = _solve_settings(problem, None, poisson_ratio, rtol, max_steps)
    loads = jnp.stack([calc_cavity_loads(problem, faces) for faces in cavities]).astype(vertices.dtype)
    return _cavity_fields(problem, loads, vertices, nu, rtol, max_steps, throw, multigrid)
