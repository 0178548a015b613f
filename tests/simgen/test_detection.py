"""simgen.detection: box convention, both detectors, association, matching to ground truth, MOT files."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from simgen.detection import (
    DETECTIONS_SCHEMA,
    BackgroundSubtractionDetector,
    DetectionBatch,
    SegmentationDetector,
    append_detections,
    box_iou,
    detections_table,
    greedy_assign,
    import_mot,
    mask_boxes,
    match_to_gt,
    nearest_sample,
    write_mot_gt,
)


def id_map(shape, *regions):
    """(H, W) int32 map, -1 everywhere but the given (agent_id, row slice, col slice) regions."""
    ids = np.full(shape, -1, dtype=np.int32)
    for agent, rows, cols in regions:
        ids[rows, cols] = agent
    return ids


class TestMaskBoxes:
    @pytest.mark.parametrize(
        "regions, expected",
        [
            ([], {}),
            ([(0, slice(0, 1), slice(0, 1))], {0: (-0.5, -0.5, 0.5, 0.5, 1)}),
            ([(7, slice(1, 3), slice(2, 5))], {7: (1.5, 0.5, 4.5, 2.5, 6)}),
            ([(3, slice(5, 6), slice(9, 10))], {3: (8.5, 4.5, 9.5, 5.5, 1)}),  # bottom-right pixel of 6x10
            (
                [(1000, slice(0, 2), slice(0, 1)), (1000, slice(4, 6), slice(7, 10)), (2, slice(2, 4), slice(3, 5))],
                {2: (2.5, 1.5, 4.5, 3.5, 4), 1000: (-0.5, -0.5, 9.5, 5.5, 8)},  # one id in two pieces
            ),
        ],
    )
    def test_hand_computed(self, regions, expected):
        assert mask_boxes(id_map((6, 10), *regions)) == expected

    @given(hnp.arrays(np.int32, hnp.array_shapes(min_dims=2, max_dims=2, max_side=40), elements=st.integers(-1, 5)))
    def test_against_brute_force(self, ids):
        expected = {}
        for agent in np.unique(ids[ids >= 0]):
            rows, cols = np.nonzero(ids == agent)
            expected[int(agent)] = (cols.min() - 0.5, rows.min() - 0.5, cols.max() + 0.5, rows.max() + 0.5, rows.size)
        assert mask_boxes(ids) == expected

    def test_refuses_huge_ids(self):
        with pytest.raises(ValueError, match="agent ids must be below"):
            mask_boxes(id_map((2, 2), (2**30, slice(0, 1), slice(0, 1))))

    def test_segmentation_detector_foot_points(self):
        ids = id_map((8, 12), (4, slice(2, 7), slice(3, 6)), (1, slice(0, 1), slice(11, 12)))
        batch = SegmentationDetector().detect(3, 0.15, np.zeros((8, 12, 3), np.uint8), ids)
        assert batch.detector == "segmentation" and batch.frame == 3 and batch.t == 0.15
        np.testing.assert_array_equal(batch.agent_id, [1, 4])
        np.testing.assert_array_equal(batch.xyxy, [[10.5, -0.5, 11.5, 0.5], [2.5, 1.5, 5.5, 6.5]])
        np.testing.assert_array_equal(batch.foot, [[11.0, 0.5], [4.0, 6.5]])
        np.testing.assert_array_equal(batch.score, [1.0, 1.0])


class TestDetectionsTable:
    def test_columns_and_foot_points(self):
        batches = [
            DetectionBatch("rgb", 0, 0.0, np.array([[1.5, 2.5, 5.5, 10.5]]), np.array([0.5]), np.array([7], np.int32)),
            DetectionBatch("rgb", 1, 0.05, np.empty((0, 4)), np.empty(0), np.empty(0, np.int32)),
            DetectionBatch("rgb", 2, 0.1, np.array([[0.0, 0.0, 2.0, 4.0], [9, 9, 10, 10]]), np.ones(2), np.array([-1, 3])),
        ]
        table = detections_table(batches)
        assert table.schema == DETECTIONS_SCHEMA
        assert table.column("frame").to_pylist() == [0, 2, 2]
        assert table.column("t").to_pylist() == [0.0, 0.1, 0.1]
        assert table.column("agent_id").to_pylist() == [7, -1, 3]
        assert table.column("u").to_pylist() == [3.5, 1.0, 9.5]
        assert table.column("v").to_pylist() == [10.5, 4.0, 10.0]

    def test_empty(self):
        assert detections_table([]).schema == DETECTIONS_SCHEMA

    def test_batch_shapes_checked(self):
        with pytest.raises(ValueError, match="shapes"):
            DetectionBatch("rgb", 0, 0.0, np.zeros((2, 4)), np.zeros(3), np.zeros(2, np.int32))


def moving_scene(n_frames, height=180, width=320, seed=0):
    """Static textured background with coloured rectangles moving over it.

    Yields (frame, rgb (H, W, 3) uint8, agent_ids (H, W) int32, true boxes {agent_id: (x1, y1, x2, y2)});
    agents 5, 9 and 42, and a mover that is no agent (agent_ids -1 there, its box under key -1).
    """
    rng = np.random.default_rng(seed)
    background = cv2.GaussianBlur(rng.integers(0, 256, (height, width, 3), dtype=np.uint8), (0, 0), 1.5)
    # agent, colour, top-left at frame 0 (col, row), velocity (px / frame), size (w, h)
    movers = [
        (5, (230, 40, 40), (10, 20), (3, 0), (14, 40)),
        (9, (40, 230, 40), (280, 100), (-2, 1), (10, 30)),
        (42, (40, 40, 230), (150, 10), (1, 2), (20, 24)),
        (-1, (230, 230, 40), (40, 2), (4, 0), (30, 12)),
    ]
    checker = ((np.arange(64)[:, None] // 3 + np.arange(64) // 3) % 2 * 60).astype(np.uint8)  # a textured inside
    for frame in range(n_frames):
        rgb, ids, boxes = background.copy(), np.full((height, width), -1, np.int32), {}
        for agent, colour, (c, r), (vc, vr), (w, h) in movers:
            c, r = c + vc * frame, r + vr * frame
            rgb[r : r + h, c : c + w] = np.clip(np.array(colour) - checker[:h, :w, None], 0, 255)
            ids[r : r + h, c : c + w] = agent
            boxes[agent] = (c - 0.5, r - 0.5, c + w - 0.5, r + h - 0.5)
        yield frame, rgb, ids, boxes


class TestBackgroundSubtraction:
    def test_finds_and_associates_the_movers(self):
        detector = BackgroundSubtractionDetector(min_area=20)
        for frame, rgb, ids, boxes in moving_scene(40):
            batch = detector.detect(frame, frame / 20, rgb, ids)
            if frame == 0:
                assert len(batch) == 0  # no background model yet
            if frame < 15:  # the young model still absorbs parts of the movers
                continue
            assert sorted(batch.agent_id.tolist()) == [-1, 5, 9, 42], frame  # the mover that is no agent: -1
            for agent, box in boxes.items():
                iou = box_iou(batch.xyxy[batch.agent_id == agent], box).item()
                assert iou >= 0.6, (frame, agent, iou)

    @pytest.mark.parametrize(
        "downscale, rows, cols, expected",
        [
            (1, slice(10, 30), slice(7, 19), (6.5, 9.5, 18.5, 29.5)),
            (2, slice(10, 30), slice(8, 20), (7.5, 9.5, 19.5, 29.5)),  # on the 2x2 grid: exact
            (2, slice(11, 30), slice(7, 19), (5.5, 9.5, 19.5, 29.5)),  # off it: grown to the grid
        ],
    )
    def test_box_convention_after_rescaling(self, downscale, rows, cols, expected):
        grey = np.full((40, 60, 3), 100, np.uint8)
        appeared = grey.copy()
        appeared[rows, cols] = 250
        ids = id_map((40, 60), (3, rows, cols))
        detector = BackgroundSubtractionDetector(downscale=downscale, min_area=1)
        detector.detect(0, 0.0, grey, np.full((40, 60), -1, np.int32))
        batch = detector.detect(1, 0.05, appeared, ids)
        np.testing.assert_array_equal(batch.xyxy, [expected])
        np.testing.assert_array_equal(batch.agent_id, [3])

    @pytest.mark.parametrize("resume_at", [7, 16, 29, 33])
    def test_resume_reproduces_state(self, resume_at):
        frames = list(moving_scene(40))
        make = lambda: BackgroundSubtractionDetector(min_area=20, reset_every=16, warmup=5)  # noqa: E731
        whole = make()
        expected = [whole.detect(f, f / 20, rgb, ids) for f, rgb, ids, _ in frames]
        resumed = make()
        for f, rgb, _, _ in frames[resumed.resume_start(resume_at) : resume_at]:
            resumed.feed(f, rgb)
        for f, rgb, ids, _ in frames[resume_at:]:
            got = resumed.detect(f, f / 20, rgb, ids)
            np.testing.assert_array_equal(got.xyxy, expected[f].xyxy)
            np.testing.assert_array_equal(got.agent_id, expected[f].agent_id)
            np.testing.assert_array_equal(got.score, expected[f].score)

    def test_refuses_missing_warmup_and_gaps(self):
        (_, rgb, ids, _), *_ = moving_scene(1)
        detector = BackgroundSubtractionDetector(reset_every=16, warmup=5)
        with pytest.raises(ValueError, match="needs frames 11..19 fed first"):
            detector.detect(20, 1.0, rgb, ids)
        detector.detect(32, 1.6, rgb, ids)
        with pytest.raises(ValueError, match="frame 34 after frame 32"):
            detector.detect(34, 1.7, rgb, ids)


class TestGreedyAssign:
    @pytest.mark.parametrize(
        "score, min_score, pairs",
        [
            ([[0.9, 0.8], [0.85, 0.1]], 0.3, [(0, 0)]),
            ([[0.9, 0.8], [0.85, 0.1]], 0.05, [(0, 0), (1, 1)]),
            ([[0.5, 0.5], [0.5, 0.5]], 0.5, [(0, 0), (1, 1)]),  # ties: lower row, then lower column
            ([[0.2, 0.7, 0.6]], 0.3, [(0, 1)]),
            (np.zeros((0, 3)), 0.3, []),
        ],
    )
    def test_pairs(self, score, min_score, pairs):
        rows, cols = greedy_assign(np.array(score, dtype=np.float64).reshape(-1, np.shape(score)[-1]), min_score)
        assert list(zip(rows.tolist(), cols.tolist())) == pairs


class TestNearestSample:
    @pytest.mark.parametrize(
        "times, query, expected",
        [
            ([0.0, 0.05, 0.1], [-1.0, 0.0, 0.02, 0.025, 0.03, 0.1, 7.0], [0, 0, 0, 0, 1, 2, 2]),
            ([0.0, 0.05, 0.1], [3 * 0.025], [1]),  # a midpoint up to rounding is a tie: earlier
            ([0.5], [0.0, 9.0], [0, 0]),
            ([0.0, 0.05, 0.05, 0.1], [0.05, 0.06, 0.2], [1, 1, 3]),  # repeated times: the first
        ],
    )
    def test_table(self, times, query, expected):
        assert nearest_sample(np.array(times), np.array(query)).tolist() == expected


def random_gt(rng, agents=(0, 1, 2, 4), n_samples=40):
    """gt table: each agent on a random subset of 50 ms samples, rows shuffled."""
    rows = [(k * 0.05, a) for a in agents for k in range(n_samples) if rng.random() < 0.6]
    rows = [rows[i] for i in rng.permutation(len(rows))]
    t = np.array([r[0] for r in rows])
    return pa.table(
        {
            "t": t,
            "agent_id": pa.array([r[1] for r in rows], pa.int32()),
            "x": rng.normal(size=len(rows)),
            "y": rng.normal(size=len(rows)) + 20,
        }
    )


class TestMatchToGt:
    @pytest.mark.parametrize("seed", range(6))
    def test_against_brute_force(self, seed):
        rng = np.random.default_rng(seed)
        gt = random_gt(rng)
        n = 300
        t = np.concatenate([rng.uniform(-0.2, 2.2, n - 100), rng.integers(0, 40, 100) * 0.05 + 0.025])  # + midpoints
        agent = rng.choice([-1, 0, 1, 2, 3, 4], size=n).astype(np.int32)  # agent 3 has no ground truth
        batches = [DetectionBatch("seg", i, t[i], np.zeros((1, 4)), np.ones(1), agent[i : i + 1]) for i in range(n)]
        matched = match_to_gt(detections_table(batches), gt)

        g = {c: gt.column(c).to_numpy() for c in ("t", "agent_id", "x", "y")}
        expected = np.full((n, 3), np.nan)
        for i in range(n):
            same = np.flatnonzero(g["agent_id"] == agent[i]) if agent[i] >= 0 else []
            if len(same):
                gap = np.abs(g["t"][same] - t[i])
                ties = same[gap <= gap.min() + 1e-9]
                j = ties[np.argmin(g["t"][ties])]
                expected[i] = g["t"][j], g["x"][j], g["y"][j]
        got = np.column_stack([matched.column(c).to_numpy() for c in ("gt_t", "gt_x", "gt_y")])
        np.testing.assert_array_equal(got, expected)
        assert np.isnan(got[agent == 3]).all() and np.isnan(got[agent == -1]).all()
        assert matched.column_names == DETECTIONS_SCHEMA.names + ["gt_t", "gt_x", "gt_y"]


def gt_with_boxes(n_samples=20):
    """gt table over 1 s: agents 0, 1, 7 with boxes (1 and 7 overlap; 7 hidden on odd samples)."""
    rows = []
    for k in range(n_samples):
        for agent, (x1, y1, w, h) in {0: (10.5 + k, 20.5, 12, 30), 1: (100.25, 50.5 + 2 * k, 20, 41), 7: (105.5, 60.5, 20, 40)}.items():
            hidden = agent == 7 and k % 2 == 1
            box = (np.nan,) * 4 if hidden else (x1, y1, x1 + w, y1 + h)
            rows.append((k * 0.05, agent, 3.0 * agent + 0.1 * k, 10.0 + k, *box, 0.0 if hidden else 0.5 + agent / 20))
    columns = list(zip(*rows))
    return pa.table(
        {
            "t": pa.array(columns[0], pa.float64()),
            "agent_id": pa.array(columns[1], pa.int32()),
            **{name: pa.array(columns[i], pa.float64()) for i, name in enumerate(("x", "y", "x1", "y1", "x2", "y2", "visible_fraction"), 2)},
        }
    )


def make_dataset(path, gt, fps):
    path.mkdir()
    (path / "manifest.json").write_text(json.dumps({"fps": fps}))
    pq.write_table(gt, path / "gt.parquet")
    return path


class TestMot:
    @pytest.mark.parametrize("fps", [20.0, 10.0])
    def test_round_trip(self, tmp_path, fps):
        gt = gt_with_boxes()
        dataset = make_dataset(tmp_path / "run", gt, fps)
        write_mot_gt(gt, fps, dataset / "mot" / "gt.txt")
        table = import_mot(dataset, dataset / "mot" / "gt.txt", "yolo")

        g = {c: gt.column(c).to_numpy() for c in gt.column_names}
        per_frame = round(20 / fps)  # ground-truth samples per video frame
        expected = {}
        for i in np.flatnonzero(np.isfinite(g["x1"])):
            step = round(g["t"][i] / 0.05)
            if step % per_frame == 0:
                expected[step // per_frame, g["agent_id"][i]] = [g[c][i] for c in ("x1", "y1", "x2", "y2", "t", "x", "y")]
        rows = table.to_pylist()
        got = {(r["frame"], r["agent_id"]): [r[c] for c in ("x1", "y1", "x2", "y2", "gt_t", "gt_x", "gt_y")] for r in rows}
        assert got.keys() == expected.keys() and len(rows) == len(got)
        for key, values in expected.items():
            np.testing.assert_allclose(got[key], values, rtol=0, atol=1e-9, err_msg=str(key))
        assert all(r["t"] == r["frame"] / fps and r["score"] == 1.0 and r["detector"] == "yolo" for r in rows)

    def test_gt_file_format(self, tmp_path):
        gt = gt_with_boxes(2)
        write_mot_gt(gt, 20.0, tmp_path / "gt.txt")
        assert (tmp_path / "gt.txt").read_text().splitlines() == [
            "1,0,12,22,12,30,1,1,0.5",  # box (10.5, 20.5, 22.5, 50.5): 1-based left pixel 12
            "1,1,101.75,52,20,41,1,1,0.55",
            "1,7,107,62,20,40,1,1,0.85",
            "2,0,13,22,12,30,1,1,0.5",  # agent 7 hidden
            "2,1,101.75,54,20,41,1,1,0.55",
        ]
        assert sorted(p.name for p in tmp_path.iterdir()) == ["gt.txt"]  # no temporary file left

    def test_unmatched_boxes_get_no_agent(self, tmp_path):
        dataset = make_dataset(tmp_path / "run", gt_with_boxes(), 20.0)
        mot = tmp_path / "det.txt"
        mot.write_text("\ufeff1,-1,300,300,10,10,0.4,-1,-1,-1\n\n3,-1,14,22,12,30,0.9,-1,-1,-1\n")  # BOM, blank line
        table = import_mot(dataset, mot, "yolo")
        assert table.column("frame").to_pylist() == [0, 2]
        assert table.column("agent_id").to_pylist() == [-1, 0]
        assert table.column("score").to_pylist() == [0.4, 0.9]
        assert np.isnan(table.column("gt_x")[0].as_py()) and table.column("gt_t")[1].as_py() == 0.1

    @pytest.mark.parametrize(
        "text, line",
        [
            ("1,1,10,10,5,5,1,-1,-1,-1\n1,2,10,10,5,5,1,1\n", 2),
            ("1,1,10,10,5,5,1,1,0.5\n1,2,10,10,5,5,1,1,0.5,-1,-1\n", 2),
            ("1,1,10,10,5,5,1,-1,-1,-1\n\n1,2,ten,10,5,5,1,-1,-1,-1\n", 3),
            ("1 2 10 10 5 5 1 -1 -1 -1\n", 1),
            ("0,1,10,10,5,5,1,-1,-1,-1\n", 1),
            ("1,1,10,10,5,5,1,-1,-1,-1\n2.5,1,10,10,5,5,1,-1,-1,-1\n", 2),
            ("1,1,10,10,-5,5,1,-1,-1,-1\n", 1),
            ("1,1,10,nan,5,5,1,-1,-1,-1\n", 1),
        ],
        ids=["8 values", "11 values", "not a number", "spaces", "frame 0", "fractional frame", "negative width", "nan"],
    )
    def test_bad_input_names_the_line(self, tmp_path, text, line):
        dataset = make_dataset(tmp_path / "run", gt_with_boxes(2), 20.0)
        mot = tmp_path / "det.txt"
        mot.write_text(text)
        with pytest.raises(ValueError, match=rf"det\.txt: line {line}: "):
            import_mot(dataset, mot, "yolo")

    def test_append_replaces_same_detector(self, tmp_path):
        dataset = make_dataset(tmp_path / "run", gt_with_boxes(), 20.0)
        (_, rgb, ids, _), *_ = moving_scene(1)
        own = match_to_gt(detections_table([SegmentationDetector().detect(0, 0.0, rgb, ids)]), gt_with_boxes())
        pq.write_table(own, dataset / "detections.parquet")
        write_mot_gt(gt_with_boxes(), 20.0, dataset / "mot" / "gt.txt")
        imported = import_mot(dataset, dataset / "mot" / "gt.txt", "yolo")
        append_detections(dataset, imported)
        append_detections(dataset, imported)
        merged = pq.read_table(dataset / "detections.parquet")
        assert merged.schema == own.schema
        assert merged.num_rows == own.num_rows + imported.num_rows
        assert merged.slice(own.num_rows).equals(imported)
        assert sorted(p.name for p in dataset.iterdir()) == ["detections.parquet", "gt.parquet", "manifest.json", "mot"]
