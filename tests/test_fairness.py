"""Line turns, edge ratios and the angle range of a net, with their worst places."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import measured_saddle_candidate

from fabplan.net.fairness import fairness_record
from fabplan.net.generate import height_field_grid


def test_a_straight_grid_does_not_turn_even_on_a_curved_surface():
    # lines of a paraboloid grid bend with the surface but do not turn in it (by symmetry
    # the x- and y-lines through the apex are geodesics; elsewhere they turn a little)
    flat = height_field_grid(9, 9, lambda x, y: 0 * x)
    record = fairness_record(flat)
    assert record["line_turn_deg"]["max"] == pytest.approx(0.0, abs=1e-9)
    assert record["edge_ratio_along_lines"]["max"] == pytest.approx(1.0)
    assert record["intersection_angle_deg"]["min"] == pytest.approx(90.0)


def test_a_vertex_moved_sideways_is_the_worst_place():
    grid = height_field_grid(9, 9, lambda x, y: 0 * x)
    X = grid.vertices.copy()
    v = 4 * 9 + 4                          # the centre
    X[v, 1] += 0.2                         # across the family-0 line through it
    record = fairness_record(grid, X)
    turn = record["line_turn_deg"]
    # independent: the line bends by twice atan(0.2 / 1) at the moved vertex
    assert turn["max"] == pytest.approx(2 * np.degrees(np.arctan(0.2)), rel=1e-9)
    assert turn["vertex"] == v and turn["point"] == X[v].tolist()
    ratio = record["edge_ratio_along_lines"]
    # the other family's line through it: edges 1.2 and 0.8
    assert ratio["max"] == pytest.approx(1.2 / 0.8) and ratio["vertex"] == v
    assert record["intersection_angle_deg"]["min"] < 90.0


def test_a_study_limits_how_far_the_lines_turn():
    from fabplan.study.run import verdict
    from fabplan.study.spec import Limits

    result, _, metrics = measured_saddle_candidate(5.0)
    turn = metrics["line_turn_deg"]["max"]
    assert turn == result.properties["fairness"]["line_turn_deg"]["max"] and turn > 0

    def check(limit):
        limits = Limits(max_deviation_mm=1e9, mold_tolerance_mm=5.0, max_line_turn_deg=limit)
        return next(c for c in verdict(metrics, limits) if c["limit"] == "max_line_turn_deg")

    assert check(turn * 1.01)["ok"] and not check(turn * 0.99)["ok"]
    assert f"{turn:.2f} deg" in check(turn * 0.99)["text"]
