"""The end-to-end forward model: sensor + material + probe trajectory -> what each
barometer reads, the contact wrench and the contact labels."""

from ._model import (
    Material as Material,
    SensorModel as SensorModel,
    make_material as make_material,
    make_sensor_model as make_sensor_model,
)
from ._simulate import (
    CONTACT_THRESHOLD_N as CONTACT_THRESHOLD_N,
    Samples as Samples,
    SimCapacity as SimCapacity,
    UnitResponse as UnitResponse,
    calc_contact_angles as calc_contact_angles,
    calc_samples as calc_samples,
    calc_simulation as calc_simulation,
    calc_unit_response as calc_unit_response,
    calc_viscoelastic_samples as calc_viscoelastic_samples,
    compute_unit_responses as compute_unit_responses,
    grown_sim_capacity as grown_sim_capacity,
    scale_unit_responses as scale_unit_responses,
    simulate as simulate,
)
from ._trajectory import Trajectory as Trajectory, make_trajectory as make_trajectory, read_trajectory as read_trajectory
