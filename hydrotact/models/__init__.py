"""Contact estimators small enough for the sensor's microcontroller (no Flax): a
two-layer GRU with binned angle heads, and the barometric estimation paper's RNN and
MLP baselines, binned and plain. Parameters are plain pytrees; each cell is a pure
single-step function driven by `lax.scan`."""

from ._bins import BIN_WIDTH as BIN_WIDTH, AngleBins as AngleBins, calc_bin_index as calc_bin_index, decode_bins as decode_bins, make_angle_bins as make_angle_bins
from ._cells import calc_gru_step as calc_gru_step, calc_linear as calc_linear, calc_rnn_step as calc_rnn_step
from ._estimator import (
    ARCHITECTURES as ARCHITECTURES,
    DEFAULT_HIDDEN as DEFAULT_HIDDEN,
    LABEL_COLUMNS as LABEL_COLUMNS,
    PARAMETER_BUDGET as PARAMETER_BUDGET,
    REGRESSION_TARGETS as REGRESSION_TARGETS,
    EstimatorSpec as EstimatorSpec,
    calc_estimator_sequence as calc_estimator_sequence,
    calc_estimator_step as calc_estimator_step,
    calc_target_scaling as calc_target_scaling,
    check_budget as check_budget,
    count_macs as count_macs,
    count_parameters as count_parameters,
    decode_estimator_outputs as decode_estimator_outputs,
    init_estimator as init_estimator,
    label_column as label_column,
    make_estimator_spec as make_estimator_spec,
    make_initial_state as make_initial_state,
)
from ._evaluate import (
    CONTACT_FORCE as CONTACT_FORCE,
    StreamingEstimator as StreamingEstimator,
    calc_detection as calc_detection,
    calc_error_map as calc_error_map,
    calc_skin_radius as calc_skin_radius,
    evaluate_estimator as evaluate_estimator,
    predict_recording as predict_recording,
)
from ._export import export_c_header as export_c_header
from ._loss import DEFAULT_WEIGHTS as DEFAULT_WEIGHTS, calc_arc_length as calc_arc_length, calc_loss as calc_loss, calc_loss_terms as calc_loss_terms, calc_table_metrics as calc_table_metrics
from ._saved import load_estimator as load_estimator, save_estimator as save_estimator
from ._sequences import Normaliser as Normaliser, make_sequences as make_sequences, target_labels as target_labels
from ._train import (
    SCHEDULES as SCHEDULES,
    TrainConfig as TrainConfig,
    TrainedEstimator as TrainedEstimator,
    fine_tune_estimator as fine_tune_estimator,
    join_recordings as join_recordings,
    train_estimator as train_estimator,
)
