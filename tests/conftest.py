import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
MIMU4444_DIR = Path(os.environ.get("GFIMU_MIMU4444_DIR", REPO.parent / "shared" / "data" / "mimu4444"))


@pytest.fixture(scope="session")
def mimu4444_dir() -> Path:
    """Folder of the real MIMU4444 recordings; skips the test when absent."""
    if not (MIMU4444_DIR / "exp_1" / "data.bin").is_file():
        pytest.skip(f"MIMU4444 recordings not found at {MIMU4444_DIR}")
    return MIMU4444_DIR


@pytest.fixture(scope="session")
def turntable_5cm_smoother():
    """Lu, Tsai & Lin 2010's 1 Hz turntable, 6 s at 500 Hz (seed 1), on a 5 cm cube at 0.07 m/s², and the default batch
    smoother's estimate of it, computed once for the tests that check it: (log, report, motion) of the run."""
    from gfimu.array import cube_array
    from gfimu.simulate import simulate
    from gfimu.smoother.batch.engine import BatchSmootherEstimator

    log = simulate("turntable", cube_array(0.025, noise_std_mps2=0.07), rate_hz=500.0, duration_s=6.0, seed=1)
    estimate = BatchSmootherEstimator().estimate(log)
    return log, estimate.report, estimate.motion
