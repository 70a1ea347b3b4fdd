"""The forward model: sensor layout + material + probe trajectory -> what each
barometer reports, the contact wrench and the contact labels.

`calc_simulation` is the one pure function (jit, vmap over trajectories, grad with
respect to poses, material, layout and barometer); `simulate` its host entry (chunks,
buffer growth, progress, cache, resumable runs); `simulate_log` the same as a
`hydrotact.data.BarometerLog`, without files.
"""

from ._host import (
    BLOCK as BLOCK,
    calc_responses_key as calc_responses_key,
    compute_pose_responses as compute_pose_responses,
    compute_trajectory_responses as compute_trajectory_responses,
    compute_unit_responses as compute_unit_responses,
    simulate as simulate,
)
from ._log import (
    BarometerSettings as BarometerSettings,
    make_barometer_log as make_barometer_log,
    material_metadata as material_metadata,
    simulate_log as simulate_log,
)
from ._model import (
    SensorModel as SensorModel,
    make_ray_layout as make_ray_layout,
    make_sensor_model as make_sensor_model,
    with_barometer_positions as with_barometer_positions,
)
from ._reach import check_reach as check_reach
from ._rig import RigTable as RigTable, calc_rig_inputs as calc_rig_inputs, make_rig_table as make_rig_table
from ._simulate import (
    CONTACT_THRESHOLD_N as CONTACT_THRESHOLD_N,
    Samples as Samples,
    SimCapacity as SimCapacity,
    UnitResponse as UnitResponse,
    calc_contact_angles as calc_contact_angles,
    calc_samples as calc_samples,
    calc_simulation as calc_simulation,
    calc_unit_response as calc_unit_response,
)
from ._stage import (
    FINGERTIP_SENSOR as FINGERTIP_SENSOR,
    StageSession as StageSession,
    find_contact_heights as find_contact_heights,
    make_site_grid as make_site_grid,
    simulate_stage_log as simulate_stage_log,
)
from ._trajectory import (
    Trajectory as Trajectory,
    find_distinct_poses as find_distinct_poses,
    make_trajectory as make_trajectory,
    read_trajectory as read_trajectory,
    resample_trajectory as resample_trajectory,
)
