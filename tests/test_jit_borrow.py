"""``cmbs.jit.borrow``: the same memory, the same types, nothing else changed.

The loops borrow a run's arrays once at their top; what they then write must land in the
caller's arrays (the records, the state), and a borrowed tuple must have the type of the tuple
it came from, or every kernel below would be compiled a second time for it.  A sweep's variants
run on copies of a formulation's kernel tuple (``cmbs.integrate.variants.fresh``)."""

from typing import NamedTuple

import numpy as np
import pytest

from cmbs import jit
from cmbs.integrate.variants import fresh


class Inner(NamedTuple):
    values: np.ndarray
    scale: float


class Outer(NamedTuple):
    inner: Inner
    matrix: np.ndarray
    flag: bool
    count: int


@jit.njit
def _write_through(outer, pair):
    borrowed = jit.borrow(outer)
    borrowed_pair = jit.borrow(pair)
    borrowed.inner.values[1] = 7.0
    borrowed.matrix[1, 0] = -2.0
    borrowed_pair[1][0] = 3.0
    return borrowed.inner.scale + borrowed.count, borrowed.flag, borrowed_pair[0]


def _outer():
    return Outer(Inner(np.zeros(3), 0.5), np.zeros((2, 2)), True, 4)


def test_borrowed_arrays_write_into_the_callers_arrays():
    outer, pair = _outer(), (1.5, np.zeros(2))
    scalars = _write_through(outer, pair)
    assert scalars == (4.5, True, 1.5)
    np.testing.assert_array_equal(outer.inner.values, [0.0, 7.0, 0.0])
    np.testing.assert_array_equal(outer.matrix, [[0.0, 0.0], [-2.0, 0.0]])
    np.testing.assert_array_equal(pair[1], [3.0, 0.0])


@pytest.mark.skipif(not jit.COMPILED, reason="numba's types: numba is not installed")
def test_a_borrowed_tuple_has_the_type_of_the_tuple():
    import numba

    @numba.njit
    def same_type(outer):
        borrowed = jit.borrow(outer)
        outer = borrowed          # numba refuses a second type for one variable
        return outer.matrix.shape[0]

    assert same_type(_outer()) == 2
    assert len(same_type.signatures) == 1


def test_interpreted_borrow_returns_the_value_itself():
    outer = _outer()
    assert jit.interpreted(jit.borrow)(outer) is outer


class Wider(Inner):
    """A kernel class that differs from its base only in the kernels it carries."""

    __slots__ = ()


@pytest.mark.parametrize("kind", [Inner, Wider])
def test_fresh_gives_a_kernel_of_its_class_with_arrays_of_its_own(kind):
    """A sweep's variants each run on a copy of the formulation's kernel: of its class (the class
    chooses its kernels: a copy of a band-LU kernel must not come back as the Schur-complement
    one), each writeable array copied, nested tuples too, read-only data shared (a copy would be
    writeable: another type to compile the loops for)."""
    read_only = np.arange(2.0)
    read_only.setflags(write=False)
    value = Outer(kind(np.arange(3.0), 0.5), read_only, True, 4)
    copy = fresh(value)
    assert type(copy) is Outer and type(copy.inner) is kind
    assert copy.inner.values is not value.inner.values
    np.testing.assert_array_equal(copy.inner.values, value.inner.values)
    assert copy.matrix is read_only and copy.inner.scale == 0.5 and (copy.flag, copy.count) == (True, 4)
