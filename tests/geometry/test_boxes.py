"""homocal.geometry.boxes: box_iou on ordinary, empty and degenerate boxes; greedy_pairs and link_tracks against
a brute-force greedy matching (every pair, sorted); link_tracks' bound on boxes per frame."""
from __future__ import annotations

import numpy as np
import pytest

import simgen.detection
from homocal.geometry.boxes import (HIDDEN_FEET_PX, MAX_BOXES_PER_FRAME, box_iou, greedy_pairs, hidden_feet, link_tracks,
                                    short_boxes, trim_boxes)

BOX = [0.0, 0.0, 10.0, 10.0]
FAR = [0.0, 0.0, 10.0, 50.0]  # a far person's box: feet at row 50


@pytest.mark.parametrize("other,expected", [
    ([5.0, 40.0, 20.0, 100.0], [True, False]),  # lower, overlapping columns, its head above the far box's feet
    ([5.0, 50.0 + HIDDEN_FEET_PX, 20.0, 100.0], [True, False]),  # its head HIDDEN_FEET_PX below the feet: hides
    ([5.0, 50.0 + 2 * HIDDEN_FEET_PX, 20.0, 100.0], [False, False]),  # its head clear below the feet
    ([10.0, 40.0, 20.0, 100.0], [False, False]),  # columns touching, not overlapping
    ([-20.0, 40.0, 0.5, 100.0], [True, False]),  # half a pixel of overlap on the left
    ([5.0, 0.0, 20.0, 50.0], [False, False]),  # the same foot row: neither is nearer
    ([5.0, 40.0, 20.0, 49.0], [False, True]),  # its feet higher: farther, FAR may hide them
])
def test_hidden_feet_pairs(other, expected):
    assert hidden_feet(np.array([FAR, other]), np.zeros(2, np.int64)).tolist() == expected
    assert hidden_feet(np.array([FAR, other]), np.arange(2)).tolist() == [False, False]  # other frames


def test_hidden_feet_against_every_pair():
    """Random boxes in three frames against the rule written out pair by pair."""
    rng = np.random.default_rng(5)
    n = 60
    x1, y1 = rng.uniform(0, 200, n), rng.uniform(0, 200, n)
    edges = np.column_stack([x1, y1, x1 + rng.uniform(1, 40, n), y1 + rng.uniform(1, 80, n)])
    frames = rng.integers(0, 3, n)
    expected = [any(frames[j] == frames[i] and edges[j, 3] > edges[i, 3] and edges[j, 1] <= edges[i, 3] + HIDDEN_FEET_PX
                    and min(edges[i, 2], edges[j, 2]) > max(edges[i, 0], edges[j, 0]) for j in range(n)) for i in range(n)]
    assert 5 < sum(expected) < n - 5  # the draw holds both kinds
    assert hidden_feet(edges, frames).tolist() == expected
    assert hidden_feet(np.zeros((0, 4)), np.zeros(0, np.int64)).shape == (0,)


@pytest.mark.parametrize("a,b,expected", [
    (BOX, BOX, 1.0),  # the same box
    (BOX, [5.0, 0.0, 15.0, 10.0], 50 / 150),  # half of each overlaps: 50 / (100 + 100 - 50)
    (BOX, [2.0, 2.0, 4.0, 4.0], 4 / 100),  # one inside the other
    (BOX, [10.0, 0.0, 20.0, 10.0], 0.0),  # touching edges
    (BOX, [20.0, 20.0, 30.0, 30.0], 0.0),  # apart
    (BOX, [5.0, 5.0, 5.0, 5.0], 0.0),  # an empty box (a point) inside a box
    ([5.0, 5.0, 5.0, 5.0], [5.0, 5.0, 5.0, 5.0], 0.0),  # two empty boxes: the union is 0
    (BOX, [0.0, 5.0, 10.0, 5.0], 0.0),  # a zero-height box
    (BOX, [10.0, 10.0, 0.0, 0.0], 0.0),  # upside down: area 0, not -100
    ([10.0, 10.0, 0.0, 0.0], [10.0, 10.0, 0.0, 0.0], 0.0),  # both upside down
    (BOX, [np.nan, 0.0, 10.0, 10.0], np.nan),
])
def test_box_iou(a, b, expected):
    got = box_iou(np.array([a]), np.array([b]))
    assert got.shape == (1, 1)
    np.testing.assert_allclose(got, [[expected]], rtol=1e-12)
    np.testing.assert_allclose(box_iou(np.array([b]), np.array([a])), [[expected]], rtol=1e-12)  # symmetric


def test_box_iou_shapes_and_one_function():
    assert box_iou(np.zeros((0, 4)), np.ones((3, 4))).shape == (0, 3)
    assert box_iou(BOX, [BOX, BOX]).shape == (1, 2)  # a single box is one row
    assert simgen.detection.box_iou is box_iou  # simgen associates detections with homocal's


def brute_greedy(score: np.ndarray, min_score: float) -> list[tuple[int, int]]:
    """Every pair at or above min_score, sorted by (-score, row, column), taken while both are free."""
    pairs = sorted((-score[i, j], i, j) for i in range(score.shape[0]) for j in range(score.shape[1])
                   if score[i, j] >= min_score)
    rows, cols, taken = set(), set(), []
    for _, i, j in pairs:
        if i not in rows and j not in cols:
            rows.add(i), cols.add(j), taken.append((i, j))
    return taken


@pytest.mark.parametrize("seed", range(20))
def test_greedy_pairs_is_the_greedy_matching(seed):
    rng = np.random.default_rng(seed)
    score = rng.integers(0, 4, (rng.integers(1, 12), rng.integers(1, 12))) / 4.0  # many ties
    rows, cols = np.nonzero(score >= 0.25)
    r, c = greedy_pairs(rows, cols, score[rows, cols], score.shape[1])
    assert list(zip(r.tolist(), c.tolist())) == brute_greedy(score, 0.25)  # the same pairs, in the order taken


def brute_link(frames: np.ndarray, xyxy: np.ndarray, min_iou: float = 0.3, max_gap: int = 5) -> np.ndarray:
    """link_tracks' rule, written out: frame by frame, the greedy matching of the frame's boxes (in index order)
    with the tracks last seen at most max_gap frames earlier (in id order) over every pair's IoU."""
    ids = np.full(len(frames), -1)
    last = {}  # track id -> (frame, box)
    for frame in sorted(set(frames.tolist())):
        rows = np.flatnonzero(frames == frame)
        live = [t for t in sorted(last) if frame - last[t][0] <= max_gap]
        score = np.array([[box_iou(xyxy[i], last[t][1])[0, 0] for t in live] for i in rows]).reshape(len(rows), len(live))
        for i, j in brute_greedy(score, min_iou):
            ids[rows[i]] = live[j]
        for i in rows:
            if ids[i] < 0:
                ids[i] = len(last)
                last[ids[i]] = None
            last[ids[i]] = (frame, xyxy[i])
    return ids


@pytest.mark.parametrize("seed", range(10))
def test_link_tracks_against_brute_force(seed):
    rng = np.random.default_rng(seed)
    n = 120
    frames = rng.integers(0, 15, n)
    xy = rng.uniform(0, 100, (n, 2))
    wh = rng.uniform(5, 40, (n, 2))
    if seed % 2:  # on a grid: many equal IoUs
        xy, wh = np.round(xy / 20) * 20, np.round(wh / 20) * 20 + 10
    boxes = np.column_stack([xy, xy + wh])
    np.testing.assert_array_equal(link_tracks(frames, boxes), brute_link(frames, boxes))


def test_link_tracks_bounds():
    frames = np.zeros(MAX_BOXES_PER_FRAME + 1, int)
    boxes = np.tile(BOX, (len(frames), 1))
    with pytest.raises(ValueError, match=f"frame 0 has {MAX_BOXES_PER_FRAME + 1:,} boxes, more than"):
        link_tracks(frames, boxes)
    with pytest.raises(ValueError, match="min_iou must be > 0"):
        link_tracks(frames[:2], boxes[:2], min_iou=0.0)


def test_link_tracks_a_full_crowd_on_one_spot():
    """The worst case of the bound: every frame MAX_BOXES_PER_FRAME boxes on one spot, each one continues the
    track of its index (the greedy's tie rule), none is left over."""
    frames = np.repeat(np.arange(3), MAX_BOXES_PER_FRAME)
    ids = link_tracks(frames, np.tile(BOX, (len(frames), 1)))
    np.testing.assert_array_equal(ids, np.tile(np.arange(MAX_BOXES_PER_FRAME), 3))


def test_trim_boxes_by_hand():
    """trim_boxes: half the margin off the top and the bottom edge; a box no taller keeps none, on its middle row
    (short_boxes); margin 0 leaves the edges as they are."""
    edges = np.array([[10.0, 20.0, 30.0, 120.0], [0.0, 5.0, 4.0, 7.0], [1.0, 2.0, 3.0, 4.5]])
    np.testing.assert_array_equal(trim_boxes(edges, 2.0), [[10.0, 21.0, 30.0, 119.0], [0.0, 6.0, 4.0, 6.0],
                                                           [1.0, 3.0, 3.0, 3.5]])
    np.testing.assert_array_equal(trim_boxes(edges, 3.0)[1], [0.0, 6.0, 4.0, 6.0])  # 2 px tall: its middle row
    np.testing.assert_array_equal(short_boxes(edges, 2.0), [False, True, False])
    np.testing.assert_array_equal(short_boxes(edges, 2.5), [False, True, True])
    assert not short_boxes(edges, 0.0).any() and np.array_equal(trim_boxes(edges, 0.0), edges)
    assert trim_boxes(edges, 0.0) is not edges
