"""OpenSim storage files (``.sto``, ``.mot``): tables of numbers against time, written atomically.

Both suffixes share one text format, the one OpenSim's ``Storage`` class reads (and its tools,
e.g. inverse kinematics, write)::

    Coordinates                 <- the table's name (first line, free text)
    version=1
    nRows=114                   <- data rows
    nColumns=16                 <- columns, time included
    inDegrees=yes               <- rotational columns in degrees (yes) or radians (no)
    endheader
    time<TAB>pelvis_tilt<TAB>...
    0<TAB>-2.8<TAB>...          <- one line per time, values separated by tabs

With ``version=1`` and ``nRows``/``nColumns`` OpenSim 4 reads the file with the legacy Storage
parser (opensim-core ``Storage::Storage(fileName)``: files of version ≤ 1 need both counts;
``Storage::parseHeaders`` takes the first line as the name and ``key=value`` lines up to
``endheader``; the labels are split at tabs, the data read as whitespace-separated numbers), the
format of OpenSim's own IK output (``Pipelines/Rajagopal/outputReference/ResultsIK/*.mot`` in
opensim-models).  Values are written with Python's shortest round-trip representation
(``repr(float)``): reading the file back gives the same doubles.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from cmbs.errors import CmbsError
from cmbs.files_io import atomic_path, checked_output

SUFFIXES = (".sto", ".mot")
#: Header keys of Storage::parseHeaders: a name starting with one of them would be read as that key.
_HEADER_KEYS = ("name", "nr", "nRows", "datarows", "nc", "nColumns", "datacolumns", "units", "version",
                "inDegrees", "Angles", "endheader", "#", "range", "Range", "wrap", "Wrap", "WRAP", "event",
                "enforce_loops", "enforce_constraints", "calc_derivatives")


def write_storage(path: str | os.PathLike, times: np.ndarray,
                  columns: dict[str, np.ndarray] | tuple[list[str] | tuple[str, ...], np.ndarray], *,
                  in_degrees: bool, name: str) -> Path:
    """Write ``columns`` against ``times`` as an OpenSim storage file (format in the module
    docstring); returns the path.

    ``columns`` is either ``{label: (k,) values}`` or ``(labels, (k, C) array)``; ``times`` (k,)
    strictly increasing.  ``in_degrees`` only sets the header flag (OpenSim converts the
    rotational columns it recognises to radians when it is ``yes``): the values are written as
    given.

    Raises
    ------
    CmbsError
        Suffix not ``.sto``/``.mot``, missing folder, no rows, times not finite and strictly
        increasing, a column of another length, a non-finite value (the label is named), a
        label that is empty, contains whitespace, is ``time`` or repeats, a name that is not a
        single line or reads as a header key, or a failed write.  Nothing is written then.
    """
    path = checked_output(path, SUFFIXES, "OpenSim storage file")
    labels, table = _table(path, columns)
    _check_labels(path, labels)
    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or times.size == 0:
        raise CmbsError(f"{path}: times must be a 1-D array with at least one row, got shape {times.shape}")
    if not (np.all(np.isfinite(times)) and np.all(np.diff(times) > 0)):
        raise CmbsError(f"{path}: times must be finite and strictly increasing")
    if table.shape[0] != times.size:
        raise CmbsError(f"{path}: {table.shape[0]} rows of values for {times.size} times")
    for label, column in zip(labels, table.T):
        if not np.all(np.isfinite(column)):
            raise CmbsError(f"{path}: refusing to write non-finite values in column {label!r}")
    _check_name(path, name)
    if not isinstance(in_degrees, bool):
        raise CmbsError(f"{path}: in_degrees must be True or False, got {in_degrees!r}")
    header = [name, "version=1", f"nRows={times.size}", f"nColumns={len(labels) + 1}",
              f"inDegrees={'yes' if in_degrees else 'no'}", "endheader", "\t".join(("time", *labels))]
    rows = ("\t".join(repr(float(value)) for value in row) for row in np.column_stack([times, table]))
    try:
        with atomic_path(path) as temporary, open(temporary, "w", encoding="utf-8", newline="\n") as stream:
            stream.write("\n".join(header) + "\n")
            for row in rows:
                stream.write(row + "\n")
    except OSError as error:
        raise CmbsError(f"{path}: writing the OpenSim storage file failed ({error})") from None
    return path


def read_storage(path: str | os.PathLike) -> tuple[list[str], np.ndarray, dict[str, str]]:
    """Read an OpenSim storage file: ``(labels, data, header)``.

    ``labels`` are the column labels, ``"time"`` first; ``data`` (rows, columns) holds the
    numbers as stored (time in column 0, angles in the unit ``header["inDegrees"]`` says);
    ``header`` maps each ``key=value`` line before ``endheader`` to its value (strings) and
    ``"name"`` to the first line when that is not a ``key=value`` line.  Other header lines
    (free-text notes) and blank lines are skipped, as OpenSim does.

    Raises
    ------
    CmbsError
        Missing file, no ``endheader``, no ``time`` column, a row of another length or not
        numbers (its line number is named), or row/column counts that differ from ``nRows``/
        ``nColumns`` in the header.
    """
    path = Path(path)
    if not path.is_file():
        raise CmbsError(f"{path}: no such file")
    lines = path.read_text(encoding="utf-8").splitlines()
    header: dict[str, str] = {}
    end = None
    for number, line in enumerate(lines):
        text = line.strip()
        if text == "endheader":
            end = number
            break
        key, equals, value = text.partition("=")
        if equals and key.strip():
            header[key.strip()] = value.strip()
        elif number == 0 and text:
            header["name"] = text
    if end is None:
        raise CmbsError(f"{path}: not an OpenSim storage file (no 'endheader' line)")
    body = [(number + 1, line) for number, line in enumerate(lines[end + 1:], start=end + 1) if line.strip()]
    if not body or body[0][1].split("\t")[0].strip() != "time":
        raise CmbsError(f"{path}: the line after 'endheader' must be the column labels, starting with 'time'")
    labels = [label.strip() for label in body[0][1].rstrip("\r\n").split("\t")]
    rows = []
    for number, line in body[1:]:
        fields = line.split()
        if len(fields) != len(labels):
            raise CmbsError(f"{path}: line {number} has {len(fields)} values for {len(labels)} columns")
        try:
            rows.append([float(field) for field in fields])
        except ValueError:
            raise CmbsError(f"{path}: line {number} is not a row of numbers") from None
    data = np.array(rows, dtype=float).reshape(len(rows), len(labels))
    for key, count in (("nRows", data.shape[0]), ("nColumns", data.shape[1])):
        if key in header and header[key] != str(count):
            raise CmbsError(f"{path}: header says {key}={header[key]} but the file has {count}")
    return labels, data, header


def _table(path: Path, columns) -> tuple[list[str], np.ndarray]:
    """(labels, (k, C) float array) from either accepted form of ``columns``."""
    if isinstance(columns, dict):
        labels = list(columns)
        arrays = [np.asarray(columns[label], dtype=float) for label in labels]
        lengths = {array.shape for array in arrays}
        if any(array.ndim != 1 for array in arrays) or len(lengths) > 1:
            raise CmbsError(f"{path}: columns must all be 1-D arrays of one length, got shapes "
                            + ", ".join(f"{label} {array.shape}" for label, array in zip(labels, arrays)))
        return labels, (np.column_stack(arrays) if arrays else np.zeros((0, 0)))
    if not (isinstance(columns, tuple) and len(columns) == 2):
        raise CmbsError(f"{path}: columns must be a dict {{label: values}} or a pair (labels, 2-D array)")
    labels, table = list(columns[0]), np.asarray(columns[1], dtype=float)
    if table.ndim != 2 or table.shape[1] != len(labels):
        raise CmbsError(f"{path}: values of shape {table.shape} for {len(labels)} labels "
                        f"(expected (rows, {len(labels)}))")
    return labels, table


def _check_labels(path: Path, labels: list[str]) -> None:
    if not labels:
        raise CmbsError(f"{path}: no columns to write")
    for label in labels:
        if not isinstance(label, str) or not label or any(c.isspace() for c in label) or label == "time":
            raise CmbsError(f"{path}: column label {label!r} must be a non-empty string without whitespace, "
                            "other than 'time'")
    repeated = sorted({label for label in labels if labels.count(label) > 1})
    if repeated:
        raise CmbsError(f"{path}: repeated column labels: {', '.join(repeated)}")


def _check_name(path: Path, name: str) -> None:
    if not isinstance(name, str) or not name.strip() or "\n" in name or "\r" in name or "=" in name:
        raise CmbsError(f"{path}: the table name must be one non-empty line without '=', got {name!r}")
    first_word = name.strip().replace("\t", " ").split(" ")[0]
    if first_word in _HEADER_KEYS:
        raise CmbsError(f"{path}: the table name {name!r} would be read as the header key {first_word!r}")
