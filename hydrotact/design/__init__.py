"""Sensor-layout design: where the barometers go and how they face, by gradient of the
information their readings carry about contact location and force.

`design_layout` is the host entry (contacts, feasible starts, Adam with projection,
restarts, a designed SensorSpec); `calc_layout_information` the pure objective's core
(the Fisher information of each contact's skin position and force in a layout's
readings, differentiable in the layout) and `calc_neighbour_errors` the learned
objective's (a nearest-neighbour estimator's leave-one-out localisation error); `DesignConfig` the settings; `FeasibleRegion`
the constraints (inside the elastomer or on the board, spacing, unit axes within a tilt).
"""

from ._config import DesignConfig as DesignConfig, LayoutDesign as LayoutDesign, LayoutScore as LayoutScore
from ._contacts import DesignContacts as DesignContacts, linearise_contacts as linearise_contacts
from ._design import (
    design_layout as design_layout,
    draw_design_contacts as draw_design_contacts,
    make_noise_model as make_noise_model,
)
from ._feasible import FeasibleRegion as FeasibleRegion, Placement as Placement, calc_closest_points as calc_closest_points, make_feasible_region as make_feasible_region
from ._objective import (
    DesignObjective as DesignObjective,
    LayoutInformation as LayoutInformation,
    LayoutReadings as LayoutReadings,
    NoiseModel as NoiseModel,
    calc_design_score as calc_design_score,
    calc_layout_information as calc_layout_information,
    calc_layout_readings as calc_layout_readings,
    calc_localisation_bounds as calc_localisation_bounds,
    calc_neighbour_errors as calc_neighbour_errors,
    calc_neighbour_features as calc_neighbour_features,
    calc_neighbour_score as calc_neighbour_score,
    calc_neighbour_targets as calc_neighbour_targets,
    calc_prior_precision as calc_prior_precision,
)
