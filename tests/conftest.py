import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
MIMU4444_DIR = Path(os.environ.get("GFIMU_MIMU4444_DIR", REPO.parent / "shared" / "data" / "mimu4444"))


@pytest.fixture
def mimu4444_dir() -> Path:
    """Folder of the real MIMU4444 recordings; skips the test when absent."""
    if not (MIMU4444_DIR / "exp_1" / "data.bin").is_file():
        pytest.skip(f"MIMU4444 recordings not found at {MIMU4444_DIR}")
    return MIMU4444_DIR
