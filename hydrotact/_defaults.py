"""Defaults shared by the stages and the command line (no imports: the command line
reads them while it builds its parser, before JAX is loaded)."""

DEFAULT_MODULUS = 1e6
"""The hydroelastic modulus E (Pa) used when the user gives none: p = E e, so it sets
the scale of every pressure. 1 MPa is a typical hydroelastic modulus of a soft silicone
skin (of the order of its Young's modulus); set your own with `--modulus` or a
material.json (e.g. from `hydrotact fit`). Exported as `hydrotact.field.DEFAULT_MODULUS`."""

DEFAULT_DATASET_MODULUS = 1e7
"""The hydroelastic modulus (Pa) of `hydrotact generate` without a material, chosen for
the barometric estimation paper's data-collection regime (0-8 N) on the built-in curved
sensors: at 10 MPa a 3 mm sphere reaches 8 N at about its own radius, 3.1-3.2 mm along
the inward normal (measured at six points of sphere8 up to 45 deg from its top: 6.9-7.4 N
at 3 mm, 12.8-13.8 N at 4 mm), as Hertz's law gives for a 3 mm sphere pressed 3 mm into
a Shore-20A-class silicone (E about 0.5 MPa, nearly incompressible: 8.0 N). At 3 MPa it
took 5.8 mm, the ball sunk to twice its radius, which no gantry regime does. A bonded
silicone layer is stiffer in the hydroelastic sense than its Young's modulus. Each
manifest reports the channels' swing next to the published 3-9 kPa. A fitted
material.json replaces it."""

DEFAULT_POISSON_RATIO = 0.49
"""Poisson's ratio nu of the elastomer, for barometers that read its stress (receptive
field `elastic`): cast silicones (Ecoflex, Dragon Skin, Sylgard 184) are nearly
incompressible, and 0.45-0.499 is what their datasheets and the tactile-sensing
literature use; 0.49 sits in that range. A sensor file sets its own
(`"elastomer": {"poisson_ratio": ...}`)."""

DEFAULT_PORT_RADIUS = 0.5e-3
"""Radius (m) of the Gaussian over which an elastic barometer averages the elastomer's
stress at its port: a BMP388's vent in its 2.0 x 2.0 mm package is about 1 mm across.
Our choice; a sensor file sets it per barometer (`receptive_field.port_radius`)."""
