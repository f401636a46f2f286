"""tools/replay_udp.py measures the peak memory of the ``gfimu live`` it starts: the command's own, not the
replay tool's (Linux keeps a process's peak resident set across exec, so a child spawned by a process that
once held a lot reports that as its own peak)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from tool_modules import TOOLS, load_tool

HELD_MIB = 300
"""What the measuring process holds (then frees) before the command starts: well above a bare interpreter's
peak (about 10 MiB, 40 with numpy imported), so that the two measures cannot be mistaken."""

SCRIPT = f"""
import json, subprocess, sys
sys.path.insert(0, {str(TOOLS)!r})
import replay_udp
launcher = replay_udp.Launcher()          # started while this process holds little
held = bytearray({HELD_MIB} * 2**20)      # every page written: resident
del held                                  # freed: the peak stays
bare = [sys.executable, "-c", "pass"]
direct = replay_udp._wait_peak_mib(subprocess.Popen(bare), 60.0)
launched = replay_udp._wait_peak_mib(launcher.start(bare), 60.0)
print(json.dumps({{"own": replay_udp._own_peak_mib(), "direct": direct, "launched": launched,
                  "floor": launcher.floor_mib, "rc": launcher.proc.returncode}}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the peak carried across exec is Linux's")
def test_the_peak_of_a_command_started_by_the_launcher_is_its_own():
    """A bare interpreter spawned straight from a process that held 300 MiB reports at least 300 MiB (the
    measure the replay once made of gfimu live: 1,476 MiB after a 600 s stream, this tool's own simulated
    log and rows); started by the launcher made before, it reports its own peak, below 100 MiB."""
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    m = json.loads(out.stdout.strip().splitlines()[-1])
    assert m["rc"] == 0
    assert m["own"] >= HELD_MIB
    assert m["direct"] >= HELD_MIB  # the effect the launcher avoids, on this kernel
    assert m["floor"] < 100
    assert m["launched"] < 100


def test_a_launcher_never_started_ends_on_its_closed_input():
    """A replay that stops before the command (an unknown cell, a log that cannot be read): the launcher
    ends at once, status 0, nothing run."""
    launcher = load_tool("replay_udp").Launcher()
    launcher.proc.stdin.close()
    assert launcher.proc.wait(timeout=30) == 0
    assert launcher.proc.stdout.read() == "" and launcher.proc.stderr.read() == ""
    launcher.proc.stdout.close()
    launcher.proc.stderr.close()
