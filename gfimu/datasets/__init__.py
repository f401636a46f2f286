"""Public datasets used by :mod:`gfimu.simulate`.

* :mod:`gfimu.datasets.gtsam_recordings`: the EuRoC and KITTI IMU recordings
  shipped with the gtsam package (real motions for :mod:`gfimu.simulate`).

Recorded formats that ``gfimu convert`` reads are in :mod:`gfimu.io.readers`.
"""
