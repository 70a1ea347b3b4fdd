"""Synthetic datasets: the contact-estimation data-collection regime of the barometric
estimation paper (events uniform by area over the skin, low forces over-sampled, one
continuous 100 Hz session), sharded, resumable, deterministic, on every local device
or on Ray.

`generate_dataset` writes one; `load_dataset` reads it back for training. The pieces:
`DatasetConfig` (the regime), `find_touchable_skin` and `sample_events` (where, how
hard, how long), `march_presses`, `lay_out_timeline` and `run_session` (the session
through the one forward model, `hydrotact.sim.calc_samples`), `PoseEngine` (unit
responses on local devices or Ray tasks).
"""

from ._compute import PoseEngine as PoseEngine
from ._compute import compute_block as compute_block
from ._config import FORCE_DISTRIBUTIONS as FORCE_DISTRIBUTIONS
from ._config import PHASES as PHASES
from ._config import DatasetConfig as DatasetConfig
from ._events import EventPlan as EventPlan
from ._events import Skin as Skin
from ._events import calc_approach_thickness as calc_approach_thickness
from ._events import draw_target_forces as draw_target_forces
from ._events import find_touchable_skin as find_touchable_skin
from ._events import pressing_rotation_vectors as pressing_rotation_vectors
from ._events import sample_events as sample_events
from ._events import sample_skin_points as sample_skin_points
from ._generate import GENERATOR as GENERATOR
from ._generate import PUBLISHED_CHANNEL_STD_PA as PUBLISHED_CHANNEL_STD_PA
from ._generate import draw_material as draw_material
from ._generate import generate_dataset as generate_dataset
from ._session import Presses as Presses
from ._session import Timeline as Timeline
from ._session import lay_out_timeline as lay_out_timeline
from ._session import march_presses as march_presses
from ._session import run_session as run_session
from ._store import PLOTS as PLOTS
from ._store import Dataset as Dataset
from ._store import load_dataset as load_dataset
from ._store import read_manifest as read_manifest
