"""Tetrahedral meshes of elastomers: the TetMesh pytree, builders, quality, I/O."""

from ._io import MESH_SUFFIXES as MESH_SUFFIXES, read_mesh as read_mesh, to_pyvista as to_pyvista, write_mesh as write_mesh
from ._load import load_tet_mesh as load_tet_mesh
from ._mould import BOARD_FACES as BOARD_FACES, make_mould_cavity as make_mould_cavity
from ._primitives import (
    make_ball as make_ball,
    make_box as make_box,
    make_spherical_shell as make_spherical_shell,
    make_truncated_ellipsoid_surface as make_truncated_ellipsoid_surface,
)
from ._quality import (
    calc_dihedral_angles as calc_dihedral_angles,
    calc_mesh_quality as calc_mesh_quality,
    calc_radius_ratios as calc_radius_ratios,
)
from ._seeds import SEED_SENSORS as SEED_SENSORS, make_seed_mesh as make_seed_mesh, seed_surface as seed_surface
from ._surface import (
    SURFACE_SUFFIXES as SURFACE_SUFFIXES,
    check_surface as check_surface,
    find_self_intersections as find_self_intersections,
    load_surface as load_surface,
)
from ._tags import Plane as Plane, make_face_tagger as make_face_tagger
from ._tetmesh import (
    CORE as CORE,
    FREE as FREE,
    INSULATED as INSULATED,
    TAG_NAMES as TAG_NAMES,
    TetMesh as TetMesh,
    calc_signed_volumes as calc_signed_volumes,
    extract_boundary_faces as extract_boundary_faces,
    make_tet_mesh as make_tet_mesh,
    orient_tets as orient_tets,
)
from ._tetrahedralize import tetrahedralize as tetrahedralize
