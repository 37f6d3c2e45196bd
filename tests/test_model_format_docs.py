"""docs/model-format.md cannot rot: every ```toml block in it is a complete model file that loads,
assembles (|Φ(q0, 0)| < 1e-9, consistent q̇0) and has the DOF stated in its first line
``# DOF: k``.  The ```csv blocks whose first line is ``# file: NAME`` are written next to the
model files, so that drivers can read them."""

import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.model.files import _SECTIONS
from cmbs.model.spatial_files import SECTIONS as SPATIAL_SECTIONS

DOC = Path(__file__).resolve().parents[1] / "docs" / "model-format.md"
FENCE = re.compile(r"^```(\w+)[ \t]*\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)
DOF_LINE = re.compile(r"# DOF: (\d+)")
FILE_LINE = re.compile(r"# file: (\S+)")


def fenced_blocks(kind):
    """(line number in the document, text) of every ```kind block."""
    text = DOC.read_text()
    return [(text.count("\n", 0, match.start()) + 1, match.group(2))
            for match in FENCE.finditer(text) if match.group(1) == kind]


TOML_BLOCKS = fenced_blocks("toml")
CSV_BLOCKS = fenced_blocks("csv")


def write_csv_files(directory):
    for _, text in CSV_BLOCKS:
        name = FILE_LINE.fullmatch(text.splitlines()[0]).group(1)
        (directory / name).write_text(text)


def stated_dof(text):
    match = DOF_LINE.fullmatch(text.splitlines()[0])
    assert match, f"the block must start with '# DOF: k', got {text.splitlines()[0]!r}"
    return int(match.group(1))


def test_the_document_has_examples():
    assert len(TOML_BLOCKS) >= 15
    assert CSV_BLOCKS


@pytest.mark.parametrize("line, text", TOML_BLOCKS, ids=[f"line-{line}" for line, _ in TOML_BLOCKS])
def test_example_loads_assembles_and_has_its_dof(tmp_path, line, text):
    dof = stated_dof(text)
    write_csv_files(tmp_path)
    path = tmp_path / f"example-{line}.toml"
    path.write_text(text)
    model = cmbs.load(path)
    if model.m:
        assert np.abs(model.constraints(model.q0, 0.0)).max() < 1e-9
        velocity_residual = model.jacobian(model.q0, 0.0) @ model.qd0 + model.constraints_t(model.q0, 0.0)
        assert np.abs(velocity_residual).max() < 1e-9
    report = cmbs.constraint_report(model, model.q0, 0.0)
    assert report.dof == dof, f"docs/model-format.md line {line}: DOF {report.dof}, the block says {dof}"
    assert report.redundant == ()


def test_csv_blocks_are_named_and_used():
    names = [FILE_LINE.fullmatch(text.splitlines()[0]) for _, text in CSV_BLOCKS]
    assert all(names), "every ```csv block starts with '# file: NAME'"
    used = {name.group(1) for name in names}
    referenced = {driver.get("file") for _, text in TOML_BLOCKS
                  for driver in tomllib.loads(text).get("drivers", {}).values()} - {None}
    assert used == referenced


def _dimension(text):
    return tomllib.loads(text).get("model", {}).get("dimension", 2)


@pytest.mark.parametrize("dimension, allowed", [(2, _SECTIONS), (3, SPATIAL_SECTIONS)])
def test_every_section_has_an_example_and_the_last_uses_all(dimension, allowed):
    """For the planar files and for the spatial ones (section 9) alike."""
    sections = [set(tomllib.loads(text)) for _, text in TOML_BLOCKS if _dimension(text) == dimension]
    assert sections
    assert set().union(*sections) == set(allowed)
    assert sections[-1] == set(allowed)
