"""TOML model files against the builder: tests/data/kitchen-sink.toml (every entry kind) must give
the same equations as tests/helpers.py kitchen_sink(python_driver=False), and a driver table read
from a CSV file the same equations as the inline table it copies."""

import re
from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.model.files import assembled
from helpers import kitchen_sink

DATA = Path(__file__).parent / "data"
KITCHEN_SINK = DATA / "kitchen-sink.toml"
TABLE_CSV = DATA / "kitchen-sink-table.csv"
INLINE_TABLE = re.compile(r"^table = \{.*\}$", re.MULTILINE)


def random_states(model, rng, count=4):
    """(q, q̇, t, u) around the assembled configuration, t inside and beyond the table's range."""
    for t in [0.0, *rng.uniform(0.0, 3.5, count - 1)]:
        yield (model.q0 + 0.2 * rng.standard_normal(model.n), rng.standard_normal(model.n), float(t),
               rng.standard_normal(model.n_u))


def assert_same_equations(first, second, rng, *, tolerance=1e-13):
    """Names, sizes and M, Q, Φ, A, γ, Φ_t at random states agree to ``tolerance`` (relative to 1)."""
    for attribute in ("coordinate_names", "coordinate_kinds", "constraint_names", "actuator_names",
                      "point_names", "lines", "segment_masses"):
        assert getattr(first, attribute) == getattr(second, attribute), attribute
    np.testing.assert_array_equal(first.drivers, second.drivers)
    for q, qd, t, u in random_states(first, rng):
        a, b = first.evaluate(q, qd, t, u), second.evaluate(q, qd, t, u)
        for term in ("M", "Q", "phi", "A", "gamma", "phi_t"):
            np.testing.assert_allclose(getattr(a, term), getattr(b, term), rtol=tolerance, atol=tolerance,
                                       err_msg=f"{term} at t={t}")
        assert first.kinetic_energy(q, qd) == pytest.approx(second.kinetic_energy(q, qd), rel=tolerance)
        assert first.potential_energy(q) == pytest.approx(second.potential_energy(q), rel=tolerance)


def test_kitchen_sink_file_equals_builder_model():
    from_file = cmbs.load(KITCHEN_SINK)
    built = kitchen_sink(python_driver=False)
    assert from_file.name == built.name == "kitchen-sink"
    assert_same_equations(from_file, built, np.random.default_rng(7))
    # loading assembles; the builder's model assembled the same way lands on the same state
    reference = assembled(built, "builder")
    np.testing.assert_allclose(from_file.q0, reference.q0, atol=1e-12)
    np.testing.assert_allclose(from_file.qd0, reference.qd0, atol=1e-12)
    assert np.abs(from_file.constraints(from_file.q0, 0.0)).max() < 1e-10
    assert cmbs.constraint_report(from_file, from_file.q0).dof == 1


def test_kitchen_sink_file_uses_every_section():
    import tomllib

    from cmbs.model.files import _SECTIONS

    document = tomllib.loads(KITCHEN_SINK.read_text())
    # [initial_velocities] sets the start, which the builder model of tests/helpers.py does not
    # have; tests/test_file_start.py and the docs' last example cover it
    assert set(document) == set(_SECTIONS) - {"initial_velocities"}
    assert {"line", "segment", "through"} <= {key for slider in document["sliders"].values() for key in slider}


def variant(tmp_path, name, *, interpolation, csv):
    """kitchen-sink.toml with the table-drive's interpolation changed and, if ``csv``, its inline
    table replaced by ``file =`` the CSV copy of the same samples."""
    text = KITCHEN_SINK.read_text()
    assert len(INLINE_TABLE.findall(text)) == 1
    text = text.replace('interpolation = "spline"', f'interpolation = "{interpolation}"')
    if csv:
        text = INLINE_TABLE.sub(f"file = {str(TABLE_CSV)!r}", text)
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return cmbs.load(path)


@pytest.mark.parametrize("interpolation", ["spline", "linear"])
def test_csv_table_driver_equals_inline_table(tmp_path, interpolation):
    inline = variant(tmp_path, "inline", interpolation=interpolation, csv=False)
    from_csv = variant(tmp_path, "from-csv", interpolation=interpolation, csv=True)
    assert_same_equations(inline, from_csv, np.random.default_rng(3), tolerance=0.0)


def test_relative_csv_path_and_linear_interpolation(tmp_path):
    """``file`` is relative to the model file; linear interpolation has the piecewise slope and no
    second derivative (inside a piece)."""
    (tmp_path / "drive.csv").write_text("# t, x of P\nt,value\n0,1\n1,0.5\n\n2,0.5\n")
    path = tmp_path / "slide.toml"
    path.write_text("""
[points]
P = { x = 1.0, z = 0.0, mass = 1.0 }

[sliders.rail]
point = "P"
through = [0.0, 0.0]
direction = [1.0, 0.0]

[drivers.push]
coordinate = "P.x"
file = "drive.csv"
interpolation = "linear"
""")
    model = cmbs.load(path)
    index = model.constraint_names.index("push")
    q = np.array([0.0, 0.0])
    assert model.constraints(q, 0.5)[index] == pytest.approx(-0.75)
    assert model.constraints_t(q, 0.5)[index] == pytest.approx(0.5)
    assert model.gamma(q, np.zeros(2), 0.5)[index] == pytest.approx(0.0)
    np.testing.assert_allclose(model.qd0, [-0.5, 0.0], atol=1e-12)
