"""Taxels: what each barometer reads of a contact surface, by ray casting its
receptive field (disk or cone) and aggregating the pressures hit."""

from ._patterns import (
    ReceptiveFieldKind as ReceptiveFieldKind,
    TaxelLayout as TaxelLayout,
    calc_spiral as calc_spiral,
    calc_taxel_rays as calc_taxel_rays,
    make_taxel_layout as make_taxel_layout,
)
from ._raycast import calc_first_hits as calc_first_hits, calc_surface_triangles as calc_surface_triangles, intersect_ray_triangle as intersect_ray_triangle
from ._sample import (
    TaxelCapacity as TaxelCapacity,
    TaxelReadings as TaxelReadings,
    calc_taxel_pressures as calc_taxel_pressures,
    sample_taxels as sample_taxels,
)
