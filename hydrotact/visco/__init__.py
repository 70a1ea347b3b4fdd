"""Viscoelasticity (Prony series, hereditary integral) and the barometer signal model."""

from ._prony import (
    Prony as Prony,
    calc_contact_response as calc_contact_response,
    calc_hereditary_integral as calc_hereditary_integral,
    calc_kernel_responses_and_derivatives as calc_kernel_responses_and_derivatives,
    make_prony as make_prony,
)
from ._signal import (
    BarometerSignal as BarometerSignal,
    calc_barometer_readings as calc_barometer_readings,
    calc_resampled as calc_resampled,
    calc_sample_times as calc_sample_times,
    make_barometer_signal as make_barometer_signal,
)
