"""tools/benchmarks.py, the writer of docs/benchmarks.md: its text from a script's output, its refusals, a
failed script, one section replaced in a page it wrote (without running the long scripts)."""

import importlib.util
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "tools" / "benchmarks.py"
_spec = importlib.util.spec_from_file_location("tools_benchmarks", SCRIPT)
bench = importlib.util.module_from_spec(_spec)
sys.modules["tools_benchmarks"] = bench  # its dataclass looks its module up
_spec.loader.exec_module(bench)


def run(*args):
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=120)


def test_a_scripts_output_becomes_page_text():
    tmp = tempfile.gettempdir()
    out = (f"# 2026-01-02, host, 2 cores, x86_64\ncube half edge 0.025 m\n| a | b |\n|---|---|\n| 1 | 2 |\n"
           f"note one\nnote two\n\nend to end: gfimu estimate {tmp}/tmpab_1x/log --out {tmp}/tmpab_1x/est.csv\n"
           "\nresults written to bench.json\nwritten smoother_accuracy.json\n")
    assert bench.to_markdown(out, bench.DROP) == (
        "cube half edge 0.025 m\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\nnote one\n\nnote two\n\n"
        "end to end: gfimu estimate log --out est.csv")


def test_a_page_not_written_by_the_script_is_refused_and_left_as_it_was(tmp_path):
    page = tmp_path / "notes.md"
    page.write_bytes(b"# my notes\n")
    done = run("--out", str(page), "--only", "startup")
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and str(page) in done.stderr and "not a page written by" in done.stderr
    assert page.read_bytes() == b"# my notes\n"


def test_an_unknown_section_is_refused_with_the_names(tmp_path):
    done = run("--out", str(tmp_path / "b.md"), "--only", "startup,speed")
    assert done.returncode == 2 and "no section 'speed'" in done.stderr and "reader-memory" in done.stderr
    assert not (tmp_path / "b.md").exists()


def test_a_failing_script_leaves_its_section_saying_so():
    section = bench.Section("x", "X", "bench_startup.py", "What it measures.", full=("--repeats", "zero"))
    text, ok = bench.run_section(section, False, REPO, None)
    assert not ok
    assert "python3 tools/bench_startup.py --repeats zero" in text
    assert "**Failed** (exit status 2)" in text and "invalid int value: 'zero'" in text
    assert text.startswith(bench.MARK.format("x")) and text.endswith(bench.END.format("x"))


@pytest.mark.slow
def test_only_replaces_its_section_and_keeps_the_others(tmp_path):
    """--only startup: that section is run again and says when, the header and the other sections stay byte
    for byte; --only real-flow without recordings keeps that section's figures as they were (said on standard
    error), and on a page without them says it was skipped."""
    sections = [bench.MARK.format("header") + "\n# Benchmarks\nMade on an earlier day.\n" + bench.END.format("header"),
                bench.MARK.format("smoother-accuracy") + "\n| old table |\n" + bench.END.format("smoother-accuracy"),
                bench.MARK.format("real-flow") + "\nold figures\n" + bench.END.format("real-flow"),
                bench.MARK.format("startup") + "\n| startup |\n" + bench.END.format("startup")]
    page = tmp_path / "benchmarks.md"
    page.write_text("\n\n".join(sections) + "\n", encoding="utf-8")
    done = run("--out", str(page), "--only", "startup", "--quick")
    assert done.returncode == 0, done.stderr
    text = page.read_text(encoding="utf-8")
    assert text.startswith("\n\n".join(sections[:3]) + "\n\n" + bench.MARK.format("startup"))
    assert "| startup |" not in text and "This section alone was run again on" in text
    before = text
    done = run("--out", str(page), "--only", "real-flow", "--recordings", str(tmp_path / "none"))
    assert done.returncode == 0, done.stderr
    assert page.read_text(encoding="utf-8") == before and "real-flow: its data are not here" in done.stderr
    page.write_text("\n\n".join(sections[:2] + sections[3:]) + "\n", encoding="utf-8")
    done = run("--out", str(page), "--only", "real-flow", "--recordings", str(tmp_path / "none"))
    assert done.returncode == 0, done.stderr
    text = page.read_text(encoding="utf-8")
    assert text.startswith(sections[0] + "\n\n" + sections[1] + "\n\n" + bench.MARK.format("real-flow"))
    assert text.endswith(bench.END.format("real-flow") + "\n\n" + sections[3] + "\n")
    assert f"was found at `{tmp_path / 'none'}`" in text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["benchmarks.md"]  # no temporary file left


def test_only_names_every_section_of_the_page_in_the_header(tmp_path):
    """A header whose list of sections is stale: after --only, it links every section the page holds, in the
    page's order, and its other lines stay as they were."""
    sections = [bench.MARK.format("header") + "\n# Benchmarks\nMade on an earlier day.\n\nSections: [old](#old).\n"
                + bench.END.format("header"),
                bench.MARK.format("smoother-accuracy") + "\n| old table |\n" + bench.END.format("smoother-accuracy"),
                bench.MARK.format("startup") + "\n| startup |\n" + bench.END.format("startup")]
    page = tmp_path / "benchmarks.md"
    page.write_text("\n\n".join(sections) + "\n", encoding="utf-8")
    done = run("--out", str(page), "--only", "real-flow", "--recordings", str(tmp_path / "none"))
    assert done.returncode == 0, done.stderr
    header = page.read_text(encoding="utf-8").split(bench.END.format("header"))[0]
    names = ["smoother-accuracy", "real-flow", "startup"]
    assert bench.section_list(names) in header and "[old](#old)" not in header
    assert "Made on an earlier day." in header
