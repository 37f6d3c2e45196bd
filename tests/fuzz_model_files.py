"""A model-file fuzzer: mutants of the library's TOML models and of the examples of
docs/model-format.md go through ``cmbs describe`` and, when they load, a very short
``cmbs simulate``; anything that escapes as an exception other than :class:`cmbs.CmbsError` is
an *uncaught exception* (a traceback for the user).  The target is 0.

Mutations (1 to 3 per mutant, chosen by a seeded generator): delete a key, an entry or a
section; copy an entry under a new name; replace a value by another type, by an extreme number
(0, -1, 1e-320, 1e200, inf, nan, a 30-digit integer, ...), by a huge or odd string or an
expression that misbehaves; rename an entry so that references to it break; add an unknown
key or section; empty an entry; and on the text: truncate, delete or duplicate a line, insert
garbage, or replace it all (empty file, binary bytes).

Run: ``python -m tests.fuzz_model_files --count 5000 [--seed 1] [--keep DIR]`` (DIR receives
each mutant that raised an uncaught exception); tests/test_fuzz_model_files.py runs a small
count with a fixed seed.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import io
import json
import math
import re
import signal
import sys
import tempfile
import tomllib
import traceback
import warnings
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
LIBRARY = ROOT / "src" / "cmbs" / "library"
DOC = ROOT / "docs" / "model-format.md"
FENCE = re.compile(r"^```(\w+)[ \t]*\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)
FILE_LINE = re.compile(r"# file: (\S+)")

#: replacement values: extreme numbers, other types, odd strings and expressions
EXTREME_NUMBERS = [0, 0.0, -0.0, -1, -1.0, 1e-320, 1e-13, 1e-300, 1e12, 1e13, 1e200, -1e200, 1.7e308,
                   math.inf, -math.inf, math.nan, 10**30, -(10**30), 2**63 - 1]
OTHER_VALUES = [True, False, "", "x", "O", "P", "crank", "t", [], [1], [1, 2, 3], ["a", "b"], [1.0, "a"],
                [math.nan, 0.0], [1e200, 1e200], {}, {"x": 1}, {"t": [0, 1], "value": [0, 1]},
                {"t": [], "value": []}, {"t": [1, 0], "value": [0, 1]}, {"t": [0, 1], "value": [math.inf, 0]}]
#: factors of a number: a mechanism of another size or sign, or nearly degenerate
SCALES = [-1, 0, 0.5, 2, 10, 1e3, 1e6, 1e-3, 1e-6, 1e-9, 1e11]
ODD_STRINGS = ["x" * 10000, "é∂∑" * 50, "../../../etc/passwd", "a" * 300 + ".csv", "\u0000", "1/t", "1/(t-0.001)",
               "t**1e10", "exp(exp(exp(t)))", "sqrt(-1)", "sin(", "__import__('os')", "t" + "+t" * 2000,
               "log(0)", "1e308*1e308", "((((((((((t))))))))))" * 20, "sin(t", "asin(2)", "t^2", "0/0"]
GARBAGE = ["[[[", "= 1", "x = ", "[points]\n[points]", "\x00\x01\x02", "key = 'unterminated", "a.b.c = {",
           "ö = 1", "[segments.x]\npoints = [\"A\"", "inf = nan"]


@dataclass
class Report:
    """The outcome of a fuzzing run: counts by exit status and the uncaught exceptions."""

    count: int = 0
    statuses: Counter = field(default_factory=Counter)
    uncaught: list[tuple[str, str, str]] = field(default_factory=list)    # (mutations, error, traceback tail)
    timeouts: list[str] = field(default_factory=list)
    warned: list[tuple[str, str]] = field(default_factory=list)    # (mutations, first RuntimeWarning)

    def summary(self) -> str:
        kinds = Counter(error.split(":", 1)[0] for _, error, _ in self.uncaught)
        lines = [f"{self.count} mutants: exit status {dict(sorted(self.statuses.items()))}; "
                 f"{len(self.uncaught)} uncaught exception(s); {len(self.timeouts)} timeout(s); "
                 f"{len(self.warned)} with a RuntimeWarning"]
        lines += [f"  {count} x {kind}" for kind, count in kinds.most_common()]
        return "\n".join(lines)


# ------------------------------------------------------------------------------------ seeds
def seeds() -> list[tuple[str, str]]:
    """(name, text) of every library TOML model and every ```toml example of the format doc."""
    found = [(path.name, path.read_text()) for path in sorted(LIBRARY.glob("*.toml"))]
    text = DOC.read_text()
    for match in FENCE.finditer(text):
        if match.group(1) == "toml":
            found.append((f"model-format.md:{text.count(chr(10), 0, match.start()) + 1}", match.group(2)))
    return found


def csv_files() -> list[tuple[str, str]]:
    """(name, text) of the ```csv blocks of the format doc that examples read (``# file: NAME``)."""
    text = DOC.read_text()
    files = []
    for match in FENCE.finditer(text):
        first = match.group(2).splitlines()[0] if match.group(2) else ""
        if match.group(1) == "csv" and FILE_LINE.fullmatch(first):
            files.append((FILE_LINE.fullmatch(first).group(1), match.group(2)))
    return files


# ------------------------------------------------------------------------------------ TOML out
def toml_text(document: dict) -> str:
    """``document`` as TOML: top-level scalars, then one [table] per dict of non-dict values,
    deeper dicts inline."""
    lines = [f"{_key(key)} = {_value(value)}" for key, value in document.items() if not isinstance(value, dict)]
    _tables(document, [], lines)
    return "\n".join(lines) + "\n"


def _tables(table: dict, path: list[str], lines: list[str]) -> None:
    for key, value in table.items():
        if not isinstance(value, dict):
            continue
        here = path + [key]
        plain = {k: v for k, v in value.items() if not _is_table_of_tables(v)}
        if plain or not value:
            lines.append(f"[{'.'.join(_key(part) for part in here)}]")
            lines.extend(f"{_key(k)} = {_value(v)}" for k, v in plain.items())
        _tables({k: v for k, v in value.items() if _is_table_of_tables(v)}, here, lines)


def _is_table_of_tables(value: object) -> bool:
    """A dict that holds dicts (written as [a.b] headers; a dict of scalars is written inline
    when it is the value of a key of a table)."""
    return isinstance(value, dict) and any(isinstance(v, dict) for v in value.values()) and len(value) > 0 and \
        all(isinstance(v, dict) for v in value.values())


def _key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key, ensure_ascii=False)


def _value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(_value(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"no TOML for {value!r}")


# ------------------------------------------------------------------------------------ mutations
def _leaves(document: dict, path: tuple = ()) -> list[tuple]:
    """Paths (tuples of keys) of every value that is not a dict, and of every dict."""
    found = []
    for key, value in document.items():
        found.append(path + (key,))
        if isinstance(value, dict):
            found.extend(_leaves(value, path + (key,)))
    return found


def _numbers(document: dict) -> list[tuple[tuple, int | None]]:
    """(path, None) of every number, (path, index) of every number in a list."""
    found = []
    for path in _leaves(document):
        value = _parent(document, path)[path[-1]]
        if _is_number(value):
            found.append((path, None))
        elif isinstance(value, list):
            found.extend((path, k) for k, item in enumerate(value) if _is_number(item))
    return found


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _parent(document: dict, path: tuple) -> dict:
    for key in path[:-1]:
        document = document[key]
    return document


def _pick(rng: np.random.Generator, items: list):
    return items[int(rng.integers(len(items)))]


def _replacement(rng: np.random.Generator) -> object:
    pool = _pick(rng, [EXTREME_NUMBERS, OTHER_VALUES, ODD_STRINGS])
    return copy.deepcopy(_pick(rng, pool))


def mutate_document(document: dict, rng: np.random.Generator) -> str:
    """Apply one structural mutation to ``document`` in place; its description."""
    paths = _leaves(document)
    kind = _pick(rng, ["delete", "replace", "replace", "copy-entry", "rename", "unknown-key", "empty-entry",
                       "replace-number", "replace-number", "scale-number", "scale-number", "scale-number"])
    if not paths:
        document["points"] = {"A": {"x": 0.0, "z": 0.0}}
        return "add a point to an empty document"
    path = _pick(rng, paths)
    parent = _parent(document, path)
    if kind == "delete":
        del parent[path[-1]]
        return f"delete {'.'.join(path)}"
    if kind in ("replace-number", "scale-number"):
        numeric = _numbers(document)
        if not numeric:
            return "no number to change"
        path, index = _pick(rng, numeric)
        parent = _parent(document, path)
        holder, key = (parent[path[-1]], index) if index is not None else (parent, path[-1])
        value = _pick(rng, EXTREME_NUMBERS) if kind == "replace-number" else \
            holder[key] * _pick(rng, SCALES)
        holder[key] = value
        return f"{'.'.join(path)}{'' if index is None else f'[{index}]'} = {value!r}"
    if kind == "replace":
        value = _replacement(rng)
        parent[path[-1]] = value
        return f"{'.'.join(path)} = {str(value)[:40]!r}"
    if kind == "copy-entry":
        parent[f"{path[-1]}_copy"] = copy.deepcopy(parent[path[-1]])
        return f"copy {'.'.join(path)}"
    if kind == "rename":
        new = _pick(rng, ["renamed", "", " ", "a.b", "O", "P", "crank", "x" * 200])
        parent[new] = parent.pop(path[-1])
        return f"rename {'.'.join(path)} -> {new!r}"
    if kind == "unknown-key":
        target = parent[path[-1]] if isinstance(parent[path[-1]], dict) else parent
        target[_pick(rng, ["colour", "mass", "x", "points", "bodies", "wheels"])] = _replacement(rng)
        return f"add a key under {'.'.join(path)}"
    parent[path[-1]] = {}
    return f"empty {'.'.join(path)}"


def mutate_text(text: str, rng: np.random.Generator) -> tuple[str, str]:
    """One textual mutation of ``text``: (new text, description)."""
    lines = text.splitlines()
    kind = _pick(rng, ["truncate", "delete-line", "duplicate-line", "garbage", "replace-all"])
    if kind == "truncate":
        cut = int(rng.integers(len(text) + 1))
        return text[:cut], f"truncate at {cut}"
    if kind in ("delete-line", "duplicate-line") and lines:
        k = int(rng.integers(len(lines)))
        if kind == "delete-line":
            return "\n".join(lines[:k] + lines[k + 1:]), f"delete line {k + 1}"
        return "\n".join(lines[:k + 1] + lines[k:]), f"duplicate line {k + 1}"
    if kind == "garbage":
        k = int(rng.integers(len(lines) + 1))
        junk = _pick(rng, GARBAGE)
        return "\n".join(lines[:k] + [junk] + lines[k:]), f"insert {junk!r} at line {k + 1}"
    replacement = _pick(rng, ["", "   \n\n", "# only a comment\n", "\udcff\udcfe binary", "[model]\n", "[points]\n"])
    return replacement, f"replace all by {replacement[:20]!r}"


def mutant(seed_text: str, rng: np.random.Generator) -> tuple[str, list[str]]:
    """A mutant of ``seed_text``: (text, descriptions of its 1 to 3 mutations)."""
    done: list[str] = []
    text = seed_text
    for _ in range(int(rng.integers(1, 4))):
        if rng.random() < 0.1:
            text, description = mutate_text(text, rng)
        else:
            try:
                document = tomllib.loads(text)
            except tomllib.TOMLDecodeError:
                text, description = mutate_text(text, rng)
                done.append(description)
                continue
            description = mutate_document(document, rng)
            text = toml_text(document)
        done.append(description)
    return text, done


# ------------------------------------------------------------------------------------ running
class _Timeout(BaseException):
    pass


def _alarm(signum, frame):
    raise _Timeout


def check(path: Path, seconds: int = 60) -> tuple[str, object]:
    """Run ``cmbs describe`` on the file and, when it loads, a 10-step ``cmbs simulate``:
    ("status", the exit status), ("uncaught", (error, traceback tail)) or ("timeout", None)."""
    from cmbs.cli import main

    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(seconds)
    sink = io.StringIO()
    try:
        with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            status = main(["describe", str(path)])
            if status == 0:
                status = main(["simulate", str(path), "--t-end", "0.01", "--dt", "0.001", "--integrator", "rk4"])
        return "status", status
    except _Timeout:
        return "timeout", None
    except SystemExit as exit_:
        return "status", exit_.code
    except Exception as error:    # noqa: BLE001 -- what the fuzzer looks for
        tail = "".join(traceback.format_exception(error)[-3:])
        return "uncaught", (f"{type(error).__name__}: {str(error)[:200]}", tail)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _warm_up(folder: Path, sources: list[tuple[str, str]]) -> None:
    """Check every seed once, without a time limit, so that the compiled kernels are built (or
    read from numba's cache) before the per-mutant alarm runs."""
    from cmbs.cli import main

    for k, (_, text) in enumerate(sources):
        path = folder / f"seed-{k}.toml"
        path.write_text(text)
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            main(["simulate", str(path), "--t-end", "0.01", "--dt", "0.001", "--integrator", "rk4"])
        path.unlink()


def fuzz(count: int, seed: int = 1, keep: Path | None = None,
         progress: Callable[[int, Report], None] | None = None) -> Report:
    """Run ``count`` mutants (seeded); return the report."""
    rng = np.random.default_rng(seed)
    sources = seeds()
    report = Report()
    with tempfile.TemporaryDirectory(prefix="cmbs-fuzz-") as directory:
        folder = Path(directory)
        for name, text in csv_files():
            (folder / name).write_text(text)
        _warm_up(folder, sources)
        for k in range(count):
            source_name, source_text = sources[int(rng.integers(len(sources)))]
            text, mutations = mutant(source_text, rng)
            path = folder / f"mutant-{k}.toml"
            path.write_text(text, errors="surrogateescape")
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                outcome, value = check(path)
            report.count += 1
            label = f"{source_name}: {'; '.join(mutations)}"
            runtime = [w for w in caught if issubclass(w.category, RuntimeWarning)]
            if runtime:
                report.warned.append((label, f"{runtime[0].filename}:{runtime[0].lineno}: {runtime[0].message}"))
            if outcome == "status":
                report.statuses[value] += 1
            elif outcome == "timeout":
                report.timeouts.append(label)
            else:
                report.uncaught.append((label, *value))
                if keep is not None:
                    keep.mkdir(parents=True, exist_ok=True)
                    (keep / f"uncaught-{k}.toml").write_text(f"# {label}\n# {value[0]}\n{text}",
                                                             errors="surrogateescape")
            path.unlink()
            if progress is not None:
                progress(k + 1, report)
    return report


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.fuzz_model_files", description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=5000, help="number of mutants (default 5000)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the mutations (default 1)")
    parser.add_argument("--keep", type=Path, help="folder for the mutants that raised an uncaught exception")
    args = parser.parse_args(argv)

    def progress(done: int, report: Report) -> None:
        if done % 250 == 0:
            print(f"{done}/{args.count}: {len(report.uncaught)} uncaught", file=sys.stderr, flush=True)

    report = fuzz(args.count, args.seed, args.keep, progress)
    print(report.summary())
    for label, error, _ in report.uncaught[:50]:
        print(f"uncaught: {error}\n    in {label}")
    for label in report.timeouts[:20]:
        print(f"timeout: {label}")
    for label, warning in report.warned[:20]:
        print(f"RuntimeWarning: {warning}\n    in {label}")
    return 1 if report.uncaught else 0


if __name__ == "__main__":
    sys.exit(main())
