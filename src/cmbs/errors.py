"""The one exception hierarchy of cmbs.

Every message names the item at fault, what was expected and what was received, so that a
user reading one line can fix the model file or the call.  The command-line interface turns
:class:`CmbsError` into a one-line message and exit status 2 (user mistake) or 1 (a run that
failed, e.g. a non-convergent assembly of a valid model).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Sequence


class CmbsError(Exception):
    """Base class of every error cmbs raises on purpose."""

    exit_status = 2


class ModelError(CmbsError):
    """A model definition is invalid: unknown name, duplicate, bad value, bad expression.

    Parameters
    ----------
    message
        What is wrong and what was expected.
    source
        The file (or builder) the definition came from, if any.
    entry
        The entry at fault, e.g. ``segment 'crank'`` or ``driver 'alpha-drive'.expression``.
    """

    def __init__(self, message: str, *, source: str | None = None, entry: str | None = None):
        self.problem = message
        self.source = source
        self.entry = entry
        super().__init__(self._format())

    def _format(self) -> str:
        where = ": ".join(part for part in (self.source, self.entry) if part)
        return f"{where}: {self.problem}" if where else self.problem

    def located(self, source: str | None = None, entry: str | None = None) -> "ModelError":
        """Return a copy that also names the file and/or entry (keeps the ones already set)."""
        return type(self)(self.problem, source=self.source or source, entry=self.entry or entry)


class ExpressionError(ModelError):
    """A time expression could not be parsed (see :mod:`cmbs.model.expressions`)."""


class ConvergenceError(CmbsError):
    """A Newton iteration (assembly, implicit step) did not converge within its limits."""

    exit_status = 1


class SingularSystemError(CmbsError):
    """A linear system is singular: redundant constraints or a singular configuration."""

    exit_status = 1


def did_you_mean(name: str | Sequence[str], choices: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` for the choice closest to a misspelt ``name``: one that differs
    in case only, else the closest by difflib's ratio (at least 0.6); an empty string when none
    is close.  Given a list of unknown names, a suggestion only when it holds one."""
    if not isinstance(name, str):
        if len(name) != 1:
            return ""
        name = name[0]
    choices = list(choices)
    close = [choice for choice in choices if choice.lower() == name.lower()] or \
        difflib.get_close_matches(name, choices, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def check_in_range(values: Iterable[float], what: str) -> None:
    """CmbsError naming ``what`` unless every value is at most
    :data:`cmbs.model.limits.MAX_MAGNITUDE` in magnitude (the bound of a model's numbers)."""
    from cmbs.model.limits import MAX_MAGNITUDE

    for value in values:
        if abs(value) > MAX_MAGNITUDE:
            raise CmbsError(f"{what}: {value:g} is out of range: values must be <= {MAX_MAGNITUDE:g} in magnitude")


class CmbsWarning(UserWarning):
    """Something cmbs works around and says so (e.g. a robot link's mesh file that cannot be read
    is drawn as a stick figure); the command-line interface prints it as one line."""
