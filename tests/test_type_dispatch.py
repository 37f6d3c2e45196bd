"""``cmbs.jit.type_dispatch``: a compiled call goes to the kernel the data's class carries.

The loops are written once for every model kind and formulation; the kernel each call reaches is
chosen by the class of its named tuple.  Checked here on small classes of their own, compiled
and interpreted, against the value each kernel computes by hand."""

from typing import NamedTuple

import numpy as np
import pytest

from cmbs import jit


@jit.njit(cache=False)
def _doubled(data, x, out):
    out[0] = 2.0 * data.scale * x
    return 1


@jit.njit(cache=False)
def _squared(data, x, out):
    out[0] = data.scale * x * x
    return 2


@jit.njit(cache=False)
def _fallback(data, x, out):
    out[0] = -x
    return 3


class Doubling(NamedTuple):
    scale: float


class Squaring(NamedTuple):
    scale: float


class Plain(NamedTuple):
    scale: float


Doubling.apply = staticmethod(_doubled)
Squaring.apply = staticmethod(_squared)
apply = jit.type_dispatch("apply", default=_fallback)
apply_strictly = jit.type_dispatch("apply")


@jit.njit(cache=False)
def _loop(data, x):
    out = np.zeros(1)
    code = apply(data, x, out)
    return code, out[0]


@jit.njit(cache=False)
def _loop_with_a_constant(data):
    out = np.zeros(1)
    code = apply(data, 3, out)          # an integer literal where the kernel computes with floats
    return code, out[0]


@pytest.mark.parametrize("data, code, value", [(Doubling(1.5), 1, 2 * 1.5 * 2.5), (Squaring(1.5), 2, 1.5 * 2.5 ** 2),
                                               (Plain(1.5), 3, -2.5)])
def test_each_class_reaches_its_kernel_or_the_default(data, code, value):
    for loop in (_loop, jit.interpreted(_loop)):
        assert loop(data, 2.5) == (code, value)


def test_arguments_are_passed_as_the_kernel_takes_them():
    """A literal integer argument reaches the kernel as the number it is."""
    for loop in (_loop_with_a_constant, jit.interpreted(_loop_with_a_constant)):
        assert loop(Doubling(0.5)) == (1, 3.0)
        assert loop(Squaring(0.5)) == (2, 4.5)


def test_a_class_without_the_kernel_and_no_default_is_a_typing_error():
    @jit.njit(cache=False)
    def strict(data):
        out = np.zeros(1)
        return apply_strictly(data, 1.0, out)

    if jit.COMPILED:
        from numba.core.errors import TypingError

        with pytest.raises(TypingError):
            strict(Plain(1.0))
    with pytest.raises(TypeError):                  # getattr gives None: not callable
        jit.interpreted(strict)(Plain(1.0))


class Wrapper(NamedTuple):
    inner: Doubling
    offset: float


class WrapperOfWrapper(NamedTuple):
    label: int
    wrapped: Wrapper


Wrapper.apply = jit.Delegated("inner")
WrapperOfWrapper.apply = jit.Delegated("wrapped")


@pytest.mark.parametrize("data", [Wrapper(Doubling(1.5), 9.0), WrapperOfWrapper(7, Wrapper(Doubling(1.5), 9.0))])
def test_a_delegated_kernel_is_the_members_own(data):
    """A wrapper's forwarding hook (drift projection's solve) calls its member's kernel with the
    member: the wrapper's own fields do not reach it."""
    for loop in (_loop, jit.interpreted(_loop)):
        assert loop(data, 2.5) == (1, 2 * 1.5 * 2.5)
