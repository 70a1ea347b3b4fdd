"""hydrotact: differentiable simulation and system identification for barometric
tactile sensors (MEMS barometers cast in silicone), in JAX.

Stages, one sub-package each: `hydrotact.mesh` (tet meshes of the elastomer),
`hydrotact.field` (strain and pressure fields), `hydrotact.viz` (renders).
Units are SI throughout (m, Pa, N, s, rad).
"""

from ._errors import HydrotactError as HydrotactError

__version__ = "0.1.0"
