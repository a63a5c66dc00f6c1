"""Ground truth of joined potholes: nested ones are one defect (synth.pothole_groups)."""

import math

import numpy as np
import pytest

from d3cli.data import synth

NO_WOBBLE = (0.0, 0.0, 0.0, 0.0)


def hole(x, y, r, depth, flat):
    return synth.Pothole(x, y, r, r, 0.0, depth, flat, NO_WOBBLE)


def opening_radius(r, depth, flat, t=0.01):
    """Radius where a round hole of the synth profile is t deep (inverse raised cosine)."""
    return r * (flat + (1 - flat) * math.acos(2 * t / depth - 1) / math.pi)


def test_a_pit_inside_a_shallower_potholes_opening_joins_it():
    # 50 mm pit 0.1 m from the centre of a 25 mm pothole of 0.35 m: inside its opening.
    holes = [hole(-0.05, 1.6, 0.35, 0.025, 0.7), hole(0.05, 1.6, 0.15, 0.05, 0.5)]
    assert opening_radius(0.35, 0.025, 0.7) > 0.1
    assert synth.pothole_groups(holes) == [1, 1]


def test_a_shallow_pothole_beside_a_deeper_one_stays_separate():
    # Centres 0.3 m apart, each outside the other's opening (0.191 m, 0.213 m): two defects,
    # although the shallow floor runs into the deep wall (no saddle).
    holes = [hole(0.15, 1.6, 0.25, 0.05, 0.5), hole(-0.15, 1.6, 0.22, 0.025, 0.7)]
    assert opening_radius(0.22, 0.025, 0.7) == pytest.approx(0.191, abs=1e-3)
    assert opening_radius(0.25, 0.05, 0.5) == pytest.approx(0.213, abs=1e-3)
    assert synth.pothole_groups(holes) == [0, 1]


def test_a_shelf_joins_the_nearest_deeper_pit_only():
    # A wide 30 mm pothole holds the centres of two deeper pits; it joins the nearer one
    # (its concentric pit) and the other pit, outside that pit's opening, stays its own.
    holes = [hole(-0.3, 1.6, 0.15, 0.055, 0.6), hole(0.0, 1.6, 0.35, 0.03, 0.7), hole(0.05, 1.6, 0.2, 0.045, 0.6)]
    assert synth.pothole_groups(holes) == [0, 2, 2]


def test_nested_truth_is_the_union_under_the_deepest_id():
    holes = [hole(-0.05, 1.6, 0.35, 0.025, 0.7), hole(0.05, 1.6, 0.15, 0.05, 0.5)]
    rig = synth.StereoRig(f=500.0, baseline=0.12, cx=99.5, cy=99.5, width=200, height=200, height_m=1.5,
                          pitch_deg=45.0, roll_deg=0.0)
    xs, ys = np.meshgrid(np.linspace(-0.5, 0.5, 200), np.linspace(1.1, 2.1, 200))
    points = np.stack([xs, ys, np.zeros_like(xs)], axis=-1)
    ids, truth = synth.pothole_truth(holes, rig, points)
    shallow, deep = truth
    assert shallow["part_of"] == 2 and shallow["visible_px"] == 0 and shallow["area_m2"] == 0.0
    assert deep["members"] == [1, 2] and deep["depth_mm"] == pytest.approx(50.0)
    assert set(np.unique(ids)) == {0, 2} and deep["visible_px"] == int((ids == 2).sum())
    # The pit lies wholly inside the shallow opening: the union's 10 mm area is the shallow
    # hole's own, pi r^2; the volume adds the pit's extra depth.
    assert deep["area_m2"] == pytest.approx(math.pi * opening_radius(0.35, 0.025, 0.7) ** 2, rel=0.01)
    assert deep["volume_l"] > 0
