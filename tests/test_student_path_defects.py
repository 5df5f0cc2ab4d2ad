"""Issue 11's model-side defects, headless: what a worksheet task or a readout promises holds."""

from __future__ import annotations

import numpy as np
import pytest

from lab_modules.exercises import get
from lab_modules.parameters import ParameterError


# -- defect 11: maglev_tuning's still segment follows the recording --------------------------------
def test_still_segment_range_follows_the_recording():
    from lab_modules.exercises.maglev_tuning import recording
    exercise = get("maglev_tuning")
    values = exercise.resolve({})
    ranges = exercise.parameter_ranges(values)
    rec = recording(values)
    assert ranges["still_start_s"] == ranges["still_end_s"] == (rec.time_s[0], rec.time_s[-1])
    assert ranges["still_end_s"][1] < 10.0 < exercise.parameters[0].maximum      # 6 s, not 3600 s
    with pytest.raises(ParameterError, match=r"inside the recording's 0 \.\.\. 5\.999 s") as error:
        exercise.analyse(exercise.resolve({"still_start_s": 36.0, "still_end_s": 40.0}))
    assert "\n" not in str(error.value)
