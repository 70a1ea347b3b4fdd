"""Which strain field an elastomer gets."""

from .._choices import Choice


class StrainFieldKind(Choice):
    """Strain field kind: `laplace`, the physical field (Laplace's equation, e = 0 on
    the free skin and 1 on the core), or `distance`, Drake's field (e = d / d_max,
    the distance from the skin over its largest value), for comparisons with Drake."""

    LAPLACE = "laplace"
    DISTANCE = "distance"
