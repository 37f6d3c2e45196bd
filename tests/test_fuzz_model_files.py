"""A small, seeded run of the model-file fuzzer (tests/fuzz_model_files.py; the large count runs
as ``python -m tests.fuzz_model_files --count 5000``): no mutant of a library or documentation
model may escape as an exception other than CmbsError."""

import math
import tomllib

import numpy as np

from tests.fuzz_model_files import fuzz, mutant, seeds, toml_text


def _same(a, b) -> bool:
    """Equal documents, NaN equal to NaN."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(map(_same, a, b))
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    return type(a) is type(b) and a == b


def test_the_fuzzer_writes_back_what_it_read():
    """Its TOML writer loses nothing: every seed parses back to the same document."""
    for name, text in seeds():
        document = tomllib.loads(text)
        assert _same(tomllib.loads(toml_text(document)), document), name


def test_mutants_are_reproducible_and_mutated():
    name, text = seeds()[0]
    first = [mutant(text, np.random.default_rng(5)) for _ in range(3)]
    again = [mutant(text, np.random.default_rng(5)) for _ in range(3)]
    assert first == again
    assert all(descriptions for _, descriptions in first)


def test_no_mutant_escapes_as_an_uncaught_exception():
    report = fuzz(200, seed=20261126)
    assert report.uncaught == [], report.summary()
    assert report.timeouts == [], report.summary()
    # the run reached both ends: files refused with one line, and files that load and simulate
    assert report.statuses[2] >= 100 and report.statuses[0] >= 10, report.summary()
