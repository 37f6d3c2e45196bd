"""numba when it is installed, else the same kernels as plain Python on numpy arrays.

Every compiled kernel of cmbs is written in the subset of Python and numpy that numba compiles,
and decorated with :func:`njit` from here.  Without numba (``import numba`` fails, e.g. on a
platform it has no wheels for, or with ``CMBS_DISABLE_NUMBA=1``) the decorator returns the
function unchanged: the same code runs interpreted, with the same results (tested to 1e-12
against the compiled kernels, tests/test_jit_fallback.py) and 100-1000× slower.  numba's own
``NUMBA_DISABLE_JIT=1`` has the same effect with numba installed.
"""

from __future__ import annotations

import os
from typing import Callable

try:
    if os.environ.get("CMBS_DISABLE_NUMBA", "") not in ("", "0"):
        raise ImportError("CMBS_DISABLE_NUMBA is set")
    import numba as _numba
except ImportError:
    _numba = None

#: True when the kernels are compiled by numba.
COMPILED = _numba is not None
#: numba's version, or "none": part of the name of generated equation modules.
VERSION = _numba.__version__ if _numba is not None else "none"


def njit(*args, **options) -> Callable:
    """``numba.njit`` with numba, else a decorator that leaves the function as it is.

    First-use compile time: numba links every compiled callee into its caller's module and
    optimises the whole module again, so each separately compiled function between a loop and a
    formulation's solve adds the solve's optimisation once more (1.5-3.5 s each).  A small
    function that only forwards to such a call (a wrapper, a right-hand side, a record step) is
    therefore compiled into its caller (``inline="always"``).  And a constant integer or boolean
    passed to a compiled callee is typed as a literal, for which numba compiles the callee once
    more: pass an ``np.int64`` (or a float) instead.  An array assigned to a slice
    (``a[:] = b``, ``a[k] = row``) brings numba's formatted shape-mismatch error, about 2 s to
    compile per array rank: the kernels copy element by element."""
    if _numba is not None:
        return _numba.njit(*args, **options)
    if len(args) == 1 and callable(args[0]) and not options:
        return args[0]
    return lambda function: function


def borrow(value):
    """``value`` with each of its arrays (itself, or the members of a tuple or named tuple, nested)
    replaced by a *borrowed* view: the same memory, which numba does not reference-count.

    numba counts the references to every array a compiled function receives, slices or reshapes,
    with an atomic increment and decrement each time (a call passing a kernel tuple counts each
    of its arrays); in the four-bar's RK4 loop these made about half of the time.  The loops
    therefore borrow the arrays of a run once, at their top (the state, the work arrays, the model's
    and the formulation's kernel tuples), and hand the borrowed views down: every view and call
    below then counts nothing.  A borrowed view must not outlive the call that made it: it is never
    returned to Python nor kept in an array or object that is; the arrays it views stay owned by
    the caller (tests/test_borrowing.py checks that the compiled paths free all they allocate).
    Compiled, a C-contiguous writeable array becomes ``numba.carray`` over its buffer (cffi's
    ``from_buffer``, the pointer numba documents for this); any other value is returned as it is.
    Interpreted, ``value`` itself."""
    return value


if _numba is not None:
    from cffi import FFI as _FFI
    from numba.core import types as _types

    _ffi = _FFI()

    @_numba.njit(cache=True)
    def _borrowed_array(array):
        """``array``'s memory as an array numba does not reference-count (``numba.carray`` over
        cffi's ``from_buffer`` pointer): the compiled :func:`borrow` of one C-contiguous array."""
        return _numba.carray(_ffi.from_buffer(array), array.shape)

    def _compile_borrow() -> None:
        """Type a compiled ``borrow(value)`` as returning ``value``'s own type and lower it member by
        member (numba's ``infer_global``/``AbstractTemplate`` typing and ``lower_builtin``): a tuple
        is rebuilt from its borrowed members in the caller's own code, each C-contiguous
        writeable array by a call of :func:`_borrowed_array`.  No function is compiled per tuple
        type, as an overload would for every tuple a run passes (900 small compilations in the
        test suite, a tenth of its compile time)."""
        from numba.core.typing.templates import AbstractTemplate, infer_global, signature
        from numba.extending import lower_builtin

        @infer_global(borrow)
        class _Typed(AbstractTemplate):
            def generic(self, args, kws):
                if len(args) == 1 and not kws:
                    return signature(args[0], args[0])
                return None

        @lower_builtin(borrow, _types.Any)
        def _lowered(context, builder, sig, args):
            return _borrowed(context, builder, sig.args[0], args[0])

        def _borrowed(context, builder, kind, value):
            """``value`` of numba type ``kind`` with its arrays borrowed, as a new reference (the
            members not borrowed are counted once more, as the caller's own)."""
            if isinstance(kind, _types.Array) and kind.layout == "C" and kind.mutable:
                function = _types.Dispatcher(_borrowed_array)
                call = function.get_call_type(context.typing_context, (kind,), {})
                return context.get_function(function, call)(builder, [value])
            if isinstance(kind, _types.BaseTuple):
                for index, member in enumerate(kind):
                    item = _borrowed(context, builder, member, builder.extract_value(value, index))
                    value = builder.insert_value(value, item, index)
                return value
            if context.enable_nrt:
                context.nrt.incref(builder, kind, value)
            return value

    _compile_borrow()


def interpreted(kernel: Callable) -> Callable:
    """The Python function a kernel was compiled from (the kernel itself without numba): for a
    one-off call from Python of a plain-numpy kernel, which then loads no compiled code."""
    return getattr(kernel, "py_func", kernel)


class Delegated:
    """A kernel attribute of a named tuple class meaning "the same kernel of my member ``field``":
    :func:`type_dispatch` then calls the member's class kernel with the member in place of the
    tuple (a wrapper whose hook only forwards, e.g. drift projection's solve, adds no call)."""

    def __init__(self, field: str):
        self.field = field


def type_dispatch(attribute: str, default: Callable | None = None) -> Callable:
    """A function ``f(data, *args)`` that calls ``type(data).<attribute>(data, *args)``, or
    ``default(data, *args)`` for a class without that attribute (when ``default`` is given); where
    the attribute is :class:`Delegated`, the same for ``data``'s member it names.

    ``data`` is a :class:`typing.NamedTuple` whose class carries the kernel as a static attribute
    (a model's terms kernel, a formulation's solve, an input law).  Compiled, the choice is made
    by numba when the caller is compiled, so a loop taking ``data`` compiles only the kernel of
    that class and its specialisation is cached like any other; interpreted, it is a plain
    attribute lookup.  Adding a kind of model or a formulation is adding a class and its kernel:
    no code of the loops changes.  The call compiles to a direct call of the kernel (numba's
    low-level typing and lowering API, :func:`_compile_as_direct_call`): no function between the
    caller and the kernel, which a compiled forwarding function would be, and which would make
    numba optimise the kernel's code once more on a first compilation."""

    def dispatch(data, *args):
        kernel = getattr(type(data), attribute, default)
        while isinstance(kernel, Delegated):
            data = getattr(data, kernel.field)
            kernel = getattr(type(data), attribute, default)
        return kernel(data, *args)

    dispatch.__name__ = dispatch.__qualname__ = f"dispatch_{attribute}"
    if _numba is not None:
        _compile_as_direct_call(dispatch, attribute, default)
    return dispatch


def _compile_as_direct_call(dispatch: Callable, attribute: str, default: Callable | None) -> None:
    """Type a compiled call ``dispatch(data, *args)`` as the call of ``data``'s class kernel
    (``numba.core.typing.templates.AbstractTemplate`` registered by ``infer_global``) and lower it
    as that call (``numba.extending.lower_builtin``), the arguments cast to the kernel's
    compiled signature; a :class:`Delegated` kernel is followed to the member it names."""
    from numba.core import types
    from numba.core.typing.templates import AbstractTemplate, infer_global, signature
    from numba.extending import lower_builtin

    def target(data: types.Type) -> tuple[types.Dispatcher | None, types.Type, list[int]]:
        """The kernel's dispatcher type, the type of the tuple it takes, and the member indices
        that lead from ``data`` to that tuple."""
        path = []
        kernel = getattr(getattr(data, "instance_class", None), attribute, default)
        while isinstance(kernel, Delegated):
            index = data.instance_class._fields.index(kernel.field)
            path.append(index)
            data = data.types[index]
            kernel = getattr(getattr(data, "instance_class", None), attribute, default)
        return (types.Dispatcher(kernel) if kernel is not None else None), data, path

    key = object()          # the typing and lowering key (``dispatch`` is not a module attribute)

    @infer_global(dispatch, typing_key=key)
    class _Typed(AbstractTemplate):
        def generic(self, args, kws):
            if not args or kws:
                return None
            kernel, data, _ = target(args[0])
            if kernel is None:
                return None
            call = self.context.resolve_function_type(kernel, (data, *args[1:]), {})
            return None if call is None else signature(call.return_type, *args)

    @lower_builtin(key, types.VarArg(types.Any))
    def _lowered(context, builder, sig, args):
        kernel, data, path = target(sig.args[0])
        value = args[0]
        for index in path:
            value = builder.extract_value(value, index)
        given = (data, *sig.args[1:])
        call = kernel.get_call_type(context.typing_context, given, {})
        values = [context.cast(builder, value, source, wanted)
                  for value, source, wanted in zip((value, *args[1:]), given, call.args)]
        result = context.get_function(kernel, call)(builder, values)
        return context.cast(builder, result, call.return_type, sig.return_type)


#: ``numba.prange`` (parallel loop over independent iterations) with numba, else ``range``.
prange = _numba.prange if _numba is not None else range


def threads() -> int:
    """Threads a parallel kernel uses (numba's), 1 without numba."""
    return _numba.get_num_threads() if _numba is not None else 1


def announce_compilation(write: Callable[[str], object]) -> None:
    """Call ``write`` with one line the first time this process compiles a kernel (numba's
    ``numba:compile`` event, which a kernel loaded from the disk cache does not raise): the first
    run after an install compiles for 20 s to a minute and would otherwise look stuck."""
    if _numba is None:
        return
    from numba.core import event

    class Announcement(event.Listener):
        done = False

        def on_start(self, event: object) -> None:
            if not self.done:
                self.done = True
                write("cmbs: compiling the kernels this run needs (first use after an install: 20 s to a minute; "
                      "cached for later runs)")

        def on_end(self, event: object) -> None:
            pass

    event.register("numba:compile", Announcement())



class _CompileClock:
    """Seconds spent in numba's ``numba:compile`` events (:mod:`numba.core.event`) since it was
    registered, from each outermost start to its end, so that a kernel compiling its callees counts
    once."""

    def __init__(self) -> None:
        from numba.core import event

        self.listener = event.TimingListener()
        event.register("numba:compile", self.listener)

    def seconds(self) -> float:
        return self.listener.duration if self.listener.done else 0.0


_clock: _CompileClock | None = None


def compile_seconds() -> float:
    """Seconds this process has spent compiling kernels since its first call of this function (0
    without numba).  The difference of two calls is the compile time between them: 0 when every
    kernel used was already compiled in this process or loaded from the disk cache.  A run
    reports it as ``info["compile_time"]``, included in its ``wall_time``."""
    global _clock
    if _numba is None:
        return 0.0
    if _clock is None:
        _clock = _CompileClock()
    return _clock.seconds()
