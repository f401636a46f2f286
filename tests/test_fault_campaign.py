"""A representative part of tools/fault_campaign.py (one case of each kind of fault and of each command):
every case's verdict is 'ok' (exit status, one error line naming the thing, inputs unchanged, nothing
written outside the output folder, no hang)."""

from __future__ import annotations

import importlib.util
import sys
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SUBSET = (
    "imu-empty", "imu-nul-50MB", "imu-nan", "imu-all-nan", "imu-huge-value", "imu-unsorted", "imu-duplicate-time",
    "array-deep", "array-huge-position", "array-not-rotation", "truth-nan", "calibration-deep",
    "calibration-int-sensors", "map-int-delimiter", "map-deep", "csv-nul-50MB", "kalibr-deep", "mimu-garbage",
    "bag-text", "opt-initial-omega", "opt-initial-omega-short", "opt-huge-value", "out-symlink-to-input",
    "out-batch-onto-log", "compare-estimates-into-log", "out-missing-folder", "out-is-folder", "live-binary",
    "smoother-huge-value", "calibrate-nan-column", "ok-estimate", "live-huge-values", "opt-ml-grid-zero",
    "opt-smoother-noise-1e-320", "calibration-list-of-ints", "bag-imu-nan",
)


def _campaign():
    spec = importlib.util.spec_from_file_location("fault_campaign", REPO / "tools" / "fault_campaign.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["fault_campaign"] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


CONTAINMENT = (
    "batch-link-in-out", "batch-same-folder-names", "batch-log-twice", "batch-log-named-summary",
    "batch-scheduler-ssh", "live-g-header", "live-guard-replace", "live-udp-no-port", "live-serial-baud-negative",
    "live-1ns-steps", "live-rate-1e9", "array-400-digit-position", "array-range-tiny", "array-noise-1e300",
    "imu-underscore-number", "imu-cr-line-ends", "imu-1ns-steps-fixed-lag", "opt-axis-frequency-1e308",
    "map-column-twice", "map-mg-over-mps2", "mimu-one-packet",
    pytest.param("kalibr-large-no-alias", marks=pytest.mark.slow), "zip-member-twice",
    "simulate-full-disk", "mimu-random-counters", "live-tcp-garbage",
)
"""The cases of live and batch containment, units by any factor, bounded resources and the message cases, each
with the words its standard error must hold (zip-bomb and the large Kalibr file, the slowest to build, run with
the slow tests)."""

campaign = _campaign()
CASES = {c.name: c for c in campaign.cases()}


def test_the_campaign_has_its_cases():
    assert len(CASES) >= 60
    assert set(SUBSET) <= set(CASES)
    commands = {c.command for c in CASES.values()}
    assert commands >= {"convert", "estimate", "evaluate", "compare", "diagnose", "calibrate", "plot", "batch",
                        "simulate", "live"}


@pytest.fixture(scope="module")
def base():
    with tempfile.TemporaryDirectory(prefix="gfimu-faults-test-") as tmp:
        root = Path(tmp)
        (root / "base").mkdir()
        (root / "work").mkdir()
        campaign.build_base(root / "base")
        yield root


@pytest.mark.parametrize("name", SUBSET)
def test_case(base, name):
    result = campaign.run_case(CASES[name], base / "base", base / "work")
    assert result["verdict"] == "ok", result
    if CASES[name].expect:
        assert result["exit"] in CASES[name].expect


def test_a_broken_command_is_caught(base, monkeypatch):
    """The checks can fail: a case whose expected exit is not met, and an input changed, are verdict FAIL."""
    case = campaign.Case("probe", ["estimate", "{w}/log", "--method", "inversion", "--out", "{w}/log/imu.csv"],
                         ["log/imu.csv"], expect={0})
    result = campaign.run_case(case, base / "base", base / "work")
    assert result["verdict"] == "FAIL" and result["exit"] == 2
    assert "exit 2, expected [0]" in result["problems"]
    touch = campaign.Case("touch", ["estimate", "{w}/log", "--method", "inversion", "--out", "{w}/e.csv"],
                          ["log/imu.csv"])
    result = campaign.run_case(touch, base / "base", base / "work")
    assert result["verdict"] == "FAIL" and "e.csv written outside the output folder" in result["problems"]


@pytest.mark.parametrize("name", CONTAINMENT)
def test_containment_case(base, name):
    if name.startswith("mimu-") and not (base / "base" / "data.bin").exists():
        pytest.skip("needs the MIMU4444 recording")
    result = campaign.run_case(CASES[name], base / "base", base / "work")
    assert result["verdict"] == "ok", result
    assert result["exit"] in CASES[name].expect


@pytest.mark.slow
def test_the_zip_bomb_case(base):
    result = campaign.run_case(CASES["zip-bomb"], base / "base", base / "work")
    assert result["verdict"] == "ok" and result["exit"] == 2, result
