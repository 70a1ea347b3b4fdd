"""Defaults shared by the stages and the command line (no imports: the command line
reads them while it builds its parser, before JAX is loaded)."""

DEFAULT_MODULUS = 1e6
"""The hydroelastic modulus E (Pa) used when the user gives none: p = E e, so it sets
the scale of every pressure. 1 MPa is a typical hydroelastic modulus of a soft silicone
skin (of the order of its Young's modulus); set your own with `--modulus` or a
material.json (e.g. from `hydrotact fit`). Exported as `hydrotact.field.DEFAULT_MODULUS`."""

DEFAULT_DATASET_MODULUS = 3e6
"""The hydroelastic modulus (Pa) of `hydrotact generate` without a material: calibrated
to the barometric estimation paper's data-collection regime on the built-in curved
sensors. At 3 MPa a 3 mm sphere reaches the paper's 8 N within half the elastomer's
thickness everywhere on the skin (at 1 MPa it reaches 3-4 N on top of sphere8), and
the channels swing with standard deviations inside the published 3-9 kPa: a bonded,
nearly incompressible silicone layer is stiffer in the hydroelastic sense than its
Young's modulus. A fitted material.json replaces it."""
