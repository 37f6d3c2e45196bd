"""Fixtures shared by several test files."""

import pytest


@pytest.fixture(scope="session")
def prepared():
    """The first right stride of the public gait trial, prepared once per test session (skipped
    with the reason when the data cannot be fetched, e.g. offline)."""
    from cmbs.gait import GaitDataError, prepare_stride
    from cmbs.gait.data import NORMATIVE, TRIAL, fetch

    try:
        fetch(TRIAL), fetch(NORMATIVE)
    except GaitDataError as error:
        pytest.skip(f"gait data not available: {error}")
    return prepare_stride(1)
