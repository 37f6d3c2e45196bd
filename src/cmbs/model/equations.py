"""Models from user-given equations: SymPy expressions or Python callables.

Both builders return the same :class:`~cmbs.model.model.Model` as the natural- and
joint-coordinate builders, so every formulation, integrator and controller treats them alike.
The convention is THEORY §1 (García de Jalón & Bayo)::

    M(q) q̈ + Aᵀ λ = Q(q, q̇, t, u),      Φ(q, t) = 0,      A = Φ_q,
    A q̇ = -Φ_t,                         A q̈ = γ = -(Ȧ q̇) - 2 Φ_qt q̇ - Φ_tt.

:func:`from_sympy`
    The user gives M, Q, Φ (and optionally V and drawable points) as SymPy expressions.  A, Φ_t
    and γ are derived symbolically: with ``Φ̇ = A q̇ + Φ_t``, ``γ = -(∂Φ̇/∂q q̇ + ∂Φ̇/∂t)``, which
    expands to the formula above (``Φ̈ = A q̈ - γ``).  All terms of one evaluation are compiled
    into one straight-line function after common-subexpression elimination (``sympy.cse``):
    scalar Python code on the ``math`` module by default (about 2 µs per evaluation for a
    pendulum, no compile delay) or the same code compiled with numba (``backend="numba"``, for
    large expressions: 1-10 s of compile time at the first build, then kept in numba's on-disk
    cache).
:func:`from_callables`
    The user gives Python functions returning numpy arrays; they are called once per
    evaluation and their results copied into the :class:`~cmbs.model.model.Terms` workspace.

Both builders check the model at build time (declared symbols, shapes, symmetry, positive
definiteness of M at ``q0``) and raise :class:`~cmbs.errors.ModelError` naming the entry at
fault.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.util
import os
import sys
import tempfile
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np
import sympy
from sympy.core.function import AppliedUndef
from sympy.printing.pycode import PythonCodePrinter

from cmbs.errors import ModelError, did_you_mean
from cmbs.model.model import Model, Terms

__all__ = ["from_sympy", "from_callables", "SympyEquations", "CallableEquations"]

BACKENDS = ("python", "numba")


# ====================================================================== code generation
class _Printer(PythonCodePrinter):
    """``math``-module printer that keeps every bit of double-precision constants."""

    def __init__(self) -> None:
        super().__init__({"fully_qualified_modules": False, "standard": "python3"})

    def _print_Float(self, expr: sympy.Float) -> str:  # noqa: N802 - sympy printer API
        return repr(float(expr))

    def _print_Pow(self, expr: sympy.Pow, rational: bool = False) -> str:  # noqa: N802
        # x*x is ~3x faster than x**2 on Python floats; only for symbols (cse temporaries and
        # variables), so that no subexpression is evaluated twice.
        base, exponent = expr.args
        if isinstance(base, sympy.Symbol) and exponent.is_Integer and 2 <= int(exponent) <= 4:
            return "(" + "*".join([self._print(base)] * int(exponent)) + ")"
        return super()._print_Pow(expr, rational=rational)


class _Kernel:
    """A straight-line function of ``(q, qd, t, u)`` for a flat list of expressions.

    ``backend="python"``: ``function(q, qd, t, u) -> tuple`` with Python lists/floats in.
    ``backend="numba"``: ``function(q, qd, t, u, out)`` writes ``out[k]`` (float64 arrays in).
    """

    def __init__(self, label: str, expressions: Sequence[sympy.Expr], arguments: dict[str, list],
                 backend: str, cache: bool = True) -> None:
        """``arguments`` maps the argument name (``q``, ``qd``, ``t``, ``u``) to canonical symbols."""
        self.label = label
        self.backend = backend
        self.size = len(expressions)
        replacements, reduced = _cse(expressions)
        printer = _Printer()
        body: list[str] = []
        for symbol, value in replacements:
            body.append(f"    {symbol.name} = {printer.doprint(value)}")
        used = set().union(*(value.free_symbols for _, value in replacements)) if replacements else set()
        used |= set().union(*(sympy.sympify(e).free_symbols for e in reduced)) if reduced else set()
        unpack: list[str] = []
        for argument, symbols in arguments.items():
            for index, symbol in enumerate(symbols):
                if symbol in used:
                    unpack.append(f"    {symbol.name} = {argument}" + ("" if argument == "t" else f"[{index}]"))
        outputs = [printer.doprint(expression) for expression in reduced]
        if backend == "python":
            signature = ", ".join(arguments)
            tail = ["    return (" + "".join(f"{text}, " for text in outputs) + ")"]
        else:
            signature = ", ".join(arguments) + ", out"
            tail = [f"    out[{k}] = {text}" for k, text in enumerate(outputs)] + ["    return"]
        self.source = "\n".join([f"def _{label}({signature}):"] + unpack + body + tail) + "\n"
        imports = {module: sorted(names) for module, names in printer.module_imports.items()}
        function = _generated_function(label, self.source, imports, numba=backend == "numba", cache=cache)
        self.function = function


def cache_directory() -> Path | None:
    """Where compiled numba kernels are kept: ``$CMBS_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/cmbs/equations`` (``~/.cache/cmbs/equations``); None if not writable."""
    configured = os.environ.get("CMBS_CACHE_DIR")
    if configured is not None:
        directory = Path(configured)
    else:
        directory = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "cmbs" / "equations"
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return directory if os.access(directory, os.W_OK) else None


def _generated_function(label: str, source: str, imports: dict[str, list[str]], *, numba: bool, cache: bool):
    """The function ``_{label}`` of the generated ``source``, written as a module file named by
    its hash and imported (never ``exec``-ed from a string).  The file goes to
    :func:`cache_directory` — where, with ``numba`` and ``cache``, numba's on-disk cache lets a
    rebuild of the same model (another process, a pickled copy) skip compilation — or, when that
    is unusable, to a per-process temporary folder."""
    from cmbs import jit

    directory = cache_directory()
    numba = numba and jit.COMPILED          # without numba the generated code runs as Python
    cached = numba and cache and directory is not None
    if directory is None:
        directory = _scratch_directory()
    decorator = "@njit(cache=True)\n" if cached else "@njit\n" if numba else ""
    header = "".join(f"from {module} import {', '.join(names)}\n" for module, names in imports.items())
    text = f"from cmbs.jit import njit\n{header}\n\n{decorator}{source}"
    digest = hashlib.sha256(f"{jit.VERSION}\n{text}".encode()).hexdigest()[:24]
    module_name = f"cmbs_equations_{digest}"
    path = directory / f"{module_name}.py"
    module = sys.modules.get(module_name)
    if module is None:
        if not path.exists():
            temporary = directory / f"{module_name}.{os.getpid()}.tmp"
            temporary.write_text(text, encoding="utf-8")
            os.replace(temporary, path)
        spec = importlib.util.spec_from_file_location(module_name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[module_name] = module  # numba's cache re-imports the module by name
        try:
            spec.loader.exec_module(module)
        except BaseException:
            sys.modules.pop(module_name, None)
            raise
    return getattr(module, f"_{label}")


@functools.cache
def _scratch_directory() -> Path:
    """A temporary folder for generated modules when the cache directory is not writable."""
    return Path(tempfile.mkdtemp(prefix="cmbs-equations-"))


def _cse(expressions: Sequence[sympy.Expr]) -> tuple[list, list]:
    if not expressions:
        return [], []
    replacements, reduced = sympy.cse(list(expressions), symbols=sympy.numbered_symbols("_c"),
                                      order="none")
    return replacements, list(reduced)


# ====================================================================== validation helpers
def _symbol_list(label: str, symbols: Sequence[object] | None, model: str) -> list[sympy.Symbol]:
    if symbols is None:
        return []
    if isinstance(symbols, sympy.MatrixBase):
        symbols = list(symbols)
    if isinstance(symbols, (sympy.Basic, str)):
        raise ModelError(f"model {model!r}: {label} must be a sequence of sympy Symbols, got {symbols!r}")
    result = list(symbols)
    for index, symbol in enumerate(result):
        if not isinstance(symbol, sympy.Symbol):
            hint = (" (for sympy.physics.mechanics dynamicsymbols substitute plain Symbols first)"
                    if isinstance(symbol, AppliedUndef) else "")
            raise ModelError(f"model {model!r}: {label}[{index}] must be a sympy Symbol, "
                             f"got {symbol!r} of type {type(symbol).__name__}{hint}")
    return result


def _as_vector(label: str, value: object, model: str, *, size: int | None) -> list[sympy.Expr]:
    """A column (or plain sequence) of expressions; ``size`` None: any length."""
    if value is None:
        entries: list = []
    elif isinstance(value, sympy.MatrixBase):
        rows, cols = value.shape
        if rows * cols == 0:
            entries = []
        elif cols != 1:
            raise ModelError(f"model {model!r}: {label} must be a column vector (k, 1), "
                             f"got a sympy Matrix of shape {value.shape}")
        else:
            entries = list(value)
    elif isinstance(value, sympy.Basic) or np.isscalar(value):
        raise ModelError(f"model {model!r}: {label} must be a column vector or a sequence of "
                         f"expressions, got the single expression {value!r}")
    else:
        entries = list(value)
    try:
        result = [sympy.sympify(entry, strict=True) for entry in entries]
    except (sympy.SympifyError, TypeError) as error:
        raise ModelError(f"model {model!r}: {label} has an entry that is not a sympy expression: "
                         f"{error}") from None
    for index, entry in enumerate(result):
        if not isinstance(entry, sympy.Expr):
            raise ModelError(f"model {model!r}: {label}[{index}] must be a scalar expression, "
                             f"got {entry!r} of type {type(entry).__name__}")
    if size is not None and len(result) != size:
        raise ModelError(f"model {model!r}: {label} has {len(result)} entries, expected {size} "
                         f"(one per coordinate)")
    return result


def _check_symbols(model: str, label: str, expression: sympy.Expr, allowed: set, declared: dict,
                   allowed_text: str) -> None:
    """Raise naming the first stray symbol/function of ``expression`` (``label`` names the entry)."""
    for function in sorted(expression.atoms(AppliedUndef), key=str):
        raise ModelError(f"model {model!r}: {label} uses undefined function {str(function.func)!r} "
                         f"in {function}; only explicit expressions can be compiled")
    for bad in (sympy.Derivative, sympy.Integral):
        if expression.has(bad):
            raise ModelError(f"model {model!r}: {label} contains an unevaluated {bad.__name__}; "
                             f"call .doit() first")
    if expression.has(sympy.I) or expression.has(sympy.zoo, sympy.nan, sympy.oo, -sympy.oo):
        raise ModelError(f"model {model!r}: {label} is complex or infinite: {expression}")
    for symbol in sorted(expression.free_symbols, key=lambda s: s.name):
        if symbol in allowed:
            continue
        if symbol in declared:
            raise ModelError(f"model {model!r}: {label} uses {declared[symbol]} {symbol.name!r}, but "
                             f"{label.split('[')[0]} may depend on {allowed_text} only")
        same_name = [s for s in declared if getattr(s, "name", None) == symbol.name]
        hint = (f" (a declared symbol of that name has other assumptions: {same_name[0].assumptions0})"
                if same_name else "; substitute numbers for parameters or declare it as an input")
        raise ModelError(f"model {model!r}: {label} uses unknown symbol {symbol.name!r}{hint}")


def _index_label(label: str, index: int, shape: tuple[int, ...] | None = None) -> str:
    if shape is not None and len(shape) == 2:
        return f"{label}[{index // shape[1]}, {index % shape[1]}]"
    return f"{label}[{index}]"


def _initial_vector(label: str, value: object, n: int, model: str) -> np.ndarray:
    if value is None:
        return np.zeros(n)
    array = np.asarray(value, dtype=float)
    if array.shape != (n,):
        raise ModelError(f"model {model!r}: {label} has shape {array.shape}, expected ({n},)")
    if not np.all(np.isfinite(array)):
        raise ModelError(f"model {model!r}: {label} is not finite: {array}")
    return array


def _check_mass(model: str, mass: np.ndarray, q0: np.ndarray, *, symmetric_tolerance: float | None) -> None:
    n = q0.size
    if mass.shape != (n, n):
        raise ModelError(f"model {model!r}: mass_matrix returned shape {mass.shape}, expected ({n}, {n})")
    if not np.all(np.isfinite(mass)):
        raise ModelError(f"model {model!r}: mass_matrix is not finite at q0 = {q0.tolist()}")
    if symmetric_tolerance is not None:
        scale = max(1.0, float(np.max(np.abs(mass))))
        if np.max(np.abs(mass - mass.T)) > symmetric_tolerance * scale:
            i, j = np.unravel_index(int(np.argmax(np.abs(mass - mass.T))), mass.shape)
            raise ModelError(f"model {model!r}: mass_matrix is not symmetric at q0: "
                             f"M[{i}, {j}] = {mass[i, j]!r} but M[{j}, {i}] = {mass[j, i]!r}")
    try:
        np.linalg.cholesky(0.5 * (mass + mass.T))
    except np.linalg.LinAlgError:
        eigenvalues = np.linalg.eigvalsh(0.5 * (mass + mass.T))
        raise ModelError(f"model {model!r}: mass_matrix is not positive definite at q0 = "
                         f"{q0.tolist()} (smallest eigenvalue {eigenvalues[0]:.6g})") from None


def _lines(lines: Sequence, point_names: Sequence[str], model: str) -> tuple[tuple[int, int], ...]:
    result = []
    for k, line in enumerate(lines):
        if len(line) != 2:
            raise ModelError(f"model {model!r}: lines[{k}] must be a pair of points, got {line!r}")
        pair = []
        for end in line:
            if isinstance(end, str):
                if end not in point_names:
                    raise ModelError(f"model {model!r}: lines[{k}] names unknown point {end!r}; "
                                     f"points: {', '.join(point_names) or '(none)'}")
                pair.append(point_names.index(end))
            elif isinstance(end, (int, np.integer)) and not isinstance(end, bool) \
                    and 0 <= end < len(point_names):
                pair.append(int(end))
            else:
                raise ModelError(f"model {model!r}: lines[{k}] has point {end!r}, expected a point "
                                 f"name or an index in [0, {len(point_names)})")
        result.append((pair[0], pair[1]))
    return tuple(result)


def _names(label: str, names: Sequence[str] | None, default: list[str], model: str) -> tuple[str, ...]:
    if names is None:
        return tuple(default)
    names = tuple(str(name) for name in names)
    if len(names) != len(default):
        raise ModelError(f"model {model!r}: {label} has {len(names)} names, expected {len(default)}")
    if len(set(names)) != len(names):
        raise ModelError(f"model {model!r}: {label} has duplicate names: {list(names)}")
    return names


def _driver_mask(drivers: Sequence[str | int] | None, names: Sequence[str], model: str,
                 timed: Sequence[bool] | None = None) -> np.ndarray:
    """The driver rows (True) among the constraints ``names``, from ``drivers``: the names or
    indices of the rows that are drivers (removed by :meth:`Model.without_drivers`).

    ``None`` means no driver when no row depends on time explicitly (``timed``, known for
    symbolic rows only); a row that does is either a driver or a rheonomic constraint of the
    mechanism, which the equations cannot tell apart, so then ``drivers`` must be given."""
    if drivers is None:
        moving = [name for name, depends in zip(names, timed or ()) if depends]
        if moving:
            listed = ", ".join(repr(name) for name in moving)
            raise ModelError(f"model {model!r}: constraints {listed} depend on time; say which rows are drivers "
                             f"(removed by without_drivers()): drivers=[{listed}] if they all are, drivers=[] if "
                             "they are rheonomic constraints of the mechanism")
        return np.zeros(len(names), dtype=bool)
    if isinstance(drivers, (str, bytes)) or not hasattr(drivers, "__iter__"):
        raise ModelError(f"model {model!r}: drivers must be a list of constraint names or row indices, got {drivers!r}")
    mask = np.zeros(len(names), dtype=bool)
    for entry in drivers:
        if isinstance(entry, str):
            if entry not in names:
                raise ModelError(f"model {model!r}: drivers names unknown constraint {entry!r}"
                                 f"{did_you_mean(entry, names)}; constraints: {', '.join(names) or 'none'}")
            row = list(names).index(entry)
        elif isinstance(entry, (int, np.integer)) and not isinstance(entry, (bool, np.bool_)):
            row = int(entry)
            if not 0 <= row < len(names):
                raise ModelError(f"model {model!r}: drivers row index {row} is out of range (the model has "
                                 f"{len(names)} constraints)")
        else:
            raise ModelError(f"model {model!r}: drivers must list constraint names or row indices, got {entry!r} "
                             f"in {list(drivers)!r}")
        if mask[row]:
            raise ModelError(f"model {model!r}: drivers names constraint {names[row]!r} twice")
        mask[row] = True
    return mask


def _buffer_positions(terms: Terms, fields: Sequence[str]) -> np.ndarray:
    """Flat indices into ``terms.buffer`` of the entries of ``fields`` (each flattened, C order)."""
    base = terms.buffer.__array_interface__["data"][0]
    itemsize = terms.buffer.itemsize
    positions = []
    for name in fields:
        view = getattr(terms, name)
        start = (view.__array_interface__["data"][0] - base) // itemsize
        positions.append(start + np.arange(view.size))
    return np.concatenate(positions) if positions else np.zeros(0, dtype=np.int64)


# ====================================================================== SymPy equations
class SympyEquations:
    """Compiled evaluators of a :func:`from_sympy` model (implements ``ModelEquations``).

    Attributes ``A``, ``phi_t``, ``gamma`` hold the derived SymPy expressions (in the user's
    symbols) for inspection; ``kernel_source`` the generated code of :meth:`evaluate`.
    """

    def __init__(self, *, name: str, n: int, m: int, n_u: int, symbols: dict[str, list],
                 inverse: dict, mass: sympy.Matrix, forces: list, phi: list, A: sympy.Matrix,
                 phi_t: list, gamma: list, potential: sympy.Expr | None, points: list, backend: str,
                 cache: bool, constant_mass: np.ndarray | None, rebuild: tuple,
                 work_sources: tuple[str, ...] | None = None, steady_drivers: frozenset[str] = frozenset()) -> None:
        """Expressions are in the canonical real symbols ``symbols`` (``_q0``, ``_v0``, ``_t``,
        ``_u0``, ...); ``inverse`` maps them back to the user's symbols.  ``work_sources``: see
        :func:`_work_sources`; ``steady_drivers``: the driver rows with Φ_t = 0."""
        self.n, self.m, self.n_u = n, m, n_u
        self.work_sources = work_sources
        self.steady_drivers = steady_drivers
        self.backend = backend
        self.A = A.xreplace(inverse)
        self.phi_t = sympy.Matrix(m, 1, phi_t).xreplace(inverse)
        self.gamma = sympy.Matrix(m, 1, gamma).xreplace(inverse)
        self._rebuild = rebuild

        def kernel(label: str, expressions: list, arguments: dict, kernel_backend: str) -> _Kernel:
            try:
                return _Kernel(label, expressions, arguments, kernel_backend, cache)
            except Exception as error:  # noqa: BLE001 - sympy printers raise assorted errors
                raise ModelError(f"model {name!r}: the {label} expressions cannot be compiled: "
                                 f"{type(error).__name__}: {error}") from error

        self.constant_mass = constant_mass
        if constant_mass is not None:
            constant_mass.setflags(write=False)
        probe = self.new_terms()
        fields = ["Q", "phi", "A", "gamma", "phi_t"] + ([] if constant_mass is not None else ["M"])
        entries = {"Q": forces, "phi": phi, "A": list(A), "gamma": gamma, "phi_t": phi_t,
                   "M": list(mass)}
        flat = [expression for name in fields for expression in entries[name]]
        positions = _buffer_positions(probe, fields)
        self._count = len(flat)
        self._contiguous = bool(np.array_equal(positions, np.arange(self._count)))
        self._positions = positions
        arguments = {"q": symbols["q"], "qd": symbols["qd"], "t": symbols["t"], "u": symbols["u"]}
        terms_kernel = kernel("terms", flat, arguments, backend)
        self.kernel_source = terms_kernel.source
        self._terms_function = terms_kernel.function
        q_only = {"q": symbols["q"]}
        self._mass_function = (None if constant_mass is not None else
                               kernel("mass", list(mass), q_only, "python").function)
        self._potential_function = (None if potential is None else
                                    kernel("potential", [potential], q_only, "python").function)
        self.n_points = len(points)
        flat_points = [coordinate for point in points for coordinate in point]
        self._points_function = (None if not points else
                                 kernel("points", flat_points, q_only, "python").function)
        self._no_u = np.zeros(0)

    def __reduce__(self):
        """Pickle by rebuilding from the SymPy expressions (the compiled code is not picklable)."""
        return _rebuild_sympy_equations, self._rebuild

    # ------------------------------------------------------------------ ModelEquations
    def new_terms(self) -> Terms:
        return Terms(self.n, self.m, constant_mass=self.constant_mass)

    def evaluate(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray, terms: Terms) -> None:
        """Fill ``terms`` with M, Q, Φ, A, γ, Φ_t at ``(q, q̇, t, u)``."""
        if self.backend == "python":
            values = self._terms_function(q.tolist(), qd.tolist(), float(t), u.tolist() if self.n_u else ())
            if self._contiguous:
                terms.buffer[:self._count] = values
            else:
                terms.buffer[self._positions] = values
        elif self._contiguous:
            self._terms_function(q, qd, float(t), u if self.n_u else self._no_u, terms.buffer)
        else:
            values = np.empty(self._count)
            self._terms_function(q, qd, float(t), u if self.n_u else self._no_u, values)
            terms.buffer[self._positions] = values
        if self.constant_mass is not None and terms.M is not self.constant_mass:
            terms.M[...] = self.constant_mass

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        if self.constant_mass is not None:
            return self.constant_mass
        return np.array(self._mass_function(np.asarray(q, float).tolist()), dtype=float).reshape(self.n, self.n)

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        """T = ½ q̇ᵀ M(q) q̇."""
        qd = np.asarray(qd, dtype=float)
        return 0.5 * float(qd @ self.mass_matrix(q) @ qd)

    def potential_energy(self, q: np.ndarray) -> float:
        """V(q) as given to :func:`from_sympy`; 0.0 when no potential was given."""
        if self._potential_function is None:
            return 0.0
        return float(self._potential_function(np.asarray(q, float).tolist())[0])

    def point_positions(self, q: np.ndarray) -> np.ndarray:
        """(n_points, 2) positions (x, z); an empty (0, 2) array when no points were given."""
        if self._points_function is None:
            return np.zeros((0, 2))
        return np.array(self._points_function(np.asarray(q, float).tolist()), dtype=float).reshape(-1, 2)


#: The coordinate kinds a model of its own equations may state.
EQUATION_KINDS = ("angle", "x", "z", "distance", "generic")


def _coordinate_kinds(kinds: Sequence[str] | None, n: int, name: str) -> tuple[str, ...]:
    """The ``n`` coordinate kinds given to :func:`from_sympy` (all "generic" if None), checked."""
    if kinds is None:
        return ("generic",) * n
    kinds = tuple(kinds)
    if len(kinds) != n or not all(kind in EQUATION_KINDS for kind in kinds):
        raise ModelError(f"model {name!r}: coordinate_kinds must give one of {', '.join(EQUATION_KINDS)} for each "
                         f"of the {n} coordinates, got {kinds!r}")
    return kinds


def _rebuild_sympy_equations(name: str, keywords: dict) -> SympyEquations:
    return from_sympy(name, **keywords).equations


def from_sympy(name: str, *, coordinates: Sequence[sympy.Symbol], mass_matrix: sympy.Matrix,
               forces: sympy.Matrix | Sequence[sympy.Expr],
               constraints: sympy.Matrix | Sequence[sympy.Expr] | None = None,
               velocities: Sequence[sympy.Symbol] | None = None,
               time: sympy.Symbol | None = None,
               inputs: Sequence[sympy.Symbol] = (),
               drivers: Sequence[str | int] | None = None,
               potential: sympy.Expr | None = None,
               points: Mapping[str, tuple[sympy.Expr, sympy.Expr]] | None = None,
               lines: Sequence[tuple[int | str, int | str]] = (),
               q0: Sequence[float] | None = None,
               qd0: Sequence[float] | None = None,
               description: str = "",
               source: str = "",
               constraint_names: Sequence[str] | None = None,
               velocity_constraints: sympy.Matrix | Sequence[sympy.Expr] | None = None,
               velocity_constraint_names: Sequence[str] | None = None,
               coordinate_kinds: Sequence[str] | None = None,
               backend: str = "python",
               cache: bool = True) -> Model:
    """A :class:`Model` from SymPy expressions of the equations of motion (THEORY §1).

    Parameters
    ----------
    name
        Model name.
    coordinates
        The n coordinate symbols ``q`` (their names become the coordinate names).
    mass_matrix
        ``M(q)``, (n, n), symmetric; depends on ``q`` only and must be positive definite at
        ``q0``.  When it does not depend on ``q`` the model gets ``constant_mass=True`` and every
        :class:`Terms` shares the read-only constant matrix.
    forces
        ``Q(q, q̇, t, u)``, n entries (column Matrix or sequence): applied forces, gravity,
        springs, dampers, inputs and, in minimal coordinates, minus the velocity-dependent
        (Coriolis/centrifugal) terms.
    constraints
        ``Φ(q, t)``, m entries (column Matrix or sequence); None or empty for an unconstrained
        system.  ``A = Φ_q``, ``Φ_t = ∂Φ/∂t`` and ``γ = -(∂Φ̇/∂q q̇ + ∂Φ̇/∂t)`` with
        ``Φ̇ = A q̇ + Φ_t`` are derived symbolically (in real symbols; derivatives of ``Abs``,
        ``sign``, ``Heaviside``, ``Min``, ``Max`` almost everywhere, i.e. ``DiracDelta`` → 0).
        The derived expressions are kept, in the user's symbols, as ``model.equations.A``,
        ``.phi_t`` and ``.gamma``.
    velocities
        Symbols for ``q̇`` (used in ``forces`` and ``velocity_constraints``).  If None, the
        symbols named ``f"{q}_d"`` (e.g. ``x_d``) that those use, whatever their assumptions.
    time
        The time symbol (``sympy.Symbol("t")`` if None).
    inputs
        Symbols of the actuator inputs ``u`` (their names become the actuator names).
    drivers
        The driver rows, by constraint name or row index (holonomic rows first, then velocity
        constraints): prescribed motions that :meth:`Model.without_drivers` removes.  None: no
        driver, allowed only when no row depends explicitly on time; a row that does is either
        a driver or a rheonomic constraint of the mechanism (kept by ``without_drivers``), so
        name the drivers (``drivers=[]`` when there are none).
    potential
        ``V(q)`` used only for energy reports; 0.0 when not given (then :meth:`Model.energy`
        is the kinetic energy only, and a conservative Q is not reflected in it).  The model's
        :attr:`~cmbs.model.model.Model.work_sources` come from the power balance of Q against
        V and M (:func:`_work_sources`): empty for a conservative model, whose runs then report
        their energy drift; gravity in Q without its V counts as a force that does work.
    points
        Drawable points ``{name: (x(q), z(q))}``; none gives an empty (0, 2) position array.
    lines
        Segments between points, as (i, j) pairs of point indices or names.
    q0, qd0
        Initial coordinates and velocities (zeros if None); M is checked at ``q0``.
    description, source
        Free text; ``source`` cites where the model comes from.
    constraint_names
        Names of the m constraints (``"phi[k]"`` if None).
    velocity_constraints
        Nonholonomic constraints ``ψ(q, q̇, t) = B(q, t) q̇ + b(q, t) = 0`` (column Matrix or
        sequence), each linear in the velocity symbols; appended after the rows of
        ``constraints`` and marked in :attr:`Model.nonholonomic`.  ``B = ∂ψ/∂q̇``, ``b = ψ|_{q̇=0}``
        and ``γ = -(∂ψ/∂q q̇ + ∂ψ/∂t)`` (so that ``ψ̇ = B q̈ - γ``) are derived symbolically; the
        row holds ``A = B``, ``Φ = 0``, ``Φ_t = b``, ``γ`` (see :class:`~cmbs.model.model.Terms`).
        ``drivers`` may name them too.
    velocity_constraint_names
        Names of the velocity constraints (``"psi[k]"`` if None).
    coordinate_kinds
        What each coordinate measures, for units and scales: ``"angle"`` (rad), ``"x"``, ``"z"``,
        ``"distance"`` (m) or ``"generic"`` (the model's own units); all ``"generic"`` if None.
    backend
        ``"python"`` (default): generated scalar code on the ``math`` module, no compile delay;
        best for small models.  ``"numba"``: the same code compiled by numba (compile time of
        order a second, paid at build; faster for expressions with hundreds of operations).
        Both raise ``ZeroDivisionError`` on division by zero; ``math`` raises ``ValueError`` on a
        domain error (e.g. ``sqrt`` of a negative number) where numba returns NaN.
    cache
        With ``backend="numba"``: keep the compiled kernel in numba's on-disk cache (the
        generated source is written to :func:`cache_directory`, named by its hash), so that
        rebuilding the same model, e.g. in a worker process, skips the compilation.

    Raises
    ------
    ModelError
        A stray symbol or undefined function (naming the entry, e.g. ``forces[2] uses unknown
        symbol 'k'``), a symbol used where it may not be (e.g. a velocity in Φ), wrong shapes,
        a non-symmetric M, an M not positive definite at ``q0``, a velocity constraint that is
        not linear in the velocities, or an evaluation failure at q0.
    """
    if backend not in BACKENDS:
        raise ModelError(f"model {name!r}: backend must be one of {BACKENDS}, got {backend!r}")
    rebuild = (name, dict(coordinates=coordinates, mass_matrix=mass_matrix, forces=forces,
                          constraints=constraints, velocities=velocities, time=time, inputs=inputs,
                          drivers=drivers, potential=potential, points=points, lines=lines, q0=q0,
                          qd0=qd0, description=description, source=source,
                          constraint_names=constraint_names, velocity_constraints=velocity_constraints,
                          velocity_constraint_names=velocity_constraint_names, backend=backend, cache=cache))
    q = _symbol_list("coordinates", coordinates, name)
    n = len(q)
    if n == 0:
        raise ModelError(f"model {name!r}: coordinates is empty; at least one coordinate is needed")
    kinds = _coordinate_kinds(coordinate_kinds, n, name)
    if velocities is None:
        qd = _default_velocities(q, forces, name, velocity_constraints)
    else:
        qd = _symbol_list("velocities", velocities, name)
        if len(qd) != n:
            raise ModelError(f"model {name!r}: velocities has {len(qd)} symbols, expected {n} "
                             f"(one per coordinate)")
    t = sympy.Symbol("t") if time is None else time
    if not isinstance(t, sympy.Symbol):
        raise ModelError(f"model {name!r}: time must be a sympy Symbol, got {t!r}")
    u = _symbol_list("inputs", inputs, name)
    declared: dict[sympy.Symbol, str] = {}
    for kind, group in (("coordinate", q), ("velocity", qd), ("time", [t]), ("input", u)):
        for symbol in group:
            if symbol in declared:
                raise ModelError(f"model {name!r}: symbol {symbol.name!r} is declared twice "
                                 f"(as {declared[symbol]} and as {kind})")
            declared[symbol] = kind

    # ------------------------------------------------------------ shapes and symbols
    if not isinstance(mass_matrix, sympy.MatrixBase):
        try:
            mass_matrix = sympy.Matrix(mass_matrix)
        except (TypeError, ValueError, sympy.SympifyError) as error:
            raise ModelError(f"model {name!r}: mass_matrix must be an (n, n) sympy Matrix: {error}") from None
    if mass_matrix.shape != (n, n):
        raise ModelError(f"model {name!r}: mass_matrix has shape {mass_matrix.shape}, expected "
                         f"({n}, {n}) for {n} coordinates")
    mass = sympy.Matrix(mass_matrix).applyfunc(sympy.sympify)
    Q = _as_vector("forces", forces, name, size=n)
    phi = _as_vector("constraints", constraints, name, size=None)
    psi = _as_vector("velocity_constraints", velocity_constraints, name, size=None)
    m_holonomic = len(phi)
    m = m_holonomic + len(psi)
    q_set, t_set = set(q), {t}
    checks = [("mass_matrix", list(mass), q_set, "the coordinates", (n, n)),
              ("forces", Q, q_set | set(qd) | t_set | set(u), "coordinates, velocities, time and inputs", None),
              ("constraints", phi, q_set | t_set, "the coordinates and time", None),
              ("velocity_constraints", psi, q_set | set(qd) | t_set, "coordinates, velocities and time", None)]
    for label, expressions, allowed, allowed_text, shape in checks:
        for index, expression in enumerate(expressions):
            _check_symbols(name, _index_label(label, index, shape), expression, allowed, declared, allowed_text)
    asymmetric = [(i, j) for i in range(n) for j in range(i + 1, n) if mass[i, j] != mass[j, i]]
    if potential is not None:
        potential = sympy.sympify(potential)
        _check_symbols(name, "potential", potential, q_set, declared, "the coordinates")
    point_names = tuple(str(key) for key in (points or {}))
    point_expressions: list[tuple[sympy.Expr, sympy.Expr]] = []
    for key, value in (points or {}).items():
        pair = _as_vector(f"points[{key!r}]", value, name, size=None)
        if len(pair) != 2:
            raise ModelError(f"model {name!r}: points[{key!r}] must be a pair (x(q), z(q)), got {value!r}")
        for axis, expression in zip("xz", pair):
            _check_symbols(name, f"points[{key!r}].{axis}", expression, q_set, declared, "the coordinates")
        point_expressions.append((pair[0], pair[1]))
    line_pairs = _lines(lines, point_names, name)
    q0_array = _initial_vector("q0", q0, n, name)
    qd0_array = _initial_vector("qd0", qd0, n, name)
    names = _names("constraint_names", constraint_names, [f"phi[{k}]" for k in range(m_holonomic)], name)
    names += _names("velocity_constraint_names", velocity_constraint_names,
                    [f"psi[{k}]" for k in range(len(psi))], name)
    if len(set(names)) != len(names):
        raise ModelError(f"model {name!r}: constraint_names and velocity_constraint_names share names: {list(names)}")
    mask = _driver_mask(drivers, names, name, [t in expression.free_symbols for expression in phi + psi])

    # ------------------------------------------------------------ derived terms
    # Differentiate in real symbols: with sympy's default (complex) symbols the derivative of
    # e.g. Abs(x) keeps unevaluated Derivative(re(x), x) terms.
    canonical = {"q": [sympy.Symbol(f"_q{i}", real=True) for i in range(n)],
                 "qd": [sympy.Symbol(f"_v{i}", real=True) for i in range(n)],
                 "t": [sympy.Symbol("_t", real=True)],
                 "u": [sympy.Symbol(f"_u{i}", real=True) for i in range(len(u))]}
    mapping = dict(zip(q + qd + [t] + u, sum(canonical.values(), [])))
    inverse = {value: key for key, value in mapping.items()}

    def real(expression: sympy.Expr) -> sympy.Expr:
        return sympy.sympify(expression).xreplace(mapping)

    q_r, qd_r, t_r = canonical["q"], canonical["qd"], canonical["t"][0]
    phi_r = sympy.Matrix(m_holonomic, 1, [real(expression) for expression in phi])
    qd_column = sympy.Matrix(n, 1, qd_r)
    A_r = phi_r.jacobian(q_r) if m_holonomic else sympy.zeros(0, n)
    phi_t_r = phi_r.diff(t_r) if m_holonomic else sympy.zeros(0, 1)
    phi_dot = A_r * qd_column + phi_t_r if m_holonomic else sympy.zeros(0, 1)
    gamma_r = -(phi_dot.jacobian(q_r) * qd_column + phi_dot.diff(t_r)) if m_holonomic else sympy.zeros(0, 1)
    if psi:
        # ψ = B q̇ + b: B = ∂ψ/∂q̇ (free of q̇), b = ψ at q̇ = 0, ψ̇ = B q̈ - γ with γ = -(ψ_q q̇ + ψ_t)
        psi_r = sympy.Matrix(len(psi), 1, [real(expression) for expression in psi])
        B_r = psi_r.jacobian(qd_r)
        velocity_set = set(qd_r)
        for row in range(B_r.rows):
            nonlinear = [inverse[v].name for v in qd_r if any(v in entry.free_symbols for entry in B_r.row(row))]
            if nonlinear:
                raise ModelError(f"model {name!r}: velocity_constraints[{row}] ({names[m_holonomic + row]!r}) is not "
                                 f"linear in the velocities (it is nonlinear in {', '.join(nonlinear)}): "
                                 f"{_short(psi[row])}; only B(q, t) q̇ + b(q, t) = 0 is supported")
        b_r = psi_r.xreplace({v: sympy.S.Zero for v in velocity_set})
        gamma_psi = -(psi_r.jacobian(q_r) * qd_column + psi_r.diff(t_r))
        A_r = A_r.col_join(B_r)
        phi_r = phi_r.col_join(sympy.zeros(len(psi), 1))
        phi_t_r = phi_t_r.col_join(b_r)
        gamma_r = gamma_r.col_join(gamma_psi)
    derived = []
    for label, matrix in (("jacobian", A_r), ("constraints_t", phi_t_r), ("gamma", gamma_r)):
        # derivatives of Abs, sign, Heaviside, Min, Max are taken almost everywhere
        matrix = matrix.replace(sympy.DiracDelta, lambda *args: sympy.S.Zero)
        for index, entry in enumerate(matrix):
            if entry.has(sympy.Derivative, sympy.Subs):
                raise ModelError(f"model {name!r}: {_index_label(label, index, matrix.shape)} of the "
                                 f"constraints could not be differentiated in closed form: {_short(entry)}")
        derived.append(matrix)
    A_r, phi_t_r, gamma_r = derived

    moving = [sympy.expand(rate) != 0 for rate in phi_t_r]          # rows with Φ_t ≠ 0 (b ≠ 0)
    sources = _work_sources(mass.xreplace(mapping), [real(e) for e in Q],
                            None if potential is None else real(potential), moving, names, mask, canonical)
    steady = frozenset(name for name, moves, driver in zip(names, moving, mask) if driver and not moves)
    constant = None
    if not any(entry.free_symbols for entry in mass):
        try:
            constant = np.array(mass.tolist(), dtype=float)
        except TypeError as error:
            raise ModelError(f"model {name!r}: mass_matrix is not real: {error}") from None
    equations = SympyEquations(name=name, n=n, m=m, n_u=len(u), symbols=canonical, inverse=inverse,
                               mass=mass.xreplace(mapping), forces=[real(e) for e in Q], phi=list(phi_r),
                               A=A_r, phi_t=list(phi_t_r), gamma=list(gamma_r),
                               potential=None if potential is None else real(potential),
                               points=[(real(a), real(b)) for a, b in point_expressions],
                               backend=backend, cache=cache, constant_mass=constant, rebuild=rebuild,
                               work_sources=sources, steady_drivers=steady)
    terms = _evaluate_at_q0(name, equations, q0_array, qd0_array, len(u))
    if asymmetric:
        _check_symmetric_sympy(name, equations, mass, asymmetric, q0_array)
    _check_mass(name, np.array(terms.M), q0_array, symmetric_tolerance=None)
    return Model(name=name, coordinate_names=tuple(symbol.name for symbol in q),
                 coordinate_kinds=kinds, constraint_names=names, drivers=mask,
                 actuator_names=tuple(symbol.name for symbol in u), q0=q0_array, qd0=qd0_array,
                 point_names=point_names, lines=line_pairs, equations=equations,
                 description=description, source=source,
                 parameters={"builder": "cmbs.model.equations.from_sympy", "mass_matrix": mass,
                             "forces": sympy.Matrix(n, 1, Q), "constraints": sympy.Matrix(m_holonomic, 1, phi),
                             "velocity_constraints": sympy.Matrix(len(psi), 1, psi),
                             "potential": potential, "backend": backend},
                 constant_mass=constant is not None,
                 nonholonomic=np.arange(m) >= m_holonomic)


#: size (expression-tree nodes) of a power balance above which it is not expanded or simplified
#: (its model's work sources are then left unstated unless a numeric evaluation shows power); the
#: 8-link chain in absolute angles has 1761
POWER_CHECK_NODES = 5000


def _work_sources(mass: sympy.Matrix, forces: list, potential: sympy.Expr | None, moving: list[bool],
                  names: tuple[str, ...], drivers: np.ndarray, symbols: dict[str, list]) -> tuple[str, ...] | None:
    """What does work on a :func:`from_sympy` model besides its drivers (see
    :attr:`cmbs.model.model.Model.work_sources`), from dE/dt with E = ½ q̇ᵀ M q̇ + V and
    M q̈ + Aᵀλ = Q, A q̇ = -Φ_t::

        dE/dt = P + λᵀ Φ_t,    P = q̇ᵀ (Q + ∂V/∂q) + ½ q̇ᵀ Ṁ q̇   (inputs u = 0).

    P is the power of the forces that V and the kinetic terms do not account for (dampers,
    applied forces; Q's gyroscopic and Coriolis terms contribute -½ q̇ᵀ Ṁ q̇ and cancel).  The
    forces are named when P is not identically zero: shown by a value at a random state;
    () when P simplifies to zero and no row but a driver is ``moving`` (Φ_t ≠ 0, or b ≠ 0 for a
    velocity constraint), those rows named otherwise; None when P can be shown neither way (it does not
    simplify, or is too large to try: :data:`POWER_CHECK_NODES`)."""
    q, qd, u = symbols["q"], symbols["qd"], symbols["u"]
    no_input = {symbol: sympy.S.Zero for symbol in u}
    gradient = [sympy.S.Zero] * len(q) if potential is None else [potential.diff(symbol) for symbol in q]
    velocity = sympy.Matrix(qd)
    kinetic = (velocity.T * mass * velocity)[0, 0] / 2      # ½ q̇ᵀ Ṁ q̇ = Σ_k q̇_k ∂T/∂q_k
    parts = [rate * (force.xreplace(no_input) + slope) for rate, force, slope in zip(qd, forces, gradient)]
    parts += [rate * kinetic.diff(symbol) for symbol, rate in zip(q, qd)]
    power = sympy.Add(*parts)
    sources = tuple(f"rheonomic constraint {name!r}" for name, moves, driver in zip(names, moving, drivers)
                    if moves and not driver)
    small = sum(1 for _ in sympy.preorder_traversal(power)) <= POWER_CHECK_NODES
    if small and sympy.expand(power) == 0:
        return sources
    if _shows_power(parts, [*q, *qd, *symbols["t"]]):
        return ("forces (q̇ᵀ(Q + ∂V/∂q) + ½ q̇ᵀṀq̇ ≠ 0)", *sources)
    return sources if small and sympy.simplify(power) == 0 else None


def _shows_power(parts: list, arguments: list) -> bool:
    """True when the sum of ``parts`` is clearly nonzero at one of a few random states: more than
    1e-6 of the sum of their magnitudes, far beyond rounding."""
    function = sympy.lambdify(arguments, parts, modules="numpy")
    generator = np.random.default_rng(20)
    for _ in range(3):
        with np.errstate(all="ignore"):
            try:
                values = np.array(function(*generator.uniform(0.3, 1.7, size=len(arguments))), dtype=float)
            except Exception:  # noqa: BLE001 - a generated function may fail in many ways at a random state
                continue
        if np.all(np.isfinite(values)) and abs(values.sum()) > 1e-6 * np.abs(values).sum():
            return True
    return False


def _default_velocities(q: list[sympy.Symbol], forces: object, model: str,
                        velocity_constraints: object = None) -> list[sympy.Symbol]:
    """The symbols named ``f"{q}_d"`` that ``forces`` or ``velocity_constraints`` use (whatever
    their assumptions), else new plain symbols of those names."""
    found = []
    for source in (forces, velocity_constraints):
        if source is None:
            continue
        try:
            found += [symbol for entry in sympy.Matrix(source) for symbol in sympy.sympify(entry).free_symbols]
        except (TypeError, ValueError, sympy.SympifyError):
            pass  # the shape checks report the problem
    velocities = []
    for symbol in q:
        wanted = f"{symbol.name}_d"
        matches = sorted({s for s in found if isinstance(s, sympy.Symbol) and s.name == wanted},
                         key=lambda s: str(s.assumptions0))
        if len(matches) > 1:
            raise ModelError(f"model {model!r}: forces or velocity_constraints use several different symbols "
                             f"named {wanted!r} (assumptions {[m.assumptions0 for m in matches]}); pass velocities")
        velocities.append(matches[0] if matches else sympy.Symbol(wanted))
    return velocities


def _short(expression: object, limit: int = 160) -> str:
    text = str(expression)
    return text if len(text) <= limit else text[:limit - 5] + " ..."


def _check_symmetric_sympy(name: str, equations: "SympyEquations", mass: sympy.Matrix,
                           pairs: list[tuple[int, int]], q0: np.ndarray) -> None:
    """Entries that differ symbolically (float coefficients defeat ``simplify``) must agree
    numerically, to 1e-12 relative, at q0 and at 8 pseudo-random configurations near it."""
    rng = np.random.default_rng(7)
    samples = [q0] + [q0 + rng.uniform(-1.0, 1.0, q0.size) for _ in range(8)]
    for q in samples:
        try:
            values = equations.mass_matrix(q)
        except (ArithmeticError, ValueError):
            continue  # outside the domain of M: only points where it is defined count
        scale = max(1.0, float(np.max(np.abs(values))))
        for i, j in pairs:
            if abs(values[i, j] - values[j, i]) > 1e-12 * scale:
                raise ModelError(f"model {name!r}: mass_matrix is not symmetric: at q = {q.tolist()}, "
                                 f"M[{i}, {j}] = {values[i, j]!r} but M[{j}, {i}] = {values[j, i]!r} "
                                 f"(M[{i}, {j}] = {_short(mass[i, j])}, M[{j}, {i}] = {_short(mass[j, i])})")


def _evaluate_at_q0(name: str, equations, q0: np.ndarray, qd0: np.ndarray, n_u: int) -> Terms:
    terms = equations.new_terms()
    try:
        equations.evaluate(q0, qd0, 0.0, np.zeros(n_u), terms)
        equations.potential_energy(q0)
        equations.point_positions(q0)
    except ModelError:
        raise
    except Exception as error:  # noqa: BLE001 - any failure of user equations is reported as such
        raise ModelError(f"model {name!r}: evaluating the equations at q0 = {q0.tolist()}, "
                         f"qd0 = {qd0.tolist()}, t = 0 failed: {type(error).__name__}: {error}") from error
    for label in ("Q", "phi", "A", "gamma", "phi_t", "M"):
        values = getattr(terms, label)
        if not np.all(np.isfinite(values)):
            raise ModelError(f"model {name!r}: {label} is not finite at q0 = {q0.tolist()}, "
                             f"qd0 = {qd0.tolist()}, t = 0: {np.asarray(values).tolist()}")
    return terms


# ====================================================================== callables
class CallableEquations:
    """Evaluators of a :func:`from_callables` model (implements ``ModelEquations``)."""

    def __init__(self, *, n: int, m: int, n_u: int, mass_matrix: Callable, forces: Callable,
                 constraints: Callable | None, jacobian: Callable, gamma: Callable,
                 constraints_t: Callable | None, potential: Callable | None, points: Callable | None,
                 n_points: int, m_velocity: int = 0, velocity_constraints: Callable | None = None,
                 velocity_gamma: Callable | None = None, work_sources: tuple[str, ...] | None = None) -> None:
        """``m`` holonomic rows, then ``m_velocity`` nonholonomic rows from
        ``velocity_constraints(q, t) -> (B, b)`` and ``velocity_gamma(q, qd, t)``;
        ``work_sources`` () when the user states the model conservative (:func:`from_callables`),
        else None (not known)."""
        self.n, self.m_holonomic, self.m_velocity, self.n_u = n, m, m_velocity, n_u
        self.work_sources = work_sources
        self.m = m + m_velocity
        self._mass, self._forces = mass_matrix, forces
        self._phi, self._A, self._gamma, self._phi_t = constraints, jacobian, gamma, constraints_t
        self._psi, self._psi_gamma = velocity_constraints, velocity_gamma
        self._potential, self._points, self.n_points = potential, points, n_points

    def new_terms(self) -> Terms:
        return Terms(self.n, self.m)

    def evaluate(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray, terms: Terms) -> None:
        """Call the user functions at ``(q, q̇, t, u)`` and copy their results into ``terms``."""
        terms.M[...] = self._mass(q)
        terms.Q[...] = self._forces(q, qd, t, u)
        h = self.m_holonomic
        if h:
            terms.phi[:h] = self._phi(q, t)
            terms.A[:h] = self._A(q, t)
            terms.gamma[:h] = self._gamma(q, qd, t)
            if self._phi_t is not None:
                terms.phi_t[:h] = self._phi_t(q, t)
            else:
                terms.phi_t[:h] = 0.0
        if self.m_velocity:
            B, b = self._psi(q, t)
            terms.phi[h:] = 0.0
            terms.A[h:] = B
            terms.phi_t[h:] = b
            terms.gamma[h:] = self._psi_gamma(q, qd, t)

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        """T = ½ q̇ᵀ M(q) q̇."""
        return 0.5 * float(qd @ np.asarray(self._mass(q), dtype=float) @ qd)

    def potential_energy(self, q: np.ndarray) -> float:
        """V(q) from the user function; 0.0 when none was given."""
        return 0.0 if self._potential is None else float(self._potential(q))

    def point_positions(self, q: np.ndarray) -> np.ndarray:
        """(n_points, 2) positions; an empty (0, 2) array when no points function was given."""
        if self._points is None:
            return np.zeros((0, 2))
        return np.asarray(self._points(q), dtype=float).reshape(self.n_points, 2)


def _difference_jacobian(phi: Callable, h: float) -> Callable:
    def jacobian(q: np.ndarray, t: float) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        columns = []
        for i in range(q.size):
            step = h * max(1.0, abs(q[i]))
            plus, minus = q.copy(), q.copy()
            plus[i] += step
            minus[i] -= step
            columns.append((np.asarray(phi(plus, t), float) - np.asarray(phi(minus, t), float)) / (2 * step))
        return np.stack(columns, axis=1)
    return jacobian


def _difference_gamma(phi: Callable, h: float) -> Callable:
    """γ = -d²/ds² Φ(q + s q̇, t + s) at s = 0 (the path with q̈ = 0, so Φ̈ = -γ)."""
    def gamma(q: np.ndarray, qd: np.ndarray, t: float) -> np.ndarray:
        q, qd = np.asarray(q, dtype=float), np.asarray(qd, dtype=float)
        scale = max(1.0, float(np.max(np.abs(qd), initial=0.0)))
        s = h / scale
        plus = np.asarray(phi(q + s * qd, t + s), float)
        minus = np.asarray(phi(q - s * qd, t - s), float)
        centre = np.asarray(phi(q, t), float)
        return -(plus - 2.0 * centre + minus) / (s * s)
    return gamma


def _difference_phi_t(phi: Callable, h: float) -> Callable:
    def phi_t(q: np.ndarray, t: float) -> np.ndarray:
        step = h * max(1.0, abs(t))
        return (np.asarray(phi(q, t + step), float) - np.asarray(phi(q, t - step), float)) / (2 * step)
    return phi_t


def _difference_velocity_gamma(velocity_constraints: Callable, h: float) -> Callable:
    """γ = -d/ds ψ(q + s q̇, q̇, t + s) at s = 0 with ψ = B q̇ + b (the path with q̈ = 0)."""
    def gamma(q: np.ndarray, qd: np.ndarray, t: float) -> np.ndarray:
        q, qd = np.asarray(q, dtype=float), np.asarray(qd, dtype=float)
        s = h / max(1.0, float(np.max(np.abs(qd), initial=0.0)))

        def psi(step: float) -> np.ndarray:
            B, b = velocity_constraints(q + step * qd, t + step)
            return np.asarray(B, float) @ qd + np.asarray(b, float)

        return -(psi(s) - psi(-s)) / (2.0 * s)
    return gamma


def from_callables(name: str, *, coordinate_names: Sequence[str],
                   mass_matrix: Callable[[np.ndarray], np.ndarray],
                   forces: Callable[[np.ndarray, np.ndarray, float, np.ndarray], np.ndarray],
                   constraints: Callable[[np.ndarray, float], np.ndarray] | None = None,
                   jacobian: Callable[[np.ndarray, float], np.ndarray] | None = None,
                   gamma: Callable[[np.ndarray, np.ndarray, float], np.ndarray] | None = None,
                   constraints_t: Callable[[np.ndarray, float], np.ndarray] | None = None,
                   n_constraints: int | None = None,
                   n_inputs: int = 0,
                   input_names: Sequence[str] | None = None,
                   drivers: Sequence[str | int] | None = None,
                   potential: Callable[[np.ndarray], float] | None = None,
                   points: Callable[[np.ndarray], np.ndarray] | None = None,
                   point_names: Sequence[str] = (),
                   lines: Sequence[tuple[int | str, int | str]] = (),
                   q0: Sequence[float] | None = None,
                   qd0: Sequence[float] | None = None,
                   description: str = "",
                   source: str = "",
                   constraint_names: Sequence[str] | None = None,
                   velocity_constraints: Callable[[np.ndarray, float], tuple[np.ndarray, np.ndarray]] | None = None,
                   velocity_gamma: Callable[[np.ndarray, np.ndarray, float], np.ndarray] | None = None,
                   velocity_constraint_names: Sequence[str] | None = None,
                   finite_differences: bool = False,
                   check: bool = True,
                   conservative: bool = False) -> Model:
    """A :class:`Model` from Python functions of the equations of motion (THEORY §1).

    Every function receives float64 numpy arrays (and a float ``t``) and returns array-likes:
    ``mass_matrix(q) -> (n, n)``, ``forces(q, qd, t, u) -> (n,)`` (``u`` has ``n_inputs``
    entries, empty if none), ``constraints(q, t) -> (m,)``, ``jacobian(q, t) -> (m, n)``,
    ``gamma(q, qd, t) -> (m,)`` with ``A q̈ = γ = -(Ȧ q̇) - 2 Φ_qt q̇ - Φ_tt``,
    ``constraints_t(q, t) -> (m,)`` (zeros if None: scleronomic constraints),
    ``potential(q) -> float`` (V = 0.0 if None), ``points(q) -> (k, 2)``.

    Parameters
    ----------
    n_constraints
        m; taken from ``constraints(q0, 0)`` if None (and checked against it otherwise).
    velocity_constraints, velocity_gamma, velocity_constraint_names
        Nonholonomic constraints ``B(q, t) q̇ + b(q, t) = 0``: ``velocity_constraints(q, t) ->
        (B (k, n), b (k,))`` and ``velocity_gamma(q, qd, t) -> (k,)`` with ``B q̈ = γ``, i.e.
        ``γ = -(dB/dt) q̇ - ḃ`` (by central differences of ψ = B q̇ + b along q + s q̇, t + s
        when None and ``finite_differences``); names ``"psi[k]"`` if None.  The rows follow
        the holonomic ones and are marked in :attr:`Model.nonholonomic`.
    drivers
        The driver rows by constraint name or row index (holonomic rows first, then velocity
        constraints); none if None.
    point_names
        Names of the k points returned by ``points`` (``"p0"``, ... if empty).
    finite_differences
        If False (default) ``jacobian`` and ``gamma`` are required with ``constraints``.  If True,
        missing ones are computed from ``constraints`` by central differences: ``A`` with
        relative step 1e-6 (error ~1e-10 relative), ``γ = -d²/ds² Φ(q + s q̇, t + s)`` with step
        1e-4 (error ~1e-7 relative: Φ̈ = A q̈ - γ is then satisfied only to that accuracy, which
        shows as constraint drift), and ``Φ_t`` too when ``constraints_t`` is None.  This costs
        2n + 3 (+2) calls of ``constraints`` per evaluation.  A missing ``velocity_gamma`` is
        computed likewise (step 1e-5, 2 calls of ``velocity_constraints``).
    conservative
        Your statement that with zero inputs nothing but ``potential`` does work: ``forces`` is
        -∂V/∂q plus forces that do no work (such as gyroscopic ones), and no constraint but a
        driver moves.  cmbs cannot check Python functions for it, so by default their runs are
        not judged by their energy; with True, :attr:`Model.work_sources` lists only the
        drivers, and runs with zero inputs and no driver report their energy drift (a drift
        then means integration error, or that the statement is wrong).
    check
        At build, compare the given ``jacobian``, ``gamma``, ``constraints_t`` and
        ``velocity_gamma`` with finite differences at ``(q0, q̇, 0)`` (q̇ a fixed pseudo-random
        vector) and raise :class:`ModelError` when they disagree by more than 1e-4 relative; and reject
        ``constraints`` that change with t when ``constraints_t`` is None.

    Raises
    ------
    ModelError
        Missing ``jacobian``/``gamma``, a function returning the wrong shape or a non-finite
        value at q0, a non-symmetric M or one not positive definite at q0, inconsistent
        derivatives (``check``), bad names.
    """
    n = len(coordinate_names)
    if n == 0:
        raise ModelError(f"model {name!r}: coordinate_names is empty; at least one coordinate is needed")
    coordinate_names = tuple(str(c) for c in coordinate_names)
    q0_array = _initial_vector("q0", q0, n, name)
    qd0_array = _initial_vector("qd0", qd0, n, name)
    for label, function in (("mass_matrix", mass_matrix), ("forces", forces), ("constraints", constraints),
                            ("jacobian", jacobian), ("gamma", gamma), ("constraints_t", constraints_t),
                            ("potential", potential), ("points", points),
                            ("velocity_constraints", velocity_constraints), ("velocity_gamma", velocity_gamma)):
        if function is not None and not callable(function):
            raise ModelError(f"model {name!r}: {label} must be callable, got {function!r}")
    if isinstance(n_inputs, bool) or not isinstance(n_inputs, (int, np.integer)) or n_inputs < 0:
        raise ModelError(f"model {name!r}: n_inputs must be a non-negative integer, got {n_inputs!r}")
    actuator_names = _names("input_names", input_names, [f"u[{k}]" for k in range(n_inputs)], name)

    def call(label: str, function: Callable, *arguments: object) -> np.ndarray:
        try:
            value = np.asarray(function(*arguments), dtype=float)
        except Exception as error:  # noqa: BLE001 - any failure of user code is reported as such
            raise ModelError(f"model {name!r}: {label} failed at q0 = {q0_array.tolist()}: "
                             f"{type(error).__name__}: {error}") from error
        if not np.all(np.isfinite(value)):
            raise ModelError(f"model {name!r}: {label} is not finite at q0 = {q0_array.tolist()}: {value.tolist()}")
        return value

    def expect(label: str, value: np.ndarray, shape: tuple[int, ...]) -> None:
        if value.shape != shape:
            raise ModelError(f"model {name!r}: {label} returned shape {value.shape}, expected {shape}")

    u0 = np.zeros(n_inputs)
    _check_mass(name, call("mass_matrix", mass_matrix, q0_array.copy()), q0_array, symmetric_tolerance=1e-12)
    expect("forces", call("forces", forces, q0_array.copy(), qd0_array.copy(), 0.0, u0), (n,))

    m = 0
    if constraints is None:
        for label, function in (("jacobian", jacobian), ("gamma", gamma), ("constraints_t", constraints_t)):
            if function is not None:
                raise ModelError(f"model {name!r}: {label} is given but constraints is None")
        if n_constraints:
            raise ModelError(f"model {name!r}: n_constraints = {n_constraints} but constraints is None")
    else:
        phi0 = call("constraints", constraints, q0_array.copy(), 0.0)
        if phi0.ndim != 1:
            raise ModelError(f"model {name!r}: constraints returned shape {phi0.shape}, expected (m,)")
        m = phi0.size
        if n_constraints is not None and n_constraints != m:
            raise ModelError(f"model {name!r}: constraints returned {m} values but n_constraints = {n_constraints}")
        missing = [label for label, function in (("jacobian", jacobian), ("gamma", gamma)) if function is None]
        if missing and not finite_differences:
            raise ModelError(f"model {name!r}: constraints is given without {' and '.join(missing)}; "
                             f"pass them (A = Φ_q and γ with A q̈ = γ) or finite_differences=True")
        if check and constraints_t is None and not finite_differences:
            later = call("constraints", constraints, q0_array.copy(), 0.731)
            if not np.allclose(later, phi0, rtol=1e-12, atol=1e-12):
                raise ModelError(f"model {name!r}: constraints depend on time (Φ(q0, 0) ≠ Φ(q0, 0.731)) "
                                 f"but constraints_t is None (None means scleronomic); pass constraints_t")
    if m:
        jacobian_fd = _difference_jacobian(constraints, 1e-6)
        gamma_fd = _difference_gamma(constraints, 1e-4)
        phi_t_fd = _difference_phi_t(constraints, 1e-6)
        if finite_differences:
            jacobian = jacobian or jacobian_fd
            gamma = gamma or gamma_fd
            constraints_t = constraints_t or phi_t_fd
        A0 = call("jacobian", jacobian, q0_array.copy(), 0.0)
        expect("jacobian", A0, (m, n))
        expect("gamma", call("gamma", gamma, q0_array.copy(), qd0_array.copy(), 0.0), (m,))
        if constraints_t is not None:
            expect("constraints_t", call("constraints_t", constraints_t, q0_array.copy(), 0.0), (m,))
        if check:
            rng = np.random.default_rng(20240613)
            qd_test = rng.uniform(-1.0, 1.0, n) * max(1.0, float(np.max(np.abs(qd0_array))))
            comparisons = [("jacobian", A0, jacobian_fd(q0_array, 0.0)),
                           ("gamma", call("gamma", gamma, q0_array.copy(), qd_test.copy(), 0.0),
                            gamma_fd(q0_array, qd_test, 0.0))]
            if constraints_t is not None:
                comparisons.append(("constraints_t", call("constraints_t", constraints_t, q0_array.copy(), 0.0),
                                    phi_t_fd(q0_array, 0.0)))
            for label, given, estimate in comparisons:
                scale = 1.0 + float(np.max(np.abs(estimate), initial=0.0))
                error = float(np.max(np.abs(given - estimate), initial=0.0))
                if error > 1e-4 * scale:
                    raise ModelError(f"model {name!r}: {label} disagrees with finite differences of "
                                     f"constraints at q0 = {q0_array.tolist()} (max difference {error:.3g}): "
                                     f"given {given.tolist()}, estimated {estimate.tolist()}; "
                                     f"check it or pass check=False")
    m_velocity = 0
    if velocity_constraints is None:
        if velocity_gamma is not None:
            raise ModelError(f"model {name!r}: velocity_gamma is given but velocity_constraints is None")
    else:
        try:
            pair = velocity_constraints(q0_array.copy(), 0.0)
        except Exception as error:  # noqa: BLE001 - any failure of user code is reported as such
            raise ModelError(f"model {name!r}: velocity_constraints failed at q0 = {q0_array.tolist()}: "
                             f"{type(error).__name__}: {error}") from error
        if not isinstance(pair, (tuple, list)) or len(pair) != 2:
            raise ModelError(f"model {name!r}: velocity_constraints must return a pair (B, b), got {pair!r}")
        B0 = call("velocity_constraints B", lambda: pair[0])
        b0 = call("velocity_constraints b", lambda: pair[1])
        if B0.ndim != 2 or B0.shape[1] != n:
            raise ModelError(f"model {name!r}: velocity_constraints returned B of shape {B0.shape}, expected (k, {n})")
        m_velocity = B0.shape[0]
        expect("velocity_constraints b", b0, (m_velocity,))
        gamma_velocity_fd = _difference_velocity_gamma(velocity_constraints, 1e-5)
        if velocity_gamma is None:
            if not finite_differences:
                raise ModelError(f"model {name!r}: velocity_constraints is given without velocity_gamma; pass it "
                                 f"(B q̈ = γ = -(dB/dt) q̇ - ḃ) or finite_differences=True")
            velocity_gamma = gamma_velocity_fd
        expect("velocity_gamma", call("velocity_gamma", velocity_gamma, q0_array.copy(), qd0_array.copy(), 0.0),
               (m_velocity,))
        if check:
            rng = np.random.default_rng(20240614)
            qd_test = rng.uniform(-1.0, 1.0, n) * max(1.0, float(np.max(np.abs(qd0_array))))
            given = call("velocity_gamma", velocity_gamma, q0_array.copy(), qd_test.copy(), 0.0)
            estimate = gamma_velocity_fd(q0_array, qd_test, 0.0)
            error = float(np.max(np.abs(given - estimate), initial=0.0))
            if error > 1e-4 * (1.0 + float(np.max(np.abs(estimate), initial=0.0))):
                raise ModelError(f"model {name!r}: velocity_gamma disagrees with finite differences of "
                                 f"velocity_constraints at q0 = {q0_array.tolist()} (max difference {error:.3g}): "
                                 f"given {given.tolist()}, estimated {estimate.tolist()}; "
                                 f"check it or pass check=False")
    names = _names("constraint_names", constraint_names, [f"phi[{k}]" for k in range(m)], name)
    names += _names("velocity_constraint_names", velocity_constraint_names,
                    [f"psi[{k}]" for k in range(m_velocity)], name)
    if len(set(names)) != len(names):
        raise ModelError(f"model {name!r}: constraint_names and velocity_constraint_names share names: {list(names)}")
    mask = _driver_mask(drivers, names, name)

    n_points = 0
    if points is not None:
        positions = call("points", points, q0_array.copy())
        if positions.ndim != 2 or positions.shape[1] != 2:
            raise ModelError(f"model {name!r}: points returned shape {positions.shape}, expected (k, 2)")
        n_points = positions.shape[0]
    point_names = _names("point_names", point_names or None, [f"p{k}" for k in range(n_points)], name)
    line_pairs = _lines(lines, point_names, name)
    if potential is not None:
        value = call("potential", potential, q0_array.copy())
        if value.shape not in ((), (1,)):
            raise ModelError(f"model {name!r}: potential returned shape {value.shape}, expected a scalar")

    equations = CallableEquations(n=n, m=m, n_u=n_inputs, mass_matrix=mass_matrix, forces=forces,
                                  constraints=constraints, jacobian=jacobian, gamma=gamma,
                                  constraints_t=constraints_t, potential=potential, points=points,
                                  n_points=n_points, m_velocity=m_velocity,
                                  velocity_constraints=velocity_constraints, velocity_gamma=velocity_gamma,
                                  work_sources=() if conservative else None)
    return Model(name=name, coordinate_names=coordinate_names, coordinate_kinds=("generic",) * n,
                 constraint_names=names, drivers=mask, actuator_names=actuator_names, q0=q0_array,
                 qd0=qd0_array, point_names=point_names, lines=line_pairs, equations=equations,
                 description=description, source=source,
                 parameters={"builder": "cmbs.model.equations.from_callables",
                             "finite_differences": finite_differences},
                 constant_mass=False, nonholonomic=np.arange(m + m_velocity) >= m)
