"""Recordings of the maglev ball as CSV files (paper 004 §3.4-3.5).

The paper tuned its filter offline on 25 s recorded from the hardware under
a lead-lag controller (Fig. 3.23, 3.25).  A recording here is a CSV text
file with a header line and one row per sample::

    # lines starting with '#' are comments; "# key = value" lines are metadata
    time_s,reference_mm,measured_position_mm,coil_voltage_v
    0.000,14.8000,14.80213,22.354

Time must increase strictly at an even pace (every interval within
``SAMPLING_TOLERANCE`` of the median: no gaps); every field must be a finite
number inside the rig's physical range (``RANGES``).  A bad file raises
``ParameterError`` with one line naming the line and column.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field

import numpy as np

from lab_modules.parameters import ParameterError

COLUMNS = ("time_s", "reference_mm", "measured_position_mm", "coil_voltage_v")
#: Upper size of an accepted file: 1 h at 1 kHz is about 130 MB, far beyond a
#: browser upload; 20 MB holds about 10 minutes at 1 kHz.
MAX_BYTES = 20_000_000
MIN_ROWS = 10
#: Physical ranges of the columns (not in the paper; chosen to be generous but physical):
#: the gap sensor spans the ball's travel, 0 ... 30 mm (the loop's touchdown limit is
#: 30 mm, twice the operating gap of §3.3); the coil voltage stays within ±100 V
#: (the equilibrium needs 22 V at R_c = 25 ohm; 100 V drives 4 A, twice eq. 2.14's
#: largest current); time within one day.
RANGES = {"time_s": (-86_400.0, 86_400.0), "reference_mm": (0.0, 30.0),
          "measured_position_mm": (0.0, 30.0), "coil_voltage_v": (-100.0, 100.0)}
#: Largest relative deviation of one sampling interval from the median interval.
SAMPLING_TOLERANCE = 0.5


@dataclass(frozen=True)
class Recording:
    """One run: sample times [s], reference and measured gap [m], coil voltage [V]."""

    time_s: np.ndarray
    reference_m: np.ndarray
    measured_m: np.ndarray
    coil_voltage_v: np.ndarray
    metadata: dict[str, str] = field(default_factory=dict)
    name: str = ""

    def __len__(self) -> int:
        return self.time_s.size

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0])

    def window(self, start_s: float, end_s: float) -> np.ndarray:
        """Boolean mask of the samples with start_s <= t < end_s."""
        return (self.time_s >= start_s) & (self.time_s < end_s)


def to_csv(recording: Recording) -> str:
    """The recording as CSV text (metadata first, positions in mm)."""
    lines = [f"# {key} = {value}" for key, value in recording.metadata.items()]
    lines.append(",".join(COLUMNS))
    for t, r, y, u in zip(recording.time_s, recording.reference_m, recording.measured_m,
                          recording.coil_voltage_v, strict=True):
        lines.append(f"{t:.3f},{r * 1e3:.4f},{y * 1e3:.5f},{u:.3f}")
    return "\n".join(lines) + "\n"


#: Field separators of other CSV dialects, named in the refusal of a header that uses one
OTHER_SEPARATORS = {";": "semicolons (';', as a spreadsheet set to decimal commas writes CSV)", "\t": "tabs"}


def other_separator(header_line: str) -> str | None:
    """The name of the separator a header line uses instead of commas, if its fields are the
    recording's columns that way (e.g. ``time_s;reference_mm;…``)."""
    for separator, name in OTHER_SEPARATORS.items():
        if all(column in [f.strip() for f in header_line.split(separator)] for column in COLUMNS):
            return name
    return None


def parse(filename: str, content: bytes, min_rows: int = MIN_ROWS) -> Recording:
    """Read and validate a recording (at least ``min_rows`` samples); any problem ->
    ``ParameterError`` (one line)."""
    if len(content) > MAX_BYTES:
        raise ParameterError(f"{filename}: file is larger than {MAX_BYTES / 1e6:.0f} MB, "
                             "the largest recording accepted")
    try:
        text = content.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise ParameterError(f"{filename}: not a UTF-8 text file (byte {error.start}); "
                             "expected a CSV recording") from None
    metadata: dict[str, str] = {}
    header: list[str] | None = None
    header_line = 0
    rows: list[list[float]] = []
    lines: list[int] = []                  # file line of each row
    for line_number, line in enumerate(io.StringIO(text), start=1):
        line = line.strip()
        if not line:
            continue
        if line.startswith("#"):
            key, sep, value = line[1:].partition("=")
            if sep:
                metadata[key.strip()] = value.strip()
            continue
        fields = [f.strip() for f in line.split(",")]
        if header is None:
            header, header_line = fields, line_number
            missing = [c for c in COLUMNS if c not in header]
            separator = other_separator(line)
            if missing and separator:
                raise ParameterError(
                    f"{filename}, line {line_number}: the fields are separated by {separator}, not by commas; "
                    "save it as CSV with ',' between the fields and '.' as the decimal sign")
            if missing:
                raise ParameterError(
                    f"{filename}, line {line_number}: missing column(s) {', '.join(missing)}; "
                    f"expected a header with {', '.join(COLUMNS)}")
            index = [header.index(c) for c in COLUMNS]
            continue
        if len(fields) != len(header):
            raise ParameterError(f"{filename}, line {line_number}: {len(fields)} fields, "
                                 f"expected {len(header)} as in the header (line {header_line})")
        row = []
        for column, i in zip(COLUMNS, index, strict=True):
            try:
                value = float(fields[i])
            except ValueError:
                raise ParameterError(f"{filename}, line {line_number}, column {column}: "
                                     f"{fields[i]!r} is not a number") from None
            if not math.isfinite(value):
                raise ParameterError(f"{filename}, line {line_number}, column {column}: "
                                     f"{fields[i]!r} is not a finite number")
            low, high = RANGES[column]
            if not low <= value <= high:
                raise ParameterError(f"{filename}, line {line_number}, column {column}: {fields[i]} is outside "
                                     f"the rig's range {low:g} ... {high:g}")
            row.append(value)
        if rows and not row[0] > rows[-1][0]:
            raise ParameterError(f"{filename}, line {line_number}, column time_s: time {row[0]:g} s "
                                 f"does not increase (previous sample {rows[-1][0]:g} s)")
        rows.append(row)
        lines.append(line_number)
    if header is None:
        raise ParameterError(f"{filename}: no header line; expected columns {', '.join(COLUMNS)}")
    if len(rows) < min_rows:
        where = f", line {lines[-1]}" if lines else ""
        raise ParameterError(f"{filename}{where}: the file ends after {len(rows)} data rows; "
                             f"at least {min_rows} are needed")
    data = np.array(rows)
    intervals = np.diff(data[:, 0])
    median = float(np.median(intervals))
    uneven = np.flatnonzero(np.abs(intervals - median) > SAMPLING_TOLERANCE * median)
    if uneven.size:
        k = int(uneven[0]) + 1
        raise ParameterError(f"{filename}, line {lines[k]}, column time_s: the interval "
                             f"{intervals[k - 1]:.6g} s to the previous sample differs from the recording's "
                             f"{median:.6g} s by more than {SAMPLING_TOLERANCE:.0%} (a gap or uneven sampling)")
    return Recording(time_s=data[:, 0], reference_m=data[:, 1] * 1e-3, measured_m=data[:, 2] * 1e-3,
                     coil_voltage_v=data[:, 3], metadata=metadata, name=filename)


def read(path) -> Recording:
    """Read a recording file from disk (``parse`` with the file's name)."""
    with open(path, "rb") as handle:
        content = handle.read(MAX_BYTES + 1)
    return parse(str(path).rsplit("/", 1)[-1], content)


def write(path, recording: Recording) -> None:
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(to_csv(recording))
