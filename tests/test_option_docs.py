"""The smoothers' options listed in their groups (model, batch, fixed-lag, tuning, guard), every one
documented; the flat ``-O name=value`` keeps working."""

import dataclasses

import pytest

from gfimu.cli.options import describe_options
from gfimu.methods import estimator_class, make_estimator
from gfimu.smoother.option_groups import GROUP_OF, GROUPS


@pytest.mark.parametrize("method", ["smoother", "fixed-lag"])
def test_every_smoother_option_has_a_group_and_is_listed_under_it(method):
    names = [f.name for f in dataclasses.fields(estimator_class(method)) if f.init and not f.name.startswith("_")]
    assert not [n for n in names if n not in GROUP_OF]
    text = describe_options(method)
    for group, members in GROUPS.items():
        present = [n for n in members if n in names]
        if not present:
            continue
        block = text.split(f"[{group}]\n", 1)[1].split("\n[", 1)[0]
        for n in present:
            assert f"{n} = " in block, (group, n)


def test_metadata_and_flat_options():
    text = describe_options("smoother")
    assert "solver = 'numpy'\n    batch solver: 'numpy'" in text
    est = make_estimator("smoother", window_s=10.0, solver="gtsam", tune_span_s=None)
    assert est.window_s == 10.0 and est.solver == "gtsam" and est.tune_span_s is None
