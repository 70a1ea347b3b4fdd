"""Contact estimators small enough for the sensor's microcontroller (no Flax): a
two-layer GRU with binned angle heads, and the barometric estimation paper's RNN and
MLP baselines, binned and plain. Parameters are plain pytrees; each cell is a pure
single-step function driven by `lax.scan`."""

from ._bins import BIN_WIDTH as BIN_WIDTH
from ._bins import AngleBins as AngleBins
from ._bins import calc_bin_index as calc_bin_index
from ._bins import decode_bins as decode_bins
from ._bins import make_angle_bins as make_angle_bins
from ._cells import calc_gru_step as calc_gru_step
from ._cells import calc_linear as calc_linear
from ._cells import calc_rnn_step as calc_rnn_step
from ._estimator import ARCHITECTURES as ARCHITECTURES
from ._estimator import DEFAULT_HIDDEN as DEFAULT_HIDDEN
from ._estimator import PARAMETER_BUDGET as PARAMETER_BUDGET
from ._estimator import EstimatorSpec as EstimatorSpec
from ._estimator import calc_estimator_sequence as calc_estimator_sequence
from ._estimator import calc_estimator_step as calc_estimator_step
from ._estimator import check_budget as check_budget
from ._estimator import count_macs as count_macs
from ._estimator import count_parameters as count_parameters
from ._estimator import decode_estimator_outputs as decode_estimator_outputs
from ._estimator import init_estimator as init_estimator
from ._estimator import make_estimator_spec as make_estimator_spec
from ._estimator import make_initial_state as make_initial_state
from ._evaluate import CONTACT_FORCE as CONTACT_FORCE
from ._evaluate import StreamingEstimator as StreamingEstimator
from ._evaluate import calc_detection as calc_detection
from ._evaluate import calc_error_map as calc_error_map
from ._evaluate import calc_skin_radius as calc_skin_radius
from ._evaluate import evaluate_estimator as evaluate_estimator
from ._evaluate import predict_recording as predict_recording
from ._export import export_c_header as export_c_header
from ._loss import DEFAULT_WEIGHTS as DEFAULT_WEIGHTS
from ._loss import calc_arc_length as calc_arc_length
from ._loss import calc_loss as calc_loss
from ._loss import calc_loss_terms as calc_loss_terms
from ._loss import calc_table_metrics as calc_table_metrics
from ._saved import load_estimator as load_estimator
from ._saved import save_estimator as save_estimator
from ._sequences import Normaliser as Normaliser
from ._sequences import make_sequences as make_sequences
from ._train import SCHEDULES as SCHEDULES
from ._train import TrainConfig as TrainConfig
from ._train import TrainedEstimator as TrainedEstimator
from ._train import fine_tune_estimator as fine_tune_estimator
from ._train import join_recordings as join_recordings
from ._train import train_estimator as train_estimator
