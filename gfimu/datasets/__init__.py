"""Readers of public and recorded datasets.

* :mod:`gfimu.datasets.mimu4444`: the MIMU4444 board's recordings.
* :mod:`gfimu.datasets.gtsam_recordings`: the EuRoC and KITTI IMU recordings
  shipped with the gtsam package (real motions for :mod:`gfimu.simulate`).
"""
