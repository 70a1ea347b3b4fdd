"""Pictures: pyvista renders and matplotlib plots. Never imported by the stages."""

from ._dataset import plot_dataset as plot_dataset
from ._design import plot_design_convergence as plot_design_convergence
from ._design import plot_localisation_maps as plot_localisation_maps
from ._design import render_layouts as render_layouts
from ._estimator import plot_contact_detection as plot_contact_detection
from ._estimator import plot_error_maps as plot_error_maps
from ._fit import plot_fit as plot_fit
from ._plots import plot_log as plot_log
from ._plots import save_figure as save_figure
from ._press import plot_comparisons as plot_comparisons
from ._press import plot_press_fit as plot_press_fit
from ._render import render_contact as render_contact
from ._render import render_field as render_field
from ._render import render_mesh as render_mesh
from ._training import plot_training_curve as plot_training_curve
