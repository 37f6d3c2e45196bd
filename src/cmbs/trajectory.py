"""The frozen result of a run: time-major arrays, names, provenance; saved and loaded atomically.

``.npz`` files hold arrays ``t`` (k,), ``q``, ``qd``, ``qdd`` (k, n), ``names`` (n,) and any
extra per-time arrays (``lam`` (k, m), ``energy`` (k,), ``constraint_error`` (k,), ...), plus
``info`` (a JSON string of the options used).  ``.csv`` files have one row per time: ``t``, the
coordinates by name, then ``<name>_dot`` and ``<name>_ddot`` columns, then extras (vector extras
as ``lam[0]``, ``lam[1]``, ...); the info goes into a leading ``# info: {...}`` comment line.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cmbs.errors import CmbsError, did_you_mean
from cmbs.files_io import atomic_path, checked_output

_CORE = ("t", "q", "qd", "qdd", "names", "info")


@dataclass(frozen=True)
class Trajectory:
    """Time histories of a model's coordinates.

    Attributes
    ----------
    t : (k,) times; q, qd, qdd : (k, n); names : coordinate names (n,);
    extras : other per-time arrays by name, first axis k; info : options and provenance.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    names: tuple[str, ...]
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        k, n = len(self.t), len(self.names)
        for label in ("q", "qd", "qdd"):
            if np.shape(getattr(self, label)) != (k, n):
                raise ValueError(f"{label} has shape {np.shape(getattr(self, label))}, expected ({k}, {n})")
        for label, array in self.extras.items():
            if np.shape(array)[:1] != (k,):
                raise ValueError(f"extra {label!r} has shape {np.shape(array)}, expected first axis {k}")

    def __getitem__(self, name: str) -> np.ndarray:
        """The time history of coordinate ``name`` (or of an extra array)."""
        if name in self.names:
            return self.q[:, self.names.index(name)]
        if name in self.extras:
            return self.extras[name]
        hint = did_you_mean(name, [*self.names, *self.extras])
        raise KeyError(f"no coordinate or array {name!r}{hint}; coordinates: {', '.join(self.names)}; arrays: "
                       f"{', '.join(self.extras) or 'none'}")

    def velocity(self, name: str) -> np.ndarray:
        return self.qd[:, self.names.index(name)]

    def acceleration(self, name: str) -> np.ndarray:
        return self.qdd[:, self.names.index(name)]

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike) -> Path:
        """Write ``.npz`` or ``.csv`` (by extension) atomically: temp file, then rename."""
        path = checked_output(path, (".npz", ".csv"), "output")
        for label, array in [("q", self.q), ("qd", self.qd), ("qdd", self.qdd), *self.extras.items()]:
            if not np.all(np.isfinite(np.asarray(array, dtype=float))):
                raise CmbsError(f"{path}: refusing to write non-finite values in {label!r}")
        with atomic_path(path) as temporary, open(temporary, "wb") as stream:
            if path.suffix.lower() == ".npz":
                self._write_npz(stream)
            else:
                stream.write(self._csv_text().encode())
        return path

    def _write_npz(self, stream) -> None:
        np.savez(stream, t=self.t, q=self.q, qd=self.qd, qdd=self.qdd, names=np.array(self.names),
                 info=np.array(json.dumps(self.info, default=str)), **self.extras)

    def _csv_text(self) -> str:
        columns = ["t", *self.names, *(f"{n}_dot" for n in self.names), *(f"{n}_ddot" for n in self.names)]
        blocks = [self.t[:, None], self.q, self.qd, self.qdd]
        for label, array in self.extras.items():
            array = np.asarray(array, dtype=float)
            if array.ndim == 1:
                columns.append(label)
                blocks.append(array[:, None])
            else:
                flat = array.reshape(len(self.t), -1)
                columns.extend(f"{label}[{k}]" for k in range(flat.shape[1]))
                blocks.append(flat)
        table = np.hstack(blocks)
        lines = [f"# info: {json.dumps(self.info, default=str)}", ",".join(columns)]
        lines.extend(",".join(repr(float(value)) for value in row) for row in table)
        return "\n".join(lines) + "\n"

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Trajectory":
        """Read a file written by :meth:`save`."""
        path = Path(path)
        if not path.is_file():
            raise CmbsError(f"{path}: no such file")
        try:
            if path.suffix.lower() == ".npz":
                return cls._read_npz(path)
            if path.suffix.lower() == ".csv":
                return cls._read_csv(path)
        except (ValueError, KeyError, OSError) as error:
            raise CmbsError(f"{path}: not a cmbs result file ({error})") from None
        raise CmbsError(f"{path}: expected a .npz or .csv file")

    @classmethod
    def _read_npz(cls, path: Path) -> "Trajectory":
        with np.load(path, allow_pickle=False) as data:
            extras = {key: data[key] for key in data.files if key not in _CORE}
            return cls(data["t"], data["q"], data["qd"], data["qdd"], tuple(str(n) for n in data["names"]),
                       extras, json.loads(str(data["info"])) if "info" in data.files else {})

    @classmethod
    def _read_csv(cls, path: Path) -> "Trajectory":
        text = path.read_text().splitlines()
        info = {}
        if text and text[0].startswith("# info: "):
            info = json.loads(text.pop(0)[len("# info: "):])
        columns = text[0].split(",")
        table = np.array([[float(v) for v in line.split(",")] for line in text[1:] if line], ndmin=2)
        if table.size == 0:
            table = np.zeros((0, len(columns)))
        names = tuple(c for c in columns[1:] if not c.endswith(("_dot", "_ddot")) and "[" not in c
                      and f"{c}_dot" in columns)
        n = len(names)
        t, q, qd, qdd = table[:, 0], table[:, 1:1 + n], table[:, 1 + n:1 + 2 * n], table[:, 1 + 2 * n:1 + 3 * n]
        columns_of: dict[str, list[int]] = {}
        vector: set[str] = set()
        for k, column in enumerate(columns[1 + 3 * n:], start=1 + 3 * n):
            label = column.split("[")[0]
            columns_of.setdefault(label, []).append(k)
            if "[" in column:
                vector.add(label)
        arrays = {label: table[:, ks] if label in vector else table[:, ks[0]] for label, ks in columns_of.items()}
        return cls(t, q, qd, qdd, names, arrays, info)
