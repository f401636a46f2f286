#!/usr/bin/env python3
"""Whole ``gfimu estimate`` commands against a data-movement floor, measured in one loop.

The floor is what any tool that reads a log and writes an estimate must at least do: a Python process
that imports numpy and ``scipy.linalg``, reads the log's ``imu.csv`` with ``numpy.loadtxt`` and writes a
10-column CSV of the same length (a timestamp and nine columns, as many as ω, ω̇ and the specific force)
with ``numpy.savetxt``. Against it, each a fresh process on the same log:

- ``batch``: ``python -m gfimu estimate LOG --out X`` (the batch smoother, the default);
- ``fixed-lag``: ``python -m gfimu estimate LOG --method fixed-lag --out X``;
- ``batch-serial``: the batch command with ``-O workers=1``: its solve windows in its own process, one after
  the other, instead of in forked workers (whether the workers pay on this machine);
- ``help``: ``gfimu --help`` (the installed command when there is one, else ``python -m gfimu --help``);
- ``import``: ``python -c "import gfimu.cli"`` and ``estimate-import``: what ``gfimu estimate`` imports
  before it reads the log (``gfimu.cli.estimate``, ``gfimu.pipeline``, the batch smoother, its guard, the
  per-sample ML estimate it checks against, the output writer);
- ``pass``: ``python -c pass``, the interpreter's own start.

The commands run in one loop: each round runs every command once, in an order turned by one place
each round, so that a change of the machine's load falls on all of them alike; the table gives the
median over ``--runs`` rounds of the wall time and of the CPU time (user + system of the process and
of the worker processes it waited for, ``resource.getrusage(RUSAGE_CHILDREN)``), and each as a multiple
of the floor's. The processes run with Python's bytecode cache on and one BLAS thread
(``tools/bench_env.py``).

The log is a simulated cube of four triads (``gfimu simulate random3d``, 5 cm half edge, 500 Hz,
``--duration-s`` long, default noise), or ``--log DIR`` (a log folder), or ``--cell NAME`` (a cell of
tools/regime_matrix.py, ``--duration-s`` long where given: the 20 kHz impact cell, at the rates impact sensors
record), or each MIMU4444 ``data.bin`` given as an argument (converted with ``gfimu convert mimu4444`` first;
one table each).

With ``--baseline DIR`` (another checkout of gfimu) each gfimu command selected also runs with that
checkout's package, in the same loop, as ``NAME@baseline``: a before/after comparison under the same load.

    python3 tools/bench_floor.py [--runs 5] [--duration-s 60] [--log DIR | --cell NAME] [--only batch,fixed-lag] [--baseline DIR] [data.bin ...]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_env import command_env  # noqa: E402

FLOOR = ("import sys, numpy, scipy.linalg\n"
         "a = numpy.loadtxt(sys.argv[1], delimiter=',', ndmin=2)\n"
         "numpy.savetxt(sys.argv[2], a[:, :10], delimiter=',', header='t,1,2,3,4,5,6,7,8,9')\n")
NAMES = ("floor", "batch", "fixed-lag", "batch-serial", "help", "import", "estimate-import", "pass")
DESCRIPTION = {
    "floor": "floor: numpy + scipy.linalg, loadtxt imu.csv, savetxt 10 columns",
    "batch": "gfimu estimate LOG (batch smoother)",
    "fixed-lag": "gfimu estimate LOG --method fixed-lag",
    "batch-serial": "gfimu estimate LOG -O workers=1 (batch, no worker processes)",
    "help": "gfimu --help",
    "import": "python -c \"import gfimu.cli\"",
    "estimate-import": "imports of gfimu estimate (cli.estimate, pipeline, smoother.batch, guard, ml, outputs)",
    "pass": "python -c pass",
}


def commands(log: Path, out: Path) -> dict[str, list[str]]:
    py = sys.executable
    script = Path(py).with_name("gfimu")
    helps = [str(script), "--help"] if script.is_file() else [py, "-m", "gfimu", "--help"]
    return {
        "floor": [py, "-c", FLOOR, str(log / "imu.csv"), str(out / "floor.csv")],
        "batch": [py, "-m", "gfimu", "estimate", str(log), "--out", str(out / "batch.csv")],
        "fixed-lag": [py, "-m", "gfimu", "estimate", str(log), "--method", "fixed-lag", "--out",
                      str(out / "fixed-lag.csv")],
        "batch-serial": [py, "-m", "gfimu", "estimate", str(log), "-O", "workers=1", "--out", str(out / "batch-serial.csv")],
        "help": helps,
        "import": [py, "-c", "import gfimu.cli"],
        "estimate-import": [py, "-c", "import gfimu.cli, gfimu.cli.estimate, gfimu.pipeline, gfimu.smoother.batch.engine, "
                            "gfimu.smoother.guard, gfimu.estimators.ml, gfimu.io.outputs"],
        "pass": [py, "-c", "pass"],
    }


GFIMU_COMMANDS = ("batch", "fixed-lag", "batch-serial", "help", "import", "estimate-import")
"""The commands that run gfimu's code (``--baseline`` runs them with the other checkout too)."""


def describe(name: str) -> str:
    base, _, tag = name.partition("@")
    return DESCRIPTION[base] + (f" [{tag}]" if tag else "")


def timed(argv: list[str], env: dict) -> tuple[float, float]:
    """(wall, CPU) seconds of one process (CPU: user + system of it and the children it waited for)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        tail = done.stderr.decode(errors="replace").strip().splitlines()[-3:]
        raise SystemExit(f"bench_floor: {' '.join(argv[:6])} ... exited {done.returncode}: {' / '.join(tail)}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def rows_of(path: Path) -> int:
    with open(path, "rb") as fh:
        return sum(1 for line in fh if line.strip() and not line.startswith(b"#"))


def measure(log: Path, names: list[str], runs: int, env: dict, baseline_env: dict | None = None) -> dict[str, dict]:
    with tempfile.TemporaryDirectory(prefix="bench-floor-") as tmp:
        out = Path(tmp)
        argvs = commands(log, out)
        envs = {n: env for n in names}
        if baseline_env is not None:
            for n in [n for n in names if n in GFIMU_COMMANDS]:
                argvs[n + "@baseline"] = [a.replace(str(out / f"{n}.csv"), str(out / f"{n}@baseline.csv")) for a in argvs[n]]
                envs[n + "@baseline"] = baseline_env
                names = names + [n + "@baseline"]
        walls: dict[str, list[float]] = {n: [] for n in names}
        cpus: dict[str, list[float]] = {n: [] for n in names}
        for r in range(runs):
            order = names[r % len(names):] + names[:r % len(names)]
            for name in order:
                for f in out.iterdir():
                    f.unlink()
                wall, cpu = timed(argvs[name], envs[name])
                walls[name].append(wall)
                cpus[name].append(cpu)
                if r == 0 and name.partition("@")[0] in ("floor", "batch", "fixed-lag", "batch-serial"):  # a row a sample
                    n_in, n_out = rows_of(log / "imu.csv"), rows_of(out / f"{name}.csv")
                    if n_in != n_out:
                        raise SystemExit(f"bench_floor: {name} wrote {n_out} rows for {n_in} samples")
    return {n: {"wall_s": statistics.median(walls[n]), "cpu_s": statistics.median(cpus[n]),
                "walls_s": walls[n], "cpus_s": cpus[n]} for n in names}


def report(title: str, res: dict[str, dict], runs: int) -> None:
    print(title)
    print()
    floor = res.get("floor")
    print("| command | wall s | × floor | CPU s | × floor |")
    print("|---|---:|---:|---:|---:|")
    for name, r in res.items():
        ratio = (f"{r['wall_s'] / floor['wall_s']:.2f}" if floor else "")
        cratio = (f"{r['cpu_s'] / floor['cpu_s']:.2f}" if floor else "")
        print(f"| {describe(name)} | {r['wall_s']:.3f} | {ratio} | {r['cpu_s']:.3f} | {cratio} |")
    print()
    pairs = [("batch", "floor"), ("fixed-lag", "floor"), ("fixed-lag", "batch"), ("batch", "batch-serial"),
             ("batch@baseline", "floor"), ("fixed-lag@baseline", "floor"), ("batch", "batch@baseline"),
             ("fixed-lag", "fixed-lag@baseline")]
    said = [f"{a} ÷ {b} = {res[a]['wall_s'] / res[b]['wall_s']:.2f} wall, "
            f"{res[a]['cpu_s'] / max(res[b]['cpu_s'], 1e-9):.2f} CPU"
            for a, b in pairs if a in res and b in res]
    if said:
        print(f"Medians of {runs} rounds: " + "; ".join(said) + ".")
    if "pass" in res:
        start = [f"{describe(n)} {res[n]['wall_s'] - res['pass']['wall_s']:+.3f} s"
                 for n in ("help", "import", "estimate-import", "help@baseline", "import@baseline",
                           "estimate-import@baseline") if n in res]
        if start:
            print(f"Start-up beyond the interpreter's own ({res['pass']['wall_s']:.3f} s): " + "; ".join(start) + ".")
    print()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recordings", nargs="*", type=Path, help="MIMU4444 data.bin files, each converted and measured")
    ap.add_argument("--runs", type=int, default=5, help="rounds of the loop; medians are shown (default 5)")
    ap.add_argument("--duration-s", type=float, default=None,
                    help="length of the simulated cube log [s] (default 60), or with --cell of the cell's log (default: "
                         "the cell's own)")
    ap.add_argument("--log", type=Path, help="measure on this log folder instead of a simulated one")
    ap.add_argument("--cell", help="measure on the log of this cell of tools/regime_matrix.py (e.g. impacts-20kHz)")
    ap.add_argument("--only", default=",".join(NAMES),
                    help=f"comma-separated commands to run, of {', '.join(NAMES)} (default all)")
    ap.add_argument("--baseline", type=Path, metavar="DIR",
                    help="another gfimu checkout: its package runs the selected gfimu commands too, in the same loop")
    ap.add_argument("--json", default="bench_floor.json", help="where to write the results")
    args = ap.parse_args(argv)
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = [n for n in names if n not in NAMES]
    if unknown or not names:
        ap.error(f"--only: no command {', '.join(map(repr, unknown)) or 'given'}; the commands are {', '.join(NAMES)}")
    if args.runs < 1:
        ap.error("--runs: at least 1")
    if args.log is not None and not (args.log / "imu.csv").is_file():
        ap.error(f"--log {args.log}: no imu.csv in that folder")
    cell = None
    if args.cell is not None:
        import regime_matrix

        cell = regime_matrix.named_cell(args.cell, args.duration_s)
        if cell is None:
            ap.error(f"--cell: no cell {args.cell!r}; tools/regime_matrix.py --list names them")
    duration_s = 60.0 if args.duration_s is None else args.duration_s
    for rec in args.recordings:
        if not rec.is_file():
            ap.error(f"{rec}: no such file")
    if args.baseline is not None and not (args.baseline / "gfimu" / "__init__.py").is_file():
        ap.error(f"--baseline {args.baseline}: not a gfimu checkout (no gfimu/__init__.py)")
    env = command_env(REPO)
    baseline_env = command_env(args.baseline.resolve()) if args.baseline is not None else None
    results = {}
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="bench-floor-logs-") as tmp:
        logs: list[tuple[str, Path]] = []
        if args.log is not None:
            logs.append((f"log {args.log}", args.log))
        if cell is not None:
            folder, _ = regime_matrix.build_log(cell, Path(tmp) / "cell")
            for extra in ("truth.csv", "reference.csv"):  # the command would not read them; the floor does not either
                (folder / extra).unlink(missing_ok=True)
            logs.append((f"regime-matrix cell {cell.name} ({cell.rate_hz:g} Hz, {cell.duration_s:g} s)", folder))
        for rec in args.recordings:
            folder = Path(tmp) / f"{rec.parent.name}-{len(logs)}"
            subprocess.run([sys.executable, "-m", "gfimu", "convert", "mimu4444", str(rec), "--out", str(folder),
                            "--quiet"], env=env, check=True)
            logs.append((f"MIMU4444 {rec.parent.name}/{rec.name} (converted)", folder))
        if not logs:
            folder = Path(tmp) / "cube"
            subprocess.run([sys.executable, "-m", "gfimu", "simulate", "random3d", "--out", str(folder),
                            "--duration-s", f"{duration_s:g}", "--rate-hz", "500", "--seed", "0", "--quiet"],
                           env=env, check=True)
            (folder / "truth.csv").unlink()  # the command would not read it; the floor does not either
            logs.append((f"simulated cube of four triads (random3d, 500 Hz, {duration_s:g} s)", folder))
        print(f"{os.cpu_count()} CPUs, 1-minute load average {load:.1f} at the start; "
              f"medians of {args.runs} rounds, each command once per round in a turning order")
        print()
        for title, folder in logs:
            n = rows_of(folder / "imu.csv")
            res = measure(folder, names, args.runs, env, baseline_env)
            report(f"{title}: {n} samples, imu.csv {(folder / 'imu.csv').stat().st_size / 1e6:.1f} MB", res, args.runs)
            results[title] = {"samples": n, **res}
    Path(args.json).write_text(json.dumps({"date": time.strftime("%Y-%m-%d %H:%M %Z"), "cpus": os.cpu_count(),
                                           "load_average_1min": load, "runs": args.runs, "logs": results}, indent=2))
    print(f"results written to {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
