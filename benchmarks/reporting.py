"""The JSON report every benchmark writes with ``--json FILE``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

from cmbs.files_io import atomic_path


def write_report(path: str | None, report: dict, default: Callable[[object], object] = float) -> None:
    """Write ``report`` to ``path`` as indented JSON (nothing when ``path`` is None or empty).

    Atomic (:func:`cmbs.files_io.atomic_path`): a value ``default`` cannot convert stops the
    write with its error and leaves no half-written file, nor a clobbered earlier one."""
    if not path:
        return
    with atomic_path(Path(path)) as temporary:
        with open(temporary, "w") as stream:
            json.dump(report, stream, indent=1, default=default)
    print(f"\nreport -> {path}")
