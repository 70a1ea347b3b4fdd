"""Pictures: pyvista renders and matplotlib plots. Never imported by the stages."""

from ._dataset import plot_dataset as plot_dataset
from ._design import plot_design_convergence as plot_design_convergence, plot_localisation_maps as plot_localisation_maps, render_layouts as render_layouts
from ._estimator import plot_contact_detection as plot_contact_detection, plot_error_maps as plot_error_maps
from ._fit import plot_fit as plot_fit
from ._plots import plot_log as plot_log, save_figure as save_figure
from ._press import plot_comparisons as plot_comparisons, plot_press_fit as plot_press_fit
from ._render import render_contact as render_contact, render_field as render_field, render_mesh as render_mesh
from ._training import plot_training_curve as plot_training_curve
