"""Viscoelasticity (Prony series, hereditary integral) and the barometer signal model."""

from ._prony import (
    Prony as Prony,
)
from ._prony import (
    calc_contact_response as calc_contact_response,
)
from ._prony import (
    calc_hereditary_integral as calc_hereditary_integral,
)
from ._prony import (
    calc_kernel_responses_and_derivatives as calc_kernel_responses_and_derivatives,
)
from ._prony import (
    make_prony as make_prony,
)
from ._signal import (
    BarometerSignal as BarometerSignal,
)
from ._signal import (
    calc_barometer_readings as calc_barometer_readings,
)
from ._signal import (
    calc_resampled as calc_resampled,
)
from ._signal import (
    calc_sample_times as calc_sample_times,
)
from ._signal import (
    make_barometer_signal as make_barometer_signal,
)
