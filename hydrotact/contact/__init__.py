"""Hydroelastic contact: soft-rigid, soft-half-space and soft-soft contact surfaces,
the wrench they exert, and the probes (with their spec strings)."""

from .._units import parse_length as parse_length
from ._api import (
    CPU_POSE_GROUP as CPU_POSE_GROUP,
    calc_contact_surface as calc_contact_surface,
    compute_contact_surface as compute_contact_surface,
    map_over_poses as map_over_poses,
)
from ._broadphase import Capacity as Capacity, TetClusters as TetClusters, make_tet_clusters as make_tet_clusters
from ._half_space import calc_half_space_surface as calc_half_space_surface
from ._polygon import calc_polygon_integrals as calc_polygon_integrals, clip_polygon as clip_polygon
from ._pose import Pose as Pose, calc_rotation_from_vector as calc_rotation_from_vector, make_pose as make_pose
from ._press import calc_skin_height as calc_skin_height, parse_at as parse_at, press_probe as press_probe
from ._probes import (
    AbstractProbe as AbstractProbe,
    HalfSpace as HalfSpace,
    RigidSurface as RigidSurface,
    make_box_probe as make_box_probe,
    make_cylinder_probe as make_cylinder_probe,
    make_rigid_surface as make_rigid_surface,
    make_sphere_probe as make_sphere_probe,
    parse_probe as parse_probe,
)
from ._soft_rigid import calc_soft_rigid_surface as calc_soft_rigid_surface
from ._soft_soft import calc_soft_soft_surface as calc_soft_soft_surface
from ._surface import ContactSurface as ContactSurface
