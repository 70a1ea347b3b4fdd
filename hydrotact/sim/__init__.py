"""The forward model: sensor layout + material + probe trajectory -> what each
barometer reports, the contact wrench and the contact labels.

`calc_simulation` is the one pure function (jit, vmap over trajectories, grad with
respect to poses, material, layout and barometer); `simulate` its host entry (chunks,
buffer growth, progress, cache, resumable runs); `simulate_log` the same as a
`hydrotact.data.BarometerLog`, without files.
"""

from ._host import (
    BLOCK as BLOCK,
)
from ._host import (
    calc_responses_key as calc_responses_key,
)
from ._host import (
    compute_pose_responses as compute_pose_responses,
)
from ._host import (
    compute_trajectory_responses as compute_trajectory_responses,
)
from ._host import (
    compute_unit_responses as compute_unit_responses,
)
from ._host import (
    simulate as simulate,
)
from ._log import (
    BarometerSettings as BarometerSettings,
)
from ._log import (
    make_barometer_log as make_barometer_log,
)
from ._log import (
    material_metadata as material_metadata,
)
from ._log import (
    simulate_log as simulate_log,
)
from ._model import SensorModel as SensorModel
from ._model import make_sensor_model as make_sensor_model
from ._reach import check_reach as check_reach
from ._simulate import (
    CONTACT_THRESHOLD_N as CONTACT_THRESHOLD_N,
)
from ._simulate import (
    Samples as Samples,
)
from ._simulate import (
    SimCapacity as SimCapacity,
)
from ._simulate import (
    UnitResponse as UnitResponse,
)
from ._simulate import (
    calc_contact_angles as calc_contact_angles,
)
from ._simulate import (
    calc_samples as calc_samples,
)
from ._simulate import (
    calc_simulation as calc_simulation,
)
from ._simulate import (
    calc_unit_response as calc_unit_response,
)
from ._stage import FINGERTIP_SENSOR as FINGERTIP_SENSOR
from ._stage import StageSession as StageSession
from ._stage import find_contact_heights as find_contact_heights
from ._stage import make_site_grid as make_site_grid
from ._stage import simulate_stage_log as simulate_stage_log
from ._trajectory import (
    Trajectory as Trajectory,
)
from ._trajectory import (
    find_distinct_poses as find_distinct_poses,
)
from ._trajectory import (
    make_trajectory as make_trajectory,
)
from ._trajectory import (
    read_trajectory as read_trajectory,
)
from ._trajectory import (
    resample_trajectory as resample_trajectory,
)
