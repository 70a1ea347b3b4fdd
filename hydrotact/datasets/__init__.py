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

from ._compute import PoseEngine as PoseEngine, compute_block as compute_block
from ._config import FORCE_DISTRIBUTIONS as FORCE_DISTRIBUTIONS, PHASES as PHASES, REGIMES as REGIMES, TARGETS as TARGETS, DatasetConfig as DatasetConfig
from ._events import (
    EventPlan as EventPlan,
    Skin as Skin,
    calc_approach_thickness as calc_approach_thickness,
    draw_hold_targets as draw_hold_targets,
    draw_target_forces as draw_target_forces,
    find_touchable_skin as find_touchable_skin,
    pressing_rotation_vectors as pressing_rotation_vectors,
    sample_events as sample_events,
    sample_skin_points as sample_skin_points,
    sample_stage_points as sample_stage_points,
)
from ._generate import GENERATOR as GENERATOR, PUBLISHED_CHANNEL_STD_PA as PUBLISHED_CHANNEL_STD_PA, draw_material as draw_material, generate_dataset as generate_dataset
from ._session import Presses as Presses, Timeline as Timeline, lay_out_timeline as lay_out_timeline, march_presses as march_presses, run_session as run_session
from ._store import PLOTS as PLOTS, Dataset as Dataset, load_dataset as load_dataset, read_manifest as read_manifest
