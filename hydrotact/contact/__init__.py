"""Hydroelastic contact: soft-rigid, soft-half-space and soft-soft contact surfaces,
the wrench they exert, and the probes (with their spec strings)."""

from .._units import parse_length as parse_length
from ._api import (
    CPU_POSE_GROUP as CPU_POSE_GROUP,
)
from ._api import (
    calc_contact_surface as calc_contact_surface,
)
from ._api import (
    compute_contact_surface as compute_contact_surface,
)
from ._api import (
    map_over_poses as map_over_poses,
)
from ._broadphase import Capacity as Capacity
from ._broadphase import TetClusters as TetClusters
from ._broadphase import make_tet_clusters as make_tet_clusters
from ._half_space import calc_half_space_surface as calc_half_space_surface
from ._polygon import calc_polygon_integrals as calc_polygon_integrals
from ._polygon import clip_polygon as clip_polygon
from ._pose import Pose as Pose
from ._pose import calc_rotation_from_vector as calc_rotation_from_vector
from ._pose import make_pose as make_pose
from ._press import calc_skin_height as calc_skin_height
from ._press import parse_at as parse_at
from ._press import press_probe as press_probe
from ._probes import (
    AbstractProbe as AbstractProbe,
)
from ._probes import (
    HalfSpace as HalfSpace,
)
from ._probes import (
    RigidSurface as RigidSurface,
)
from ._probes import (
    make_box_probe as make_box_probe,
)
from ._probes import (
    make_cylinder_probe as make_cylinder_probe,
)
from ._probes import (
    make_rigid_surface as make_rigid_surface,
)
from ._probes import (
    make_sphere_probe as make_sphere_probe,
)
from ._probes import (
    parse_probe as parse_probe,
)
from ._soft_rigid import calc_soft_rigid_surface as calc_soft_rigid_surface
from ._soft_soft import calc_soft_soft_surface as calc_soft_soft_surface
from ._surface import ContactSurface as ContactSurface
