"""OpenSim storage files (cmbs.opensim_files): the header OpenSim's Storage reader needs, exact
round trip, reading OpenSim's own output, and refusals that leave no file behind."""

from __future__ import annotations

import numpy as np
import pytest

from cmbs import opensim_files
from cmbs.errors import CmbsError
from cmbs.opensim_files import read_storage, write_storage

# The head of an OpenSim 3.x/4 tool output (opensim-models, Gait10dof18musc CMC
# walk_subject_Kinematics_q.sto, first two rows and four columns): name line, counts, a blank
# line and free-text notes before endheader, space-padded numbers.
OPENSIM_OUTPUT = """Coordinates
version=1
nRows=2
nColumns=4
inDegrees=yes

Units are S.I. units (second, meters, Newtons, ...)
Angles are in degrees.

endheader
time\tpelvis_tilt\tpelvis_tx\tknee_angle_r
      0.63000000\t      7.67464299\t      0.59767522\t      0.60666763
      0.63000411\t      7.67468309\t      0.59767558\t      0.60590442
"""


def awkward_values(rows=7, columns=3, seed=4):
    """Values over many magnitudes and signs, the kind a decimal format would round."""
    rng = np.random.default_rng(seed)
    return rng.standard_normal((rows, columns)) * 10.0 ** rng.integers(-12, 12, (rows, columns))


def test_round_trip_of_a_dict_is_exact_with_the_opensim_header(tmp_path):
    times = np.linspace(0.0, 0.06, 7) + 1e-3 / 3
    values = awkward_values()
    path = write_storage(tmp_path / "motion.mot", times, {"pelvis_tilt": values[:, 0], "hip_flexion_r": values[:, 1],
                                                          "knee_angle_r": values[:, 2]}, in_degrees=True,
                         name="Coordinates")
    assert path == tmp_path / "motion.mot"
    assert path.read_text().splitlines()[:7] == [
        "Coordinates", "version=1", "nRows=7", "nColumns=4", "inDegrees=yes", "endheader",
        "time\tpelvis_tilt\thip_flexion_r\tknee_angle_r"]
    labels, data, header = read_storage(path)
    assert labels == ["time", "pelvis_tilt", "hip_flexion_r", "knee_angle_r"]
    assert np.array_equal(data[:, 0], times) and np.array_equal(data[:, 1:], values)  # shortest repr: exact
    assert header == {"name": "Coordinates", "version": "1", "nRows": "7", "nColumns": "4", "inDegrees": "yes"}
    assert [p.name for p in tmp_path.iterdir()] == ["motion.mot"]


def test_pair_form_in_radians_as_sto(tmp_path):
    values = awkward_values(rows=3, columns=2)
    path = write_storage(tmp_path / "id.STO", [0.0, 0.5, 1.0], (("a_moment", "b_force"), values), in_degrees=False,
                         name="Inverse Dynamics Generalized Forces")
    labels, data, header = read_storage(path)
    assert labels == ["time", "a_moment", "b_force"] and np.array_equal(data[:, 1:], values)
    assert header["inDegrees"] == "no" and header["name"] == "Inverse Dynamics Generalized Forces"
    assert header["nRows"] == "3" and header["nColumns"] == "3"


def test_reads_opensim_tool_output(tmp_path):
    labels, data, header = _read_text(tmp_path, OPENSIM_OUTPUT)
    assert labels == ["time", "pelvis_tilt", "pelvis_tx", "knee_angle_r"]
    assert header == {"name": "Coordinates", "version": "1", "nRows": "2", "nColumns": "4", "inDegrees": "yes"}
    assert data.shape == (2, 4) and data[1, 0] == 0.63000411 and data[0, 3] == 0.60666763


def _read_text(folder, text):
    path = folder / "file.sto"
    path.write_text(text)
    return read_storage(path)


@pytest.mark.parametrize("name, times, columns, options, message", [
    ("x.txt", [0.0], {"a": [1.0]}, {}, r"must end in \.sto or \.mot"),
    ("missing/x.mot", [0.0], {"a": [1.0]}, {}, "does not exist"),
    ("x.mot", [0.0, 1.0], {"a": [1.0, np.nan]}, {}, "non-finite values in column 'a'"),
    ("x.mot", [0.0, 1.0], {"a": [1.0, 2.0], "b": [1.0]}, {}, r"1-D arrays of one length.*b \(1,\)"),
    ("x.mot", [0.0, 1.0, 2.0], {"a": [1.0, 2.0]}, {}, "2 rows of values for 3 times"),
    ("x.mot", [0.0, 1.0], (("a",), np.zeros((2, 2))), {}, r"shape \(2, 2\) for 1 labels"),
    ("x.mot", [0.0, 1.0], {"knee angle": [1.0, 2.0]}, {}, "'knee angle' must be a non-empty string without whitespace"),
    ("x.mot", [0.0, 1.0], {"time": [1.0, 2.0]}, {}, "other than 'time'"),
    ("x.mot", [0.0, 1.0], (("a", "a"), np.zeros((2, 2))), {}, "repeated column labels: a"),
    ("x.mot", [0.0, 1.0], {}, {}, "no columns"),
    ("x.mot", [0.0, 0.0], {"a": [1.0, 2.0]}, {}, "finite and strictly increasing"),
    ("x.mot", [], {"a": []}, {}, "at least one row"),
    ("x.mot", [0.0], {"a": [1.0]}, {"name": "two\nlines"}, "one non-empty line"),
    ("x.mot", [0.0], {"a": [1.0]}, {"name": "nRows of data"}, "header key 'nRows'"),
    ("x.mot", [0.0], {"a": [1.0]}, {"in_degrees": "yes"}, "in_degrees must be True or False"),
])
def test_refusals_write_nothing(tmp_path, name, times, columns, options, message):
    keywords = {"in_degrees": True, "name": "Coordinates", **options}
    with pytest.raises(CmbsError, match=message):
        write_storage(tmp_path / name, times, columns, **keywords)
    assert list(tmp_path.iterdir()) == []


def test_failed_write_keeps_the_old_file(monkeypatch, tmp_path):
    path = tmp_path / "motion.mot"
    path.write_text("an earlier file")
    calls = []

    def failing_repr(value):
        calls.append(value)
        if len(calls) == 5:
            raise OSError("No space left on device")
        return repr(value)

    monkeypatch.setattr(opensim_files, "repr", failing_repr, raising=False)
    with pytest.raises(CmbsError, match="writing the OpenSim storage file failed.*No space left"):
        write_storage(path, np.arange(4.0), {"a": np.arange(4.0)}, in_degrees=False, name="Coordinates")
    assert len(calls) == 5  # it failed half-way through the rows
    assert [p.name for p in tmp_path.iterdir()] == ["motion.mot"] and path.read_text() == "an earlier file"


@pytest.mark.parametrize("text, message", [
    ("Coordinates\nnRows=1\ntime\ta\n0\t1\n", "no 'endheader'"),
    ("Coordinates\nendheader\na\tb\n0\t1\n", "starting with 'time'"),
    ("Coordinates\nendheader\ntime\ta\n0\t1\n0.1\n", "line 5 has 1 values for 2 columns"),
    ("Coordinates\nendheader\ntime\ta\n0\tx\n", "line 4 is not a row of numbers"),
    ("Coordinates\nnRows=3\nendheader\ntime\ta\n0\t1\n", "nRows=3 but the file has 1"),
    ("Coordinates\nnColumns=3\nendheader\ntime\ta\n0\t1\n", "nColumns=3 but the file has 2"),
])
def test_malformed_files_are_refused(tmp_path, text, message):
    with pytest.raises(CmbsError, match=message):
        _read_text(tmp_path, text)


def test_missing_file(tmp_path):
    with pytest.raises(CmbsError, match="no such file"):
        read_storage(tmp_path / "nothing.sto")
