"""The smoothers' options listed in their groups (model, solve, batch, stream, tuning, guard, ...), every one documented;
the flat ``-O name=value`` keeps working, and an option of the other smoother's own group is refused where the
options are read (exit 2, one line naming it)."""

import dataclasses
import io
from types import SimpleNamespace

import pytest

from gfimu import io as gio
from gfimu.cli import main
from gfimu.cli.options import OptionError, parse_options
from gfimu.methods import estimator_class, make_estimator, resolve_options
from gfimu.simulate import simulate
from gfimu.smoother.model.option_groups import GROUPS


@pytest.mark.parametrize("method, groups", [("smoother", ("model", "solve", "batch_model", "attitude", "self_calibration",
                                                          "batch", "tuning", "guard")),
                                            ("fixed-lag", ("model", "solve", "stream", "tuning", "guard"))])
def test_every_smoother_option_is_listed_under_its_group(method, groups):
    names = [f.name for f in dataclasses.fields(estimator_class(method)) if f.init]
    assert sorted(names) == sorted(n for g in groups for n in GROUPS[g])
    text = resolve_options(method).describe()
    assert [line for line in text.splitlines() if line.startswith("[")] == [f"[{g}]" for g in groups]
    for group in groups:
        block = text.split(f"[{group}]\n", 1)[1].split("\n[", 1)[0]
        listed = [line.split(" = ")[0] for line in block.splitlines() if " = " in line and not line.startswith(" ")]
        assert listed == list(GROUPS[group]), group


def test_flat_options_keep_working():
    # None where the declaration allows it: window_s=None solves the whole log at once
    assert resolve_options("smoother", parse_options(["window_s=None", "tune_span_s=None"])).options == {
        "window_s": None, "tune_span_s": None}
    assert resolve_options("fixed-lag", parse_options(["marginalise_every_s=None"])).options == {
        "marginalise_every_s": None}
    with pytest.raises(OptionError, match=r"^-O lag_s=None: expected a number > 0 \[s\] \(option of method 'fixed-lag', "):
        resolve_options("fixed-lag", parse_options(["lag_s=None"])).options
    est = make_estimator("smoother", window_s=10.0, solver="gtsam", tune_span_s=None)
    assert est.window_s == 10.0 and est.solver == "gtsam" and est.tune_span_s is None
    est = make_estimator("smoother", preset="hand-held-low-rate", window_s=10.0)
    assert est.initialisation == "ml" and est.reweight_iterations == 5 and est.window_s == 10.0


@pytest.fixture(scope="module")
def log_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("options") / "log"
    gio.write_log(simulate("reversal", duration_s=1.0, seed=3), folder)
    return folder


def _files(folder):
    return {p.name: p.read_bytes() for p in folder.iterdir()}


@pytest.mark.parametrize("method, option, kind, owner", [
    ("fixed-lag", "window_s=10", "batch-smoother", "smoother"),
    ("fixed-lag", "reweight_iterations=2", "batch-smoother", "smoother"),
    ("smoother", "lag_s=0.1", "fixed-lag-smoother", "fixed-lag"),
    ("smoother", "retune_every_s=5", "fixed-lag-smoother", "fixed-lag"),
])
def test_the_other_smoother_s_option_is_refused_when_parsed(log_dir, tmp_path, capsys, method, option, kind, owner):
    before = _files(log_dir)
    out = tmp_path / "est.csv"
    assert main(["estimate", str(log_dir), "--method", method, "-O", option, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    name = option.split("=")[0]
    assert err == [f"gfimu estimate: error: -O {option}: {name} is a {kind} option (method {owner!r}, group "
                   f"[{'batch' if owner == 'smoother' else 'stream'}]); method {method!r} does not take it"]
    assert not out.exists() and _files(log_dir) == before


def test_estimate_refuses_two_different_lags(log_dir, tmp_path, capsys):
    out = tmp_path / "est.csv"
    assert main(["estimate", str(log_dir), "--method", "fixed-lag", "-O", "lag_s=0.3", "--lag-s", "0.2",
                 "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip() == ("gfimu estimate: error: --lag-s 0.2 and -O lag_s=0.3 disagree; "
                                               "give the lag once")
    assert not out.exists()


def test_live_refuses_a_batch_option_before_opening_anything(log_dir, tmp_path, capsys):
    out = tmp_path / "live.csv"
    assert main(["live", "--array", str(log_dir / "array.toml"), "--source", "udp://127.0.0.1:9",
                 "--out", str(out), "-O", "overlap_s=1"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "gfimu live: error: -O overlap_s=1: overlap_s is a batch-smoother option (method 'smoother', group [batch]); "
        "method 'fixed-lag' does not take it"]
    assert not out.exists()


def test_compare_names_the_method_of_the_refused_option(log_dir, tmp_path, capsys):
    assert main(["compare", str(log_dir), "--methods", "inversion,fixed-lag", "-O", "fixed-lag.overlap_s=1",
                 "--out", str(tmp_path / "cmp.csv")]) == 2
    err = capsys.readouterr().err
    assert "-O fixed-lag.overlap_s=1: overlap_s is a batch-smoother option" in err


def test_live_takes_the_lag_from_o_or_from_lag_s_and_refuses_both_disagreeing(log_dir, tmp_path, capsys,
                                                                              monkeypatch):
    import gfimu.live

    made = []

    def fake_run(source, estimator, sink, **kwargs):  # the session itself is tested in test_live.py
        made.append(estimator)
        return SimpleNamespace(failure=None, summary=lambda: "0 samples", signal_exit=None, ended="end of input")

    monkeypatch.setattr(gfimu.live, "run", fake_run)
    monkeypatch.setattr("sys.stdin", io.StringIO(""))
    base = ["live", "--array", str(log_dir / "array.toml"), "--rate-hz", "500", "--source", "-", "--quiet"]
    assert main(base + ["--out", str(tmp_path / "a.csv"), "-O", "lag_s=0.3"]) == 0
    assert main(base + ["--out", str(tmp_path / "b.csv"), "--lag-s", "0.1"]) == 0
    assert main(base + ["--out", str(tmp_path / "c.csv")]) == 0
    assert [e.lag_s for e in made] == [0.3, 0.1, 0.2]
    capsys.readouterr()
    assert main(base + ["--out", str(tmp_path / "d.csv"), "-O", "lag_s=0.3", "--lag-s", "0.2"]) == 2
    assert "gfimu live: error: --lag-s 0.2 and -O lag_s=0.3 disagree; give the lag once" in capsys.readouterr().err
    assert len(made) == 3 and not (tmp_path / "d.csv").exists()
