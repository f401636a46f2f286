import subprocess
import sys
import tomllib
from pathlib import Path


def test_version_matches_pyproject():
    root = Path(__file__).resolve().parents[1]
    expected = tomllib.loads((root / "pyproject.toml").read_text())["project"]["version"]
    out = subprocess.run([sys.executable, "-m", "gfimu", "--version"], capture_output=True, text=True, cwd=root)
    assert out.returncode == 0
    assert out.stdout.strip() == f"gfimu {expected}"
