#!/usr/bin/env python3
"""Regenerate docs/benchmarks.md: run the accuracy and timing scripts of this folder and write their tables.

Each section of the page is the output of one script, under the command that printed it; the date,
the commit and the machine are stated once at the top. ``--quick`` runs every script on short logs
with few repeats (and one recording) to check that the page can be made, and says so on the page;
``--only NAME`` (repeatable, or comma-separated) runs only those sections and replaces them in an
existing page, each stating when and how it was run, the others kept as they were.

    python3 tools/benchmarks.py --out docs/benchmarks.md            # the whole page (about 40 min on 2 cores)
    python3 tools/benchmarks.py --out docs/benchmarks.md --quick    # a short run
    python3 tools/benchmarks.py --out docs/benchmarks.md --only real-flow
    python3 tools/benchmarks.py --list                              # the sections

A script that fails leaves its section saying so (the command, its exit status and the end of its
standard error), the other sections are still run and written, and the exit status is 1. The
recordings of the ``real-flow`` and ``fixed-lag-real`` sections are read from ``--recordings`` (default
``$GFIMU_MIMU4444_DIR`` or ``../shared/data/mimu4444`` beside the repository, as the tests do), the phone
exports from ``$GFIMU_PHONE_EXPORTS_DIR``; without its data a section that the page already holds with
figures is kept as it was (said on standard error), else it says it was skipped.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TOOLS = REPO / "tools"
DEFAULT_RECORDINGS = Path(os.environ.get("GFIMU_MIMU4444_DIR", REPO.parent / "shared" / "data" / "mimu4444"))
RECORDING_NAMES = ("exp_1", "exp_2", "exp_3")
MARK = "<!-- benchmarks:{} -->"
END = "<!-- /benchmarks:{} -->"


# where a script says it wrote its JSON, and real_flow.py's own date line (the page states the date once)
DROP = (r"^(results )?written ", r"^# \d{4}-\d\d-\d\d, ")
# a temporary folder of a script's, in a command line it prints
TEMPORARY = re.compile(re.escape(tempfile.gettempdir().rstrip("/")) + r"/tmp[\w-]*/")


@dataclass(frozen=True)
class Section:
    name: str
    title: str
    script: str
    about: str
    full: tuple[str, ...] = ()
    quick: tuple[str, ...] = ()
    json: bool = True  # the script takes --json (sent to a temporary folder)
    recordings: bool = False  # the MIMU4444 recordings are appended as arguments
    drop: tuple[str, ...] = DROP  # lines of its output left out (regular expressions)
    data_env: str | None = None  # the environment variable naming the folder of its data (None: none needed)

    def lacks_data(self) -> bool:
        """Whether the folder of data this section reads is not there."""
        return self.data_env is not None and not Path(os.environ.get(self.data_env, "")).is_dir()


SECTIONS = (
    Section(
        "smoother-accuracy", "Accuracy on simulations, per method", "smoother_accuracy.py",
        "ω RMSE (norm, rad/s) of the best per-sample method and of the batch smoother on simulated logs: "
        "the 5 cm cube of four triads (0.07 m/s² per axis, 500 Hz) on three motions, five randomly placed and "
        "rotated triads, the near-planar MIMU4444 layout, and [McGinnis, Perkins & King 2012](references.md)'s single triad in free flight (1 kHz). "
        "\"RMSE / bound\" is the smoother's error over the bound of its own graph (1: efficient); the last "
        "columns are the process noise the smoother chose from the data.",
        quick=("--duration-s", "3")),
    Section(
        "fixed-lag-accuracy", "Fixed-lag against batch on simulations", "fixed_lag_accuracy.py",
        "ω RMSE (rad/s) of the batch smoother and of the fixed-lag smoother (lag 0.2 s) on the 5 cm cube, "
        "over the whole log and over the streamed part (after the first seconds on which the fixed-lag "
        "smoother chooses its process noise), and the share of samples whose ω points the wrong way.",
        quick=("--duration-s", "5", "--scenarios", "random3d,reversal"), json=False),
    Section(
        "slow-motion", "Slow motion: every method", "slow_motion.py",
        "ω RMSE (rad/s) of every method on a slow random 3-D rotation (the `slow3d` scenario, |ω| at most "
        "1 rad/s: a hovering drone, a slow hand) seen by the 10 cm cube of four triads (0.07 m/s², 500 Hz, "
        "20 s), over the whole log, over its first 2 s and after, and the share of those first samples whose "
        "ω points the wrong way. The fixed-lag smoother holds the first rows of the stream until the data "
        "decide ω (docs/fixed-lag.md).",
        quick=("--duration-s", "6"), json=False),
    Section(
        "euroc-lag", "Fixed-lag smoother on the demo's EuRoC log", "euroc_lag.py",
        "ω RMSE (rad/s) per axis, over the axes and of the error norm (the demo's ‖ω‖ column) on `gfimu demo`'s "
        "second log: the real EuRoC V1_01_easy motion (at rest for its first second) through the 10 cm cube of "
        "four triads (0.07 m/s², 500 Hz, 10 s), with the share of the error's power below 2 Hz. The fixed-lag "
        "smoother at three lags, with the start that tests the warm-up for rest and without it "
        "(docs/fixed-lag.md), against `imm` (which assumes a start at rest) and the batch smoother.",
        full=("--lags", "0.2,1,3", "--no-still-start"), quick=("--duration-s", "5", "--no-still-start"),
        json=False),
    Section(
        "real-flow", "A real recording, from convert to estimate", "real_flow.py",
        "The commands of the README's real-recording flow on the MIMU4444 recordings (8 IMUs on a 19 mm "
        "board, 62.5 Hz, hand motion in the last two minutes of each ten): `gfimu convert mimu4444`, "
        "`gfimu calibrate`, `gfimu estimate --calibration`, each in its own process; wall time of each step, "
        "CPU time and peak memory of the whole (worker processes included); then the estimate against the "
        "mean of the board's gyros on the moving samples (|ω_ref| > 2 rad/s, reference valid), the figures "
        "`gfimu evaluate log est.csv --moving-threshold-radps 2` prints.",
        json=False, recordings=True),
    Section(
        "fixed-lag-real", "Fixed-lag smoother on the real recordings: accuracy against lag", "fixed_lag_real.py",
        "The MIMU4444 recordings converted with `gfimu convert mimu4444` (no calibration), then `ml`, the batch "
        "smoother and the fixed-lag smoother at several lags (`-O lag_s=`), every estimate in the script's own "
        "process, one after the other; ω against the mean of the board's gyros on the moving samples "
        "(|ω_ref| > 2 rad/s, reference valid), as `gfimu evaluate log est.csv --moving-threshold-radps 2` scores "
        "it, the wall and CPU time of each estimate (reading the log included; worker processes too), and whether "
        "the fixed-lag smoother meets its two targets on each recording.",
        full=("--recordings",), quick=("--quick", "--recordings"), recordings=True),
    Section(
        "sigma-coverage", "Does σ mean what it says? Coverage per regime", "sigma_coverage.py",
        "The smoothers' one-sigma values of ω against the error they describe: on every cell of the regime "
        "matrix with noise and up to 10,000 samples (tools/regime_matrix.py), on cells whose readings carry an "
        "error array.toml does not state, built from the physics (noise 5 times the stated level; an AR(1) "
        "error per axis; sensor positions 2 mm off; gains 1 % off; each sensor shaken at 37 Hz by its mount; "
        "a MIMU-like cell; each cell drawn again, its draws pooled, until every method's σ has 100 independent "
        "samples per axis, at most five draws, and five of a cell with positions or gains off), and on the "
        "MIMU4444 recordings (moving samples against the "
        "mean of the board's gyros, as `gfimu evaluate log est.csv --moving-threshold-radps 2` scores them; a "
        "third row against the reference lined up in time, as with `--estimate-time-offset`), the share of "
        "samples within 1σ and 2σ per axis, the spread of a share from the count of independent samples and the mean NEES, "
        "for the white-noise σ and for the σ the smoothers report (scaled by the readings' own misfit, under a "
        "robust model as the M-estimator's sandwich, and following the path's own trapezoid level: "
        "[uncertainty.md](uncertainty.md)).",
        full=(), quick=("--cells", "misfit"), json=False, recordings=True),
    Section(
        "fixed-lag-latency", "Fixed-lag smoother: latency, end to end, memory", "bench_fixed_lag.py",
        "A simulated 500 Hz stream (random motion, 10 cm cube of four triads) pushed sample by sample into "
        "the fixed-lag smoother (lag 0.2 s): time of each update in steady state (wall clock, and CPU time "
        "of the thread), apart from the one update that chooses the process noise; then "
        "`gfimu estimate --method fixed-lag` on a written log in a fresh process; then the resident memory "
        "along a long stream generated on the fly.",
        quick=("--duration-s", "30", "--e2e-duration-s", "10", "--memory-duration-s", "0")),
    Section(
        "live-latency", "gfimu live: latency from a datagram to its row", "replay_udp.py",
        "A simulated 500 Hz log (random motion, four triads) sent at its own rate, one imu.csv row per UDP "
        "datagram on localhost, into `gfimu live --out -` (lag 0.2 s, the defaults); each row's latency runs from "
        "its sample's datagram being sent to the row being read from the command's standard output, over the "
        "whole replay and past its first 10 s (the first rows wait for the first 3 s of the stream, on which the "
        "process noise is chosen); the last line is `gfimu live`'s own summary (arrival to row written).",
        full=("--simulate", "40"), quick=("--simulate", "12"), json=False),
    Section(
        "live-20khz", "gfimu live at 20 kHz: the impact cell in real time", "replay_udp.py",
        "The regime matrix's 20 kHz cell (four triads, impacts; tools/regime_matrix.py), 30 s of it, sent at its "
        "own rate, one row per UDP datagram on localhost, into `gfimu live --out -` with the defaults: how many "
        "rows came out, how long after the last datagram the last row came (how far from real time the stream "
        "runs), the latencies over the whole replay and past its first 10 s (the first rows wait for the first "
        "model's stretch and the held start), and `gfimu live`'s own summary (rows dropped when the input outran "
        "the smoother; the default queue holds 10 s of samples, 200,000 at 20 kHz).",
        full=("--cell", "impacts-20kHz", "--duration-s", "30"),
        quick=("--cell", "impacts-20kHz", "--duration-s", "0.2"), json=False),
    Section(
        "stream-cost", "Fixed-lag smoother: CPU sample by sample", "stream_cost.py",
        "The fixed-lag method as `gfimu estimate --method fixed-lag` runs it (its screening, then the stream "
        "session fed the log in blocks of samples, each run the smoother can take at once in one compiled call, "
        "the others one by one), on a simulated 60 s, 500 Hz cube of four triads: the CPU of the whole run (the "
        "model choices made in their own process included), of the stream's own thread (`time.thread_time`: a busy "
        "machine stretches wall time, not this), of the call that made the first choice of the model, the calls, "
        "and per sample in steady state (the log's second half); and the rate the stream's thread keeps up with.",
        full=(), quick=("--simulate-s", "10"), json=False),
    Section(
        "stream-cost-20khz", "Fixed-lag smoother at 20 kHz: CPU sample by sample", "stream_cost.py",
        "The same on 6 s of the regime matrix's 20 kHz impact cell (four triads, impacts of 20-100 g; "
        "tools/regime_matrix.py).",
        full=("--cell", "impacts-20kHz", "--duration-s", "6"), quick=("--cell", "impacts-20kHz", "--duration-s", "0.5"),
        json=False),
    Section(
        "screen-cost", "Screening a log with spikes: the whole-log rule and the stream's", "screen_cost.py",
        "The readings' screening of a simulated 10-minute, 62.5 Hz log of a cube of four triads with a 60 m/s² "
        "spike on one channel every 150 samples (2.4 s), by the whole-log rule the batch smoother uses and by the "
        "stream's rule applied row by row, as `gfimu estimate --method fixed-lag` and `gfimu live` screen (each "
        "block it cannot pass as it is decided on its own buffer). One process, medians of three runs.",
        full=("--runs", "3"), quick=("--duration-s", "60", "--runs", "1"), json=False),
    Section(
        "batch-throughput", "Batch smoother: throughput and memory", "bench_smoother.py",
        "The whole command `gfimu estimate LOG --method smoother` (start-up, reading and writing included) "
        "on simulated random motion, 10 cm cube of four triads, 500 Hz, for several log lengths: median wall "
        "time and CPU time (worker processes included) over the repeats, and the peak resident memory of its "
        "largest process.",
        full=("--command", "--durations", "20", "60", "200", "600", "--repeats", "3"),
        quick=("--command", "--durations", "10", "20", "--repeats", "1"),
        drop=DROP + (r"^\s*\d+ s\s+\d+ samples\s+wall ",)),  # its progress lines: the table repeats them
    Section(
        "floor", "Whole commands against a data-movement floor", "bench_floor.py",
        "A 60 s, 500 Hz simulated log of a cube of four triads (30,000 samples). The floor is a Python process "
        "that imports numpy and scipy.linalg, reads the log's `imu.csv` with `numpy.loadtxt` and writes a "
        "10-column CSV of the same length with `numpy.savetxt`; against it the whole `gfimu estimate LOG` "
        "command (batch smoother), the same with `-O workers=1` (no worker processes for its solve windows) and "
        "`gfimu estimate LOG --method fixed-lag`, and the start-up of `gfimu --help`, "
        "of importing `gfimu.cli` and of what `gfimu estimate` imports, each a fresh process. All run in one loop, "
        "each once per round in a turning order; medians of the rounds, wall and CPU time (worker processes "
        "included), and each as a multiple of the floor's.",
        full=("--runs", "5"), quick=("--runs", "1", "--duration-s", "10")),
    Section(
        "floor-real", "Batch and fixed-lag whole commands on the real recordings", "bench_floor.py",
        "The same loop on the MIMU4444 recordings (converted with `gfimu convert mimu4444`, 10 minutes at "
        "62.5 Hz, 8 triads): the floor, `gfimu estimate LOG` and `gfimu estimate LOG --method fixed-lag`, "
        "medians of the rounds, and fixed-lag ÷ batch.",
        full=("--runs", "3", "--only", "floor,batch,fixed-lag"),
        quick=("--runs", "1", "--only", "floor,batch,fixed-lag"), recordings=True),
    Section(
        "floor-20khz", "Batch and fixed-lag whole commands at 20 kHz", "bench_floor.py",
        "The same loop on 6 s of the regime matrix's 20 kHz impact cell (four triads, 2.5 cm, impacts of "
        "20-100 g; tools/regime_matrix.py): the floor, `gfimu estimate LOG` and `gfimu estimate LOG --method "
        "fixed-lag`, medians of the rounds. At this rate the batch smoother's process-noise tuning (its marginal "
        "likelihood over every sample of the window: `tune_span_s` is 10 s whatever the rate) is most of its time.",
        full=("--runs", "3", "--only", "floor,batch,fixed-lag", "--cell", "impacts-20kHz", "--duration-s", "6"),
        quick=("--runs", "1", "--only", "floor,batch,fixed-lag", "--cell", "impacts-20kHz", "--duration-s", "1")),
    Section(
        "reader-memory", "Reading a log: memory and time", "bench_reader_memory.py",
        "A 500 Hz log of eight triads written with the library's writer, then read in a fresh process: "
        "peak resident memory above the process's memory before reading, as MB and as a multiple of the "
        "size of `imu.csv`, the time to read, and the peak of the largest worker process parsing blocks.",
        quick=("--minutes", "2")),
    Section(
        "phone-exports", "Phone exports of linear acceleration: attitude and gravity-free acceleration",
        "phone_exports.py",
        "Real Sensor Logger and phyphox exports whose accelerometer file is the linear acceleration (gravity "
        "removed by the phone), read from `$GFIMU_PHONE_EXPORTS_DIR` (not shipped: their repositories state no "
        "licence; SOURCE names them): `gfimu convert csv --map sensorlogger|phyphox`, then `gfimu estimate "
        "--orientation gyro`; before (the readings taken for the specific force, as gfimu read them until "
        "array.toml recorded `readings`) and now (the export's own Gravity.csv added back, or attitude refused "
        "and ω and a estimated without it). The first attitude is compared with the phone's own gravity vector "
        "(the first row of its Gravity.csv).",
        json=False, data_env="GFIMU_PHONE_EXPORTS_DIR"),
    Section(
        "startup", "Start-up of the command", "bench_startup.py",
        "Wall time of a few command lines that do no work, each in a fresh process, and which heavy "
        "modules each one imports.",
        quick=("--repeats", "2")),
    Section(
        "first-run", "The first fixed-lag run on a machine: compiling the kernels", "bench_first_run.py",
        "`gfimu estimate LOG --method fixed-lag` on a short simulated log with an empty numba cache (a user's "
        "first run after installing: the stream's kernels and the ML iterations compiled) and with the cache "
        "filled (every later run), and each kernel's compilation time as numba reports it.",
        quick=("--runs", "1"), json=False),
)
BY_NAME = {s.name: s for s in SECTIONS}


class PageError(Exception):
    """An --out page this script cannot update; the message names the file."""


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    memory = ""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                memory = f", {int(line.split()[1]) / 2**20:.1f} GB of memory"
                break
    except OSError:
        pass
    return f"{platform.system()} {platform.machine()}, {os.cpu_count()} CPUs ({cpu}){memory}, Python {platform.python_version()}"


def commit() -> str:
    def git(*args: str) -> str:
        try:
            done = subprocess.run(["git", *args], cwd=REPO, capture_output=True, text=True)
        except OSError:  # no git on this machine
            return ""
        return done.stdout.strip() if done.returncode == 0 else ""

    head = git("rev-parse", "--short", "HEAD")
    if not head:
        return "an unknown commit (no git checkout)"
    dirty = git("status", "--porcelain", "--untracked-files=no", "--", "gfimu", "tools")
    return f"commit {head}" + (" with uncommitted changes to gfimu/ or tools/" if dirty else "")


def recordings(folder: Path, quick: bool) -> list[Path]:
    names = RECORDING_NAMES[:1] if quick else RECORDING_NAMES
    return [folder / n / "data.bin" for n in names if (folder / n / "data.bin").is_file()]


def shown(path: Path) -> str:
    """A path as the page shows it: relative to the repository when beside it (../shared/...), else as given."""
    path = Path(os.path.abspath(path))
    return os.path.relpath(path, REPO) if path.is_relative_to(REPO.parent) else str(path)


def to_markdown(text: str, drop: tuple[str, ...]) -> str:
    """A script's standard output as page text: its tables kept as they are, each other line a paragraph,
    the lines saying where it wrote its JSON (and its own date line) left out."""
    out: list[str] = []
    for line in text.splitlines():
        line = line.rstrip()
        if any(re.search(p, line) for p in drop):
            continue
        line = TEMPORARY.sub("", line)
        if not line.strip():
            if out and out[-1] != "":
                out.append("")
            continue
        is_row = line.lstrip().startswith("|")
        if out and out[-1] != "" and not (is_row and out[-1].lstrip().startswith("|")):
            out.append("")  # a table and a paragraph, or two paragraphs, apart
        out.append(line.strip())
    while out and out[-1] == "":
        out.pop()
    return "\n".join(out)


def run_section(section: Section, quick: bool, recordings_dir: Path, note: str | None) -> tuple[str, bool]:
    """Run one script; (the section's page text, whether it succeeded)."""
    args = list(section.quick if quick else section.full)
    head = [MARK.format(section.name), f"## {section.title}", "", section.about, ""]
    if section.recordings:
        recs = recordings(recordings_dir, quick)
        if not recs:
            print(f"benchmarks: {section.name}: skipped, no MIMU4444 recording at {recordings_dir}", file=sys.stderr)
            return "\n".join(head + ([note, ""] if note else []) + [
                f"Skipped: no MIMU4444 recording (`exp_1/data.bin` ...) was found at `{shown(recordings_dir)}`.",
                END.format(section.name)]), True
        args += [str(r) for r in recs]
        display = list(section.quick if quick else section.full) + [shown(r) for r in recs]
    else:
        display = args
    command = " ".join(["python3", f"tools/{section.script}", *display])
    head += ["```sh", command, "```", ""]
    if note:
        head += [note, ""]
    print(f"benchmarks: {section.name}: {command}", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="gfimu-benchmarks-") as tmp:
        extra = ["--json", str(Path(tmp) / "out.json")] if section.json else []
        done = subprocess.run([sys.executable, str(TOOLS / section.script), *args, *extra], cwd=tmp,
                              capture_output=True, text=True)
    took = time.perf_counter() - t0
    if done.returncode != 0:
        tail = "\n".join(done.stderr.strip().splitlines()[-15:]) or "(nothing on standard error)"
        print(f"benchmarks: {section.name}: failed (exit status {done.returncode}) after {took:.0f} s:\n{tail}",
              file=sys.stderr)
        body = [f"**Failed** (exit status {done.returncode}) when this page was made; the end of its standard "
                "error:", "", "```text", tail, "```"]
        return "\n".join(head + body + [END.format(section.name)]), False
    print(f"benchmarks: {section.name}: done in {took:.0f} s", file=sys.stderr, flush=True)
    return "\n".join(head + [to_markdown(done.stdout, section.drop), END.format(section.name)]), True


def header(when: str, quick: bool, argv: list[str], names: list[str]) -> str:
    lines = [MARK.format("header"), "# Benchmarks", "",
             "Accuracy and speed of gfimu, each table under the command that printed it (run from the "
             "repository's root). The page is written by `python3 tools/benchmarks.py --out docs/benchmarks.md`, "
             "which runs those commands; nothing on it is copied by hand.", "",
             f"Made on {when}, {commit()}, on {machine()}; 1-minute load average "
             f"{os.getloadavg()[0]:.1f} at the start (wall times on a busy machine are pessimistic; the CPU "
             "times less so).", "",
             f"Command: `python3 tools/benchmarks.py {' '.join(argv)}`.", ""]
    if quick:
        lines += ["**Quick run** (`--quick`): short logs, few repeats, one recording and no memory run of the "
                  "fixed-lag smoother, to show that every command runs. Its figures are not the accuracy and speed "
                  "a full run measures (`python3 tools/benchmarks.py --out docs/benchmarks.md`).", ""]
    lines += [section_list(names), END.format("header")]
    return "\n".join(lines)


def section_list(names: list[str]) -> str:
    """The header's line of links to the sections ``names``."""
    return "Sections: " + ", ".join(f"[{BY_NAME[n].title.lower()}](#{anchor(BY_NAME[n].title)})" for n in names) + "."


def anchor(title: str) -> str:
    """GitHub's anchor of a heading."""
    return re.sub(r"[^\w\- ]", "", title.lower()).replace(" ", "-")


def read_page(path: Path) -> dict[str, str]:
    """The sections (and the header) of a page this script wrote, by name."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise PageError(f"{path}: cannot be read ({exc.strerror or exc})") from exc
    parts = {}
    for name in ["header", *BY_NAME]:
        start, end = text.find(MARK.format(name)), text.find(END.format(name))
        if start >= 0 and end > start:
            parts[name] = text[start:end + len(END.format(name))]
    if "header" not in parts:
        raise PageError(f"{path}: not a page written by tools/benchmarks.py (no '{MARK.format('header')}' "
                        "marker); give another --out, or remove the file")
    return parts


def write_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="the page to write (e.g. docs/benchmarks.md)")
    ap.add_argument("--quick", action="store_true", help="short logs and few repeats: a check that the page can be made")
    ap.add_argument("--only", action="append", default=[], metavar="NAME",
                    help="run only this section (repeatable or comma-separated; --list names them) and replace it "
                         "in the existing page")
    ap.add_argument("--recordings", type=Path, default=DEFAULT_RECORDINGS, metavar="DIR",
                    help=f"folder holding exp_1/data.bin ... (default {shown(DEFAULT_RECORDINGS)})")
    ap.add_argument("--list", action="store_true", help="list the sections and their commands, and exit")
    args = ap.parse_args(argv)
    if args.list:
        for s in SECTIONS:
            recs = ([" ".join(n + "/data.bin" for n in RECORDING_NAMES)], ["exp_1/data.bin"]) if s.recordings else ([], [])
            full, quick = " ".join([*s.full, *recs[0]]), " ".join([*s.quick, *recs[1]])
            print(f"{s.name:20s} tools/{s.script} {full}  (--quick: {quick or 'no arguments'})")
        return 0
    if args.out is None:
        ap.error("--out PAGE is required (e.g. --out docs/benchmarks.md)")
    only = [n.strip() for item in args.only for n in item.split(",") if n.strip()]
    unknown = [n for n in only if n not in BY_NAME]
    if unknown:
        ap.error(f"--only: no section {', '.join(map(repr, unknown))}; the sections are {', '.join(BY_NAME)}")
    if args.out.exists() and not args.out.is_file():
        ap.error(f"--out {args.out}: not a regular file")
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    parts: dict[str, str] = {}
    note = None
    old: dict[str, str] = {}
    if args.out.exists():
        try:
            old = read_page(args.out)
        except PageError as exc:
            print(f"benchmarks: error: {exc}", file=sys.stderr)
            return 2
    if only and args.out.exists():
        parts = dict(old)
        note = (f"*This section alone was run again on {when}, {commit()}, on {machine()}, load average "
                f"{os.getloadavg()[0]:.1f}, {'a quick run (`--quick`)' if args.quick else 'a full run'}; the "
                "header's date and run are the other sections'.*")
    else:
        parts["header"] = header(when, args.quick, argv, only or list(BY_NAME))
    ok = True
    for s in SECTIONS:
        if only and s.name not in only:
            continue
        if (s.lacks_data() or (s.recordings and not recordings(args.recordings, args.quick))) and s.name in old \
                and "\nSkipped: " not in old[s.name]:
            print(f"benchmarks: {s.name}: its data are not here; the page's section kept as it was", file=sys.stderr)
            parts[s.name] = old[s.name]
            continue
        parts[s.name], good = run_section(s, args.quick, args.recordings, note)
        ok &= good
    if only:  # the header's list of links names every section the page now holds
        present = [n for n in BY_NAME if n in parts]
        parts["header"] = re.sub(r"^Sections: .*$", lambda _: section_list(present), parts["header"], count=1,
                                 flags=re.M)
    page = "\n\n".join(parts[n] for n in ["header", *BY_NAME] if n in parts) + "\n"
    write_atomic(args.out, page)
    print(f"benchmarks: written {args.out}" + ("" if ok else " (with failed sections)"), file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
