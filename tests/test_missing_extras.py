"""A missing optional package is one error, :class:`gfimu.errors.MissingExtraError` (a ResourceError): the
command ends with exit status 1 and one line naming the package and the extra that installs it.

Each test hides one package (``sys.modules[name] = None``: its import then fails as if it were not
installed) and runs the command that needs it."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

from gfimu.cli import error_message, main
from gfimu.errors import MissingExtraError, ResourceError


def hide(monkeypatch, *names: str) -> None:
    """Make ``import name`` (and of its submodules) fail, as without the package installed."""
    for name in names:
        for loaded in [m for m in list(sys.modules) if m == name or m.startswith(name + ".")]:
            monkeypatch.delitem(sys.modules, loaded)
        monkeypatch.setitem(sys.modules, name, None)


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("extras")
    assert main(["simulate", "random3d", "--out", str(d / "log"), "--rate-hz", "100", "--duration-s", "1", "-q"]) == 0
    assert main(["estimate", str(d / "log"), "--method", "inversion", "--out", str(d / "est.csv"), "-q"]) == 0
    return d


@pytest.fixture
def work(tmp_path, base) -> Path:
    shutil.copytree(base / "log", tmp_path / "log")
    shutil.copy(base / "est.csv", tmp_path / "est.csv")
    return tmp_path


def refused(args: list[str], capsys, message: str) -> None:
    rc = main(args)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1
    assert err[-1] == f"gfimu {args[0]}: error: {message}", err


def test_the_error_is_a_resource_error_naming_the_extra():
    exc = MissingExtraError("gfimu plot", "matplotlib", "plot")
    assert isinstance(exc, ResourceError) and exc.exit_status == 1 and (exc.package, exc.extra) == ("matplotlib", "plot")
    assert error_message(exc) == ("gfimu plot needs matplotlib, which is not installed: pip install 'gfimu[plot]'", 1)


def test_plot_without_matplotlib(work, monkeypatch, capsys):
    hide(monkeypatch, "matplotlib")
    refused(["plot", str(work / "log"), str(work / "est.csv"), "--out", str(work / "f.png")], capsys,
            "gfimu plot needs matplotlib, which is not installed: pip install 'gfimu[plot]'")
    assert not (work / "f.png").exists()


def test_diagnose_figure_without_matplotlib(work, monkeypatch, capsys):
    hide(monkeypatch, "matplotlib")
    refused(["diagnose", str(work / "log"), "--figure", str(work / "d.png"), "-q"], capsys,
            "drawing figures needs matplotlib, which is not installed: pip install 'gfimu[plot]'")
    assert not (work / "d.png").exists()


TWO = "t [ms],l_x [g],l_y [g],l_z [g],r_x [g],r_y [g],r_z [g]\n0,0,0,1,0,0,1\n2,0,0,1,0,0,1\n"
TWO_MAP = ('format = "gfimu-csv-map/1"\n[time]\ncolumn = "t"\n'
           '[[accelerometers]]\nname = "left"\nx = "l_x"\ny = "l_y"\nz = "l_z"\n'
           '[[accelerometers]]\nname = "right"\nx = "r_x"\ny = "r_y"\nz = "r_z"\n')


def test_kalibr_extrinsics_without_pyyaml(tmp_path, monkeypatch, capsys):
    (tmp_path / "f.csv").write_text(TWO)
    (tmp_path / "map.toml").write_text(TWO_MAP)
    chain = tmp_path / "kalibr.yaml"
    chain.write_text("imu0:\n  T_i_b: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n")
    hide(monkeypatch, "yaml")
    refused(["convert", "csv", str(tmp_path / "f.csv"), "--map", str(tmp_path / "map.toml"), "--extrinsics",
             str(chain), "--out", str(tmp_path / "log")], capsys,
            f"{chain}: reading YAML needs pyyaml, which is not installed: pip install 'gfimu[kalibr]'")
    assert not (tmp_path / "log").exists() or not any((tmp_path / "log").iterdir())


def test_a_ros2_bag_without_pyyaml_names_the_rosbag_extra(work, monkeypatch, capsys):
    """rosbags reads YAML with ruamel; gfimu reads the bag's metadata.yaml with pyyaml, which the rosbag extra
    installs too."""
    bag = work / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  version: 5\n")
    hide(monkeypatch, "yaml")
    refused(["convert", "rosbag", str(bag), "--array", str(work / "log" / "array.toml"), "--out", str(work / "out")],
            capsys, f"{bag / 'metadata.yaml'}: reading YAML needs pyyaml, which is not installed: "
                    "pip install 'gfimu[rosbag]'")
    assert not (work / "out").exists()


def test_live_serial_source_without_pyserial(work, monkeypatch, capsys):
    hide(monkeypatch, "serial")
    source = "serial:///dev/null?baud=115200"
    refused(["live", "--array", str(work / "log" / "array.toml"), "--source", source, "--out", str(work / "live.csv")],
            capsys, f"--source {source}: a serial port needs pyserial, which is not installed: "
                    "pip install 'gfimu[serial]'")


def test_batch_without_dask(work, monkeypatch, capsys):
    hide(monkeypatch, "dask", "distributed")
    refused(["batch", str(work / "log"), "--out", str(work / "out")], capsys,
            "gfimu batch needs dask.distributed, which is not installed: pip install 'gfimu[distributed]'")
    assert not (work / "out").exists()


def test_data_frames_without_pandas(work, monkeypatch):
    """pandas has no command: the Python call raises the error, and the command line would print its line."""
    from gfimu import read_log

    log = read_log(work / "log")
    hide(monkeypatch, "pandas")
    with pytest.raises(MissingExtraError) as caught:
        log.to_dataframe()
    assert error_message(caught.value) == (
        "Log.to_dataframe needs pandas, which is not installed: pip install 'gfimu[pandas]'", 1)
    with pytest.raises(MissingExtraError, match=r"^Motion.to_dataframe needs pandas.*gfimu\[pandas\]'$"):
        log.truth.to_dataframe()
