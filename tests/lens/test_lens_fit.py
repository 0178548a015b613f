"""homocal lens: the plumb-line fit (homocal.lens.lines), OpenCV's checkerboard calibration on boards rendered
through a known lens, the edges of one frame, and the command's refusals.

Synthetic images and lines go through OpenCV (cv2.projectPoints forward, cv2.undistortPoints with tight criteria
backward), never through the Lens under test."""
from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from homocal.lens import checkerboard, lines as lines_module
from homocal.lens.lines import check_lines, fit_lines, intrinsics, line_residuals

from cli_run import homocal_main
from lens_photos import EXACT, K, POSES, SIZE, TRUE, render_board, undistort_cv, undistorted_frame


def distort(normalised: np.ndarray, dist=TRUE, k=K) -> np.ndarray:
    """Undistorted normalised (N, 2) -> distorted pixels (N, 2), by cv2.projectPoints."""
    p, _ = cv2.projectPoints(np.column_stack([normalised, np.ones(len(normalised))]), np.zeros(3), np.zeros(3), k, dist)
    return p.reshape(-1, 2)


def corner_shift(dist=TRUE, k=K) -> float:
    """How far the lens moves the frame's corner pixel (0, 0), by cv2.undistortPoints."""
    return float(np.linalg.norm(undistort_cv(np.zeros((1, 2)), dist, k)))


def synthetic_lines(rng=None, noise_px=0.0, count=10, per_line=15, dist=TRUE, reach=np.inf) -> list[np.ndarray]:
    """``count`` straight lines of the undistorted image, away from the centre, seen through ``dist``: the part of
    each inside the frame and within ``reach`` (normalised) of its centre, ``per_line`` points, with Gaussian noise."""
    rng = rng or np.random.default_rng(0)
    out = []
    for angle in np.linspace(0.0, math.pi, count, endpoint=False):
        d, n = np.array([math.cos(angle), math.sin(angle)]), np.array([-math.sin(angle), math.cos(angle)])
        offset = 0.35 + 0.25 * (len(out) % 3)  # normalised distance from the centre
        p = distort(offset * n + np.linspace(-3, 3, 3001)[:, None] * d, dist)
        p = p[(p[:, 0] >= 0) & (p[:, 0] <= SIZE[0] - 1) & (p[:, 1] >= 0) & (p[:, 1] <= SIZE[1] - 1)
              & (np.hypot(*(p - K[:2, 2]).T) < reach * K[0, 0])]
        p = p[np.linspace(0, len(p) - 1, per_line).round().astype(int)]
        out.append(np.clip(p + rng.normal(0, noise_px, p.shape), -0.5, np.array(SIZE) - 0.5))
    return out


class TestLineResiduals:
    def test_distances_from_cv2_fitline(self):
        rng = np.random.default_rng(1)
        a, b = rng.normal(size=(5, 2)) * [3, 0.2] + [10, 20], rng.normal(size=(4, 2)) * [0.3, 5]
        got = line_residuals(np.concatenate([a, b]), np.array([0, 5, 9]))[0]
        for pts, res in ((a, got[:5]), (b, got[5:])):
            vx, vy, x0, y0 = cv2.fitLine(pts.astype(np.float32), cv2.DIST_L2, 0, 1e-7, 1e-7).ravel()
            np.testing.assert_allclose(np.abs(res), np.abs((pts[:, 0] - x0) * vy - (pts[:, 1] - y0) * vx), atol=1e-4)


class TestFitLines:
    def test_exact_lines_give_the_lens(self):
        """Noise-free lines of k1, k2: the fit reproduces them (the straightness residual vanishes at the truth)."""
        fit = fit_lines(SIZE, synthetic_lines(), K)
        np.testing.assert_allclose(fit.lens.distortion, TRUE, atol=1e-5)
        assert fit.rms_after_px < 1e-4 < 1 < fit.rms_before_px
        assert fit.corner_displacement_px == pytest.approx(corner_shift(), rel=1e-5)

    def test_clicks_with_1px_noise_within_5_percent_and_its_sigma(self):
        fit = fit_lines(SIZE, synthetic_lines(np.random.default_rng(2), noise_px=1.0), K)
        assert fit.corner_displacement_px == pytest.approx(corner_shift(), rel=0.05)
        assert abs(fit.lens.distortion[0] - TRUE[0]) < 4 * fit.sigma[0]
        assert fit.rms_after_px == pytest.approx(1.0, rel=0.3)  # the click noise is what remains

    def test_focal_length_scales_the_coefficients_not_the_pixels(self):
        """Straightness fixes k1 / f^2, k2 / f^4: another f, the same undistorted pixels."""
        lines, wide = synthetic_lines(), intrinsics(SIZE, focal_px=1.5 * K[0, 0])
        fit = fit_lines(SIZE, lines, wide)
        np.testing.assert_allclose(fit.lens.distortion[:2], TRUE[:2] * [1.5**2, 1.5**4], rtol=1e-4)
        assert fit.corner_displacement_px == pytest.approx(corner_shift(), rel=1e-5)

    def test_intrinsics_default_hfov(self):
        f = (SIZE[0] / 2) / math.tan(math.radians(lines_module.DEFAULT_HFOV_DEG) / 2)
        np.testing.assert_allclose(intrinsics(SIZE), [[f, 0, 319.5], [0, f, 179.5], [0, 0, 1]])


def write_lines(path, lines, size=SIZE):
    path.write_text(json.dumps({"image_size": list(size), "lines": [np.asarray(line).tolist() for line in lines]}))


def run(tmp_path, capsys, monkeypatch, *args):
    return homocal_main("lens", *args, cwd=tmp_path, capsys=capsys, monkeypatch=monkeypatch)


def test_command_writes_lens_json(tmp_path, capsys, monkeypatch):
    write_lines(tmp_path / "lines.json", synthetic_lines(np.random.default_rng(3), noise_px=1.0))
    for _ in range(2):  # the second run replaces its own file
        r = run(tmp_path, capsys, monkeypatch, "--lines", "lines.json", "-o", "lens.json")
        assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("homocal lens: 10 lines, 150 points: straightness RMS ") and "written to lens.json" in r.stdout
    lens = json.loads((tmp_path / "lens.json").read_text())
    np.testing.assert_allclose(lens["K"], K)
    assert lens["image_size"] == list(SIZE) and len(lens["distortion"]) == 5 and lens["fit"]["method"] == "plumb-line"
    assert corner_shift(np.array(lens["distortion"])) == pytest.approx(corner_shift(), rel=0.05)


# ---- checkerboard ---------------------------------------------------------------------------
def test_checkerboard_recovers_a_rendered_lens(tmp_path, capsys, monkeypatch):
    (tmp_path / "frames").mkdir()
    for i, pose in enumerate(POSES):
        cv2.imwrite(str(tmp_path / "frames" / f"{i}.png"), render_board(pose))
    r = run(tmp_path, capsys, monkeypatch, "--checkerboard", "frames/*.png", "--pattern", "9x6", "--square-m",
            "0.025", "-o", "lens.json")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"homocal lens: board found in {len(POSES)} of {len(POSES)} frames")
    lens = json.loads((tmp_path / "lens.json").read_text())
    np.testing.assert_allclose(np.array(lens["K"])[[0, 1], [0, 1]], K[0, 0], rtol=0.01)
    grid = np.stack(np.meshgrid(np.linspace(0, SIZE[0] - 1, 9), np.linspace(0, SIZE[1] - 1, 5)), -1).reshape(-1, 2)
    rays = [cv2.undistortPoints(grid.reshape(-1, 1, 2), k, d, criteria=EXACT).reshape(-1, 2)  # normalised
            for k, d in ((np.array(lens["K"]), np.array(lens["distortion"])), (K, TRUE))]
    assert np.abs(rays[0] - rays[1]).max() * K[0, 0] < 1.0  # pixels, over the whole frame
    again = run(tmp_path, capsys, monkeypatch, "--checkerboard", "frames/*.png", "--pattern", "9x6", "--square-m",
                "0.025", "-o", "again.json")
    assert again.returncode == 0 and (tmp_path / "again.json").read_bytes() == (tmp_path / "lens.json").read_bytes()


def test_checkerboard_lens_that_folds_the_frame_is_refused(tmp_path, capsys, monkeypatch):
    """Boards only near the image centre leave k3 free: the fitted k1, k2, k3 fold the frame's corners (a lens no
    --camera-json would read), refused in one line, nothing written."""
    (tmp_path / "frames").mkdir()
    for i, rvec in enumerate(([0, 0, 0], [0.3, 0, 0], [0, 0.3, 0], [0.2, 0.2, 0.1])):
        cv2.imwrite(str(tmp_path / "frames" / f"{i}.png"), render_board((np.array(rvec, float), np.array([-4.0, -2.5, 14.0]))))
    r = run(tmp_path, capsys, monkeypatch, "--checkerboard", "frames/*.png", "--pattern", "9x6", "--square-m", "0.025",
            "--terms", "k1,k2,k3", "-o", "lens.json")
    assert r.returncode == 2 and "the calibrated distortion: " in r.stderr and "folds the image" in r.stderr, r.stderr
    assert r.stderr.count("\n") == 1 and not (tmp_path / "lens.json").exists()


# ---- one frame ------------------------------------------------------------------------------
def test_frame_edges_recover_the_lens(tmp_path, capsys, monkeypatch):
    """Straight bars drawn on a pinhole canvas larger than the frame, the frame sampled through TRUE."""
    pad, rng = 400, np.random.default_rng(1)
    canvas = np.full((SIZE[1] + 2 * pad, SIZE[0] + 2 * pad), 90, np.uint8)
    for _ in range(12):
        a, b = rng.uniform(0, [SIZE[0] + 2 * pad, SIZE[1] + 2 * pad], (2, 2)).astype(int)
        cv2.line(canvas, tuple(map(int, a)), tuple(map(int, b)), int(rng.choice([200, 30])), 4, cv2.LINE_AA)
    src = (undistorted_frame() + pad).reshape(SIZE[1], SIZE[0], 2).astype(np.float32)
    cv2.imwrite(str(tmp_path / "frame.png"), cv2.remap(canvas, src[..., 0], src[..., 1], cv2.INTER_LINEAR))
    r = run(tmp_path, capsys, monkeypatch, "--frame", "frame.png", "-o", "lens.json")
    assert r.returncode == 0, r.stderr
    lens = json.loads((tmp_path / "lens.json").read_text())
    assert corner_shift(np.array(lens["distortion"])) == pytest.approx(corner_shift(), rel=0.05)


# ---- refusals -------------------------------------------------------------------------------
def _radial_lines() -> list:
    c = K[:2, 2]
    return [(c + np.linspace(-100, 100, 5)[:, None] * [math.cos(a), math.sin(a)]).tolist() for a in (0.3, 1.2, 2.0)]


GOOD = [line.tolist() for line in synthetic_lines()]
BAD_LINES = [  # (file content, expected part of the one-line error)
    (json.dumps({"image_size": [640, 360], "lines": [GOOD[0][:2]] + GOOD[1:]}), "line 0: 2 points; a line needs at least 3"),
    (json.dumps({"image_size": [640, 360], "lines": _radial_lines()}), "every line passes within"),
    (json.dumps({"image_size": [640, 360], "lines": GOOD + [[[1.0, 2.0], [3.0, math.nan], [5.0, 6.0]]]}), "line 10: a point is not a finite"),
    (json.dumps({"image_size": [640, 360], "lines": [[[1.0, 2.0], [math.inf, 4.0], [5.0, 6.0]]]}), "line 0: a point is not a finite"),
    (json.dumps({"image_size": [320, 180], "lines": GOOD}), "outside the 320x180 frame"),
    (json.dumps({"image_size": [640, 360]}), "missing key 'lines'"),
    (json.dumps({"image_size": [640.5, 360], "lines": GOOD}), "image_size must be two integers"),
    ('{"image_size": [640, 360], "lines": [', "not a JSON file"),
    (b'{"image_size": [640, 360], "lines": "\xe9"}', "not a JSON file"),
    (json.dumps({"image_size": [640, 360], "lines": [[[1, "a"], [2, 3], [4, 5]]]}), "line 0: expected a list of [u, v] pairs"),
]


@pytest.mark.parametrize("content,message", BAD_LINES)
def test_bad_lines_file(tmp_path, capsys, monkeypatch, content, message):
    path = tmp_path / "lines.json"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    r = run(tmp_path, capsys, monkeypatch, "--lines", "lines.json", "-o", "lens.json")
    assert (r.returncode, r.stdout) == (2, "") and r.stderr.startswith("homocal: error: lines.json")
    assert message in r.stderr and r.stderr.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lines.json"]


def test_huge_lines_file(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(lines_module, "MAX_LINES_BYTES", 1000)  # the bound, declared once, made small here
    write_lines(tmp_path / "lines.json", synthetic_lines())
    r = run(tmp_path, capsys, monkeypatch, "--lines", "lines.json", "-o", "lens.json")
    assert r.returncode == 2 and "larger than" in r.stderr and not (tmp_path / "lens.json").exists()


def test_fitted_coefficients_that_fold_the_frame(tmp_path, capsys, monkeypatch):
    """Lines of k1 = -0.25 clicked only near the centre (within 0.6 of f): its radial map r (1 + k1 r^2) turns back at
    r = 1 / sqrt(-3 k1), distorted radius 0.77 f, inside the frame's corners (1.25 f)."""
    write_lines(tmp_path / "lines.json", synthetic_lines(dist=np.array([-0.25, 0, 0, 0, 0]), reach=0.6))
    r = run(tmp_path, capsys, monkeypatch, "--lines", "lines.json", "--terms", "k1", "-o", "lens.json")
    assert r.returncode == 2 and "folds the image" in r.stderr and r.stderr.count("\n") == 1
    assert not (tmp_path / "lens.json").exists()


@pytest.mark.parametrize("args,message", [
    (["--checkerboard", "none/*.png", "--pattern", "9x6", "--square-m", "0.025"], "matches no file"),
    (["--checkerboard", "frames/*.png", "--pattern", "9x6", "--square-m", "0.025"], "board was found in 0 of 3 frames"),
    (["--checkerboard", "frames/*.png", "--pattern", "9x6"], "--square-m: required with --checkerboard"),
    (["--lines", "lines.json", "--pattern", "9x6"], "--pattern: only with --checkerboard"),
    (["--checkerboard", "frames/*.png", "--pattern", "9x6", "--square-m", "0.025", "--hfov", "90"], "--hfov: not with"),
    (["--frame", "frames/0.png"], "no long straight edge found"),
    (["--frame", "lines.json"], "not a readable image"),
    (["--checkerboard", "mixed/*.png", "--pattern", "9x6", "--square-m", "0.025"], "the first frame is 640x360"),
])
def test_bad_board_and_frame(tmp_path, capsys, monkeypatch, args, message):
    (tmp_path / "frames").mkdir()
    (tmp_path / "mixed").mkdir()
    for i in range(3):
        cv2.imwrite(str(tmp_path / "frames" / f"{i}.png"), np.full((SIZE[1], SIZE[0]), 128, np.uint8))
    cv2.imwrite(str(tmp_path / "mixed" / "0.png"), np.full((SIZE[1], SIZE[0]), 128, np.uint8))
    cv2.imwrite(str(tmp_path / "mixed" / "1.png"), np.full((100, 100), 128, np.uint8))
    write_lines(tmp_path / "lines.json", synthetic_lines())
    before = sorted(p.name for p in tmp_path.iterdir())
    r = run(tmp_path, capsys, monkeypatch, *args, "-o", "lens.json")
    assert r.returncode == 2 and message in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_frame_size_read_before_decoding(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(checkerboard, "MAX_FRAME_PIXELS", 100 * 100)  # the bound, declared once, made small here
    cv2.imwrite(str(tmp_path / "frame.png"), np.zeros((101, 100), np.uint8))
    r = run(tmp_path, capsys, monkeypatch, "--frame", "frame.png", "-o", "lens.json")
    assert r.returncode == 2 and "frame.png: 100x101 px, larger than 10,000 pixels" in r.stderr
    assert not (tmp_path / "lens.json").exists()


def test_board_search_bounded_in_pixels(tmp_path, capsys, monkeypatch):
    """Frames x pixels beyond MAX_SEARCH_PIXELS: refused before any search, from the first frame's size."""
    monkeypatch.setattr(checkerboard, "MAX_SEARCH_PIXELS", 3 * 100 * 100 - 1)  # the bound, made small here
    (tmp_path / "board").mkdir()
    for i in range(3):
        cv2.imwrite(str(tmp_path / "board" / f"{i}.png"), np.zeros((100, 100), np.uint8))
    r = run(tmp_path, capsys, monkeypatch, "--checkerboard", "board/*.png", "--pattern", "9x6", "--square-m", "0.025",
            "-o", "lens.json")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "3 frames of 100x100 px, 30,000 pixels to search for the board, more than 29,999" in r.stderr
    assert not (tmp_path / "lens.json").exists()


def test_check_lines_counts_the_points_before_converting(monkeypatch):
    monkeypatch.setattr(lines_module, "MAX_POINTS", 10)
    with pytest.raises(ValueError, match="more than 10 points"):
        check_lines([640, 360], [[[1, 1]] * 6, [[2, 2]] * 6])
