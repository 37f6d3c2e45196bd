"""Result files: .npz and .csv round trips, atomic writes, refusal of bad data."""

import numpy as np
import pytest

from cmbs.errors import CmbsError
from cmbs.trajectory import Trajectory


def sample(extras=True):
    rng = np.random.default_rng(0)
    t = np.linspace(0, 1, 6)
    q, qd, qdd = rng.normal(size=(3, 6, 2))
    more = {"energy": rng.normal(size=6), "lam": rng.normal(size=(6, 3))} if extras else {}
    return Trajectory(t, q, qd, qdd, ("a.x", "phi"), more, {"model": "m", "dt": 0.2})


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_round_trip(tmp_path, suffix):
    original = sample()
    path = original.save(tmp_path / f"run{suffix}")
    loaded = Trajectory.load(path)
    assert loaded.names == original.names
    assert loaded.info == original.info
    for label in ("t", "q", "qd", "qdd"):
        np.testing.assert_array_equal(getattr(loaded, label), getattr(original, label))
    for label in ("energy", "lam"):
        np.testing.assert_array_equal(loaded.extras[label], original.extras[label])
    np.testing.assert_array_equal(loaded["phi"], original.q[:, 1])
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_npz_layout_is_time_major(tmp_path):
    path = sample().save(tmp_path / "run.npz")
    with np.load(path) as data:
        assert data["q"].shape == (6, 2) and data["lam"].shape == (6, 3)
        assert list(data["names"]) == ["a.x", "phi"]


def test_refuses_bad_extension_missing_directory_and_nan(tmp_path):
    with pytest.raises(CmbsError, match="must end in .npz or .csv"):
        sample().save(tmp_path / "run.txt")
    with pytest.raises(CmbsError, match="does not exist"):
        sample().save(tmp_path / "missing" / "run.npz")
    bad = sample()
    bad.q[2, 1] = np.nan
    with pytest.raises(CmbsError, match="non-finite values in 'q'"):
        bad.save(tmp_path / "run.npz")
    assert list(tmp_path.iterdir()) == []


def test_existing_file_is_replaced_only_by_a_complete_write(tmp_path):
    path = tmp_path / "run.csv"
    sample().save(path)
    before = path.read_text()
    bad = sample()
    bad.extras["energy"][0] = np.inf
    with pytest.raises(CmbsError):
        bad.save(path)
    assert path.read_text() == before


def test_load_errors(tmp_path):
    with pytest.raises(CmbsError, match="no such file"):
        Trajectory.load(tmp_path / "none.npz")
    junk = tmp_path / "junk.csv"
    junk.write_text("hello\nworld, x\n")
    with pytest.raises(CmbsError, match="not a cmbs result file"):
        Trajectory.load(junk)


def test_access_by_name():
    trajectory = sample()
    np.testing.assert_array_equal(trajectory.velocity("a.x"), trajectory.qd[:, 0])
    with pytest.raises(KeyError, match="no coordinate or array 'nope'; coordinates: .*; arrays: "):
        trajectory["nope"]
    with pytest.raises(KeyError, match=r"no coordinate or array 'a\.xx' \(did you mean 'a\.x'\?\)"):
        trajectory["a.xx"]


def test_written_files_get_the_usual_permissions(tmp_path):
    import os

    umask = os.umask(0o022)
    try:
        path = sample().save(tmp_path / "run.npz")
    finally:
        os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o644
