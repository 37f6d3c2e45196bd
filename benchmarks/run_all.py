#!/usr/bin/env python
"""The whole benchmark suite in one command: every benchmark of this folder in turn, each one's
printed tables kept in a file, its figures as JSON and plots, and at the end the verdict line
of every issue target they measured.

    python benchmarks/run_all.py                   # full runs (about 40 min on 2 cores)
    python benchmarks/run_all.py --quick           # shorter batches and runs (about 10 min)
    python benchmarks/run_all.py --only sweep --only launch --out-dir bench-out

Into ``--out-dir`` (default ``bench-out``): ``NAME.txt`` (what the benchmark printed),
``NAME.json`` for those that write their figures, ``scaling.png`` (µs per evaluation against the
number of links, log axes), ``work-precision-MECHANISM.png`` and ``summary.txt`` (each target's
PASS/MISS line).  The other tools (Pinocchio, MuJoCo, Exudyn) are measured where installed:
``pip install ".[bench]"``.  Each benchmark runs in its own process, as its README section
describes; a benchmark that fails is reported and the others still run (exit status 1).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def commands(out: Path, quick: bool) -> dict[str, list[str]]:
    """Each benchmark's arguments, by name."""
    fast = ["--quick"] if quick else []
    return {
        "model": ["bench_model.py", *fast, "--json", str(out / "model.json")],
        "dynamics": ["bench_dynamics.py", *fast, "--json", str(out / "dynamics.json")],
        "scaling": ["bench_scaling.py", *fast, "--json", str(out / "scaling.json"), "--plot", str(out / "scaling.png")],
        "work-precision": ["work_precision.py", *fast, "--out-dir", str(out), "--json",
                           str(out / "work-precision.json")],
        "sweep": ["bench_sweep.py", *fast],
        "launch": ["bench_launch.py", *(["--repeat", "5", "--no-cold"] if quick else [])],
        "first-use": ["bench_first_use.py", *fast],
        "control": ["bench_control.py", *fast],
        "servo": ["bench_servo.py", *fast, "--json", str(out / "servo.json")],
        "gait": ["bench_gait.py", *(["--repeat", "2"] if quick else [])],
        "memory": ["bench_memory.py", *fast, "--json", str(out / "memory.json")],
        "n-four-bar": ["bench_n_four_bar.py", *(["--t-end", "5"] if quick else []), "--json",
                       str(out / "n-four-bar.json")],
        "n-four-bar-tools": ["bench_n_four_bar_tools.py", *(["--N", "2", "10", "--t-end", "5"] if quick else []),
                             "--json", str(out / "n-four-bar-tools.json")],
    }


def verdicts(text: str) -> list[str]:
    """The lines of a benchmark's output that judge a target, under the headings ("== ...") of
    the cases they belong to."""
    kept: list[str] = []
    for line in text.splitlines():
        if line.startswith("== "):
            kept.append(line.split(":")[0])
        elif "PASS" in line or "MISS" in line:
            kept.append("  " + line.strip())
    return [line for k, line in enumerate(kept)
            if not line.startswith("== ") or (k + 1 < len(kept) and not kept[k + 1].startswith("== "))]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="each benchmark's short mode")
    parser.add_argument("--out-dir", default="bench-out", help="folder of the outputs (default bench-out)")
    parser.add_argument("--only", action="append", metavar="NAME", help="run only these (repeatable): "
                        + ", ".join(commands(Path("."), False)))
    args = parser.parse_args()
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    chosen = commands(out, args.quick)
    unknown = sorted(set(args.only or []) - set(chosen))
    if unknown:
        parser.error(f"--only: unknown benchmark {', '.join(unknown)} (choose from {', '.join(chosen)})")
    environment = {**os.environ, "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "1")}
    summary, failed = [], []
    for name, arguments in chosen.items():
        if args.only and name not in args.only:
            continue
        print(f"=== {name}: python benchmarks/{' '.join(arguments)}", flush=True)
        started = time.perf_counter()
        result = subprocess.run([sys.executable, str(HERE / arguments[0]), *arguments[1:]], env=environment,
                                capture_output=True, text=True)
        wall = time.perf_counter() - started
        print(result.stdout, end="", flush=True)
        (out / f"{name}.txt").write_text(result.stdout + result.stderr)
        if result.returncode != 0:
            failed.append(name)
            print(result.stderr[-2000:], file=sys.stderr)
            summary.append(f"{name}: FAILED (exit status {result.returncode}, {wall:.0f} s; see {out / name}.txt)")
            continue
        summary.append(f"{name} ({wall:.0f} s):")
        summary.extend(f"    {line}" for line in verdicts(result.stdout) or ["(no target judged)"])
    text = "\n".join(summary) + "\n"
    (out / "summary.txt").write_text(text)
    print(f"=== summary (also in {out / 'summary.txt'})\n{text}", end="")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
