"""Defaults shared by the stages and the command line (no imports: the command line
reads them while it builds its parser, before JAX is loaded)."""

DEFAULT_MODULUS = 1e6
"""The hydroelastic modulus E (Pa) used when the user gives none: p = E e, so it sets
the scale of every pressure. 1 MPa is a typical hydroelastic modulus of a soft silicone
skin (of the order of its Young's modulus); set your own with `--modulus` or a
material.json (e.g. from `hydrotact fit`). Exported as `hydrotact.field.DEFAULT_MODULUS`."""
