"""hydrotact: differentiable simulation and system identification for barometric
tactile sensors (MEMS barometers cast in silicone), in JAX.

Stages, one sub-package each, in pipeline order:

- `hydrotact.mesh`: tet meshes of the elastomer (built-in sensors, surface files).
- `hydrotact.field`: the strain field (Laplace or Drake's distance) and pressure field.
- `hydrotact.contact`: hydroelastic contact surfaces and wrenches; the probes.
- `hydrotact.taxel`: what each barometer's receptive field reads of a contact.
- `hydrotact.sensors`: sensor specs (geometry, barometer part, taxel layout).
- `hydrotact.visco`: Prony materials, the hereditary integral, the barometer signal.
- `hydrotact.sim`: the one forward model, `calc_simulation`, and its host entry
  `simulate`; `simulate_log` for a log without files.
- `hydrotact.data`: barometer logs (Parquet, CSV, column mappings), tare, materials.
- `hydrotact.sysid`: fitting materials, gains and offsets to logs, with uncertainties.
- `hydrotact.datasets`: synthetic training datasets (the contact-estimation
  data-collection regime), sharded, resumable, on every local device or on Ray.

`hydrotact.viz` draws (renders and plots) and `hydrotact.cli` is the `hydrotact`
command; no stage imports either. Units are SI throughout (m, Pa, N, s, rad).
"""

from ._errors import HydrotactError as HydrotactError, HydrotactWarning as HydrotactWarning
from ._malloc import keep_freed_memory

keep_freed_memory()  # XLA's per-call working memory reused warm (see _malloc.py; HYDROTACT_MALLOC=system to opt out)

__version__ = "0.1.0"
