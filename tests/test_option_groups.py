"""The smoothers' options as nested dataclasses per group (gfimu.smoother.option_groups.nested), with the
flat names unchanged."""

from __future__ import annotations

from dataclasses import FrozenInstanceError, fields

import pytest

from gfimu.methods import make_estimator
from gfimu.smoother.graph import SmootherOptions
from gfimu.smoother.option_groups import GROUPS, flatten, nested


def test_nested_options_hold_every_flat_option_once_under_its_group():
    opt = SmootherOptions(motion_model="snap", window_s=10.0, tune_accel_noise=True)
    g = nested(opt)
    assert g.model.motion_model == "snap" and g.batch.window_s == 10.0 and g.tuning.tune_accel_noise is True
    seen = [f.name for part in fields(g) for f in fields(getattr(g, part.name))]
    assert sorted(seen) == sorted(f.name for f in fields(SmootherOptions))
    assert [f.name for f in fields(g.model)] == [n for n in GROUPS["model"] if n in seen]
    assert fields(g.fixed_lag) == () and fields(g.other) == ()  # the batch options have no fixed-lag ones
    with pytest.raises(FrozenInstanceError):
        g.model.motion_model = "jerk"
    assert flatten(SmootherOptions, g) == opt
    assert flatten(SmootherOptions, g, window_s=20.0) == SmootherOptions(motion_model="snap", window_s=20.0,
                                                                       tune_accel_noise=True)
    with pytest.raises(TypeError, match="no option lag_s"):
        flatten(SmootherOptions, g, lag_s=0.1)


def test_an_estimator_s_own_options_are_grouped_too():
    est = make_estimator("fixed-lag", lag_s=0.1, engine="gtsam")
    g = nested(est)
    assert g.fixed_lag.lag_s == 0.1 and g.fixed_lag.engine == "gtsam" and g.model.motion_model == "jerk"
    assert flatten(type(est), g) == est
