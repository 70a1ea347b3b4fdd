"""Sensor-layout design: where the barometers go and how they face, by gradient of the
information their readings carry about contact location and force.

`design_layout` is the host entry (contacts, feasible starts, Adam with projection,
restarts, a designed SensorSpec); `calc_layout_information` the pure objective's core
(the Fisher information of each contact's skin position and force in a layout's
readings, differentiable in the layout) and `calc_neighbour_errors` the learned
objective's (a nearest-neighbour estimator's leave-one-out localisation error); `DesignConfig` the settings; `FeasibleRegion`
the constraints (inside the elastomer or on the board, spacing, unit axes within a tilt).
"""

from ._contacts import DesignContacts as DesignContacts
from ._contacts import linearise_contacts as linearise_contacts
from ._design import DesignConfig as DesignConfig
from ._design import LayoutDesign as LayoutDesign
from ._design import LayoutScore as LayoutScore
from ._design import design_layout as design_layout
from ._design import draw_design_contacts as draw_design_contacts
from ._design import make_noise_model as make_noise_model
from ._feasible import FeasibleRegion as FeasibleRegion
from ._feasible import Placement as Placement
from ._feasible import calc_closest_points as calc_closest_points
from ._feasible import make_feasible_region as make_feasible_region
from ._objective import DesignObjective as DesignObjective
from ._objective import LayoutInformation as LayoutInformation
from ._objective import LayoutReadings as LayoutReadings
from ._objective import NoiseModel as NoiseModel
from ._objective import calc_design_score as calc_design_score
from ._objective import calc_layout_information as calc_layout_information
from ._objective import calc_layout_readings as calc_layout_readings
from ._objective import calc_localisation_bounds as calc_localisation_bounds
from ._objective import calc_neighbour_errors as calc_neighbour_errors
from ._objective import calc_neighbour_features as calc_neighbour_features
from ._objective import calc_neighbour_score as calc_neighbour_score
from ._objective import calc_neighbour_targets as calc_neighbour_targets
from ._objective import calc_prior_precision as calc_prior_precision
