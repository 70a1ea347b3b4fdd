"""Taxels: what each barometer reads of a contact surface, by ray casting its
receptive field (disk or cone) and aggregating the pressures hit."""

from ._patterns import (
    ReceptiveFieldKind as ReceptiveFieldKind,
)
from ._patterns import (
    TaxelLayout as TaxelLayout,
)
from ._patterns import (
    calc_spiral as calc_spiral,
)
from ._patterns import (
    calc_taxel_rays as calc_taxel_rays,
)
from ._patterns import (
    make_taxel_layout as make_taxel_layout,
)
from ._raycast import calc_first_hits as calc_first_hits
from ._raycast import calc_surface_triangles as calc_surface_triangles
from ._raycast import intersect_ray_triangle as intersect_ray_triangle
from ._sample import (
    TaxelCapacity as TaxelCapacity,
)
from ._sample import (
    TaxelReadings as TaxelReadings,
)
from ._sample import (
    calc_taxel_pressures as calc_taxel_pressures,
)
from ._sample import (
    sample_taxels as sample_taxels,
)
