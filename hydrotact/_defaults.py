"""Defaults shared by the stages and the command line (no imports: the command line
reads them while it builds its parser, before JAX is loaded)."""

DEFAULT_MODULUS = 1e6
"""The hydroelastic modulus E (Pa) used when the user gives none: p = E e, so it sets
the scale of every pressure. 1 MPa is a typical hydroelastic modulus of a soft silicone
skin (of the order of its Young's modulus); set your own with `--modulus` or a
material.json (e.g. from `hydrotact fit`). Exported as `hydrotact.field.DEFAULT_MODULUS`."""

DEFAULT_DATASET_MODULUS = 3e6
"""The hydroelastic modulus (Pa) of `hydrotact generate` without a material, chosen for
the barometric estimation paper's data-collection regime on the built-in curved
sensors: at 3 MPa a 3 mm sphere reaches the paper's 8 N within half the elastomer's
thickness (measured along the inward normal at six points of sphere8: 3.2-3.4 N at
6 mm on top at 1 MPa, and the force is linear in E), where at 1 MPa it reaches only
3-4 N on top. A bonded, nearly incompressible silicone layer is stiffer in the
hydroelastic sense than its Young's modulus. Each manifest reports the channels'
swing next to the published 3-9 kPa. A fitted material.json replaces it."""
