"""homocal.geometry against independent computations: pinhole projection, OpenCV, hand-made quads."""
import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from homocal.geometry import (
    PinholeCamera,
    SiteMap,
    ViewTransformer,
    box_bottom_points,
    check_orientation,
    signed_area,
    validate_quad,
)

CAM = PinholeCamera()  # the paper's camera: 1280x720, 95 deg hfov, 4 m high, 15 deg down
GROUND = np.array([[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]])  # TL, TR, BR, BL (far edge on top)


def pinhole_pixel(x: float, y: float) -> np.ndarray:
    """Project a ground point by explicit trigonometry (independent of PinholeCamera.K/R/t)."""
    h, tilt, f = 4.0, np.radians(15.0), 640.0 / np.tan(np.radians(47.5))
    depth = y * np.cos(tilt) + h * np.sin(tilt)  # along the optical axis
    down = -(y * np.sin(tilt)) + h * np.cos(tilt)  # camera y (down)
    return np.array([639.5 + f * x / depth, 359.5 + f * down / depth])


class TestPinholeCamera:
    def test_intrinsics_match_notes(self):
        assert CAM.focal_px == pytest.approx(586.452, abs=1e-3)
        assert CAM.vfov_deg == pytest.approx(63.088285, abs=1e-6)

    @pytest.mark.parametrize("xy", [(0.0, 5.0), (3.0, 12.0), (-7.0, 44.0), (10.0, 50.0)])
    def test_projection_matches_trigonometry(self, xy):
        np.testing.assert_allclose(CAM.project_ground([xy])[0], pinhole_pixel(*xy), atol=1e-9)

    def test_horizon_row(self):
        expected = 359.5 - CAM.focal_px * np.tan(np.radians(15.0))
        assert CAM.horizon_row == pytest.approx(expected, abs=1e-9)

    def test_ray_to_ground_inverts_projection(self):
        xy = np.array([[0.0, 5.0], [-4.0, 20.0], [6.0, 49.0]])
        np.testing.assert_allclose(CAM.ray_to_ground(CAM.project_ground(xy)), xy, atol=1e-9)
        assert np.isnan(CAM.ray_to_ground([[640.0, 100.0]])).all()  # above the horizon

    @pytest.mark.parametrize("field,value", [("hfov_deg", 0.0), ("mount_height_m", -1.0), ("tilt_deg", -60.0)])
    def test_bad_parameters(self, field, value):
        with pytest.raises(ValueError, match=field.split("_")[0]):
            PinholeCamera(**{field: value})


class TestViewTransformer:
    def setup_method(self):
        self.image = CAM.project_ground(GROUND)
        self.vt = ViewTransformer(self.image, GROUND)

    def test_matches_pinhole_ground_mapping(self):
        xy = np.array([[0.0, 5.0], [2.0, 15.0], [-9.0, 40.0], [0.5, 60.0]])
        pixels = np.array([pinhole_pixel(*p) for p in xy])
        np.testing.assert_allclose(self.vt.transform_points(pixels), xy, atol=1e-9)

    def test_matches_opencv_where_opencv_works(self):
        m = cv2.getPerspectiveTransform(self.image.astype(np.float32), GROUND.astype(np.float32))
        pts = np.array([[100.0, 700.0], [640.0, 300.0], [1200.0, 500.0]])
        ref = cv2.perspectiveTransform(pts.reshape(-1, 1, 2), m).reshape(-1, 2)
        np.testing.assert_allclose(self.vt.transform_points(pts), ref, rtol=1e-4)

    def test_horizon_through_image_origin(self):
        """OpenCV fixes h33 = 1, which fails when the horizon passes through (0, 0); ours does not."""
        shift = np.array([0.0, CAM.horizon_row])  # move the image so that the horizon is row 0
        vt = ViewTransformer(self.image - shift, GROUND)
        assert abs(vt.m[2, 2]) < 1e-12
        np.testing.assert_allclose(vt.transform_points(self.image - shift), GROUND, atol=1e-9)
        assert np.isnan(vt.transform_points([[0.0, 0.0], [500.0, -3.0]])).all()

    def test_horizon_line(self):
        assert self.vt.horizon_row(123.0) == pytest.approx(CAM.horizon_row, abs=1e-9)
        np.testing.assert_allclose(self.vt.horizon, CAM.horizon, atol=1e-12)

    @pytest.mark.parametrize("v_offset", [0.0, -0.5, -100.0])
    def test_on_or_above_horizon_is_nan(self, v_offset):
        out = self.vt.transform_points([[640.0, CAM.horizon_row + v_offset]])
        assert np.isnan(out).all()

    @pytest.mark.parametrize("dtype", [np.float16, np.float32, np.float64, np.int32])
    @pytest.mark.parametrize("shape", [(3, 2), (3, 1, 2)])
    def test_input_shapes_and_dtypes(self, dtype, shape):
        pts = np.array([[600, 500], [700, 400], [640, 650]], dtype=dtype).reshape(shape)
        out = self.vt.transform_points(pts)
        assert out.shape == (3, 2) and out.dtype == np.float64
        np.testing.assert_allclose(out, self.vt.transform_points(pts.reshape(3, 2).astype(np.float64)))

    def test_subpixel_points_are_not_rounded(self):
        a, b = self.vt.transform_points(np.array([[640.25, 500.75], [640.0, 500.0]], dtype=np.float32))
        assert not np.allclose(a, b)

    def test_empty_input(self):
        assert self.vt.transform_points(np.empty((0, 2))).shape == (0, 2)

    def test_inverse_round_trip(self):
        pts = np.array([[10.0, 719.0], [640.0, 210.0], [1279.0, 400.0]])
        np.testing.assert_allclose(self.vt.inverse_transform_points(self.vt.transform_points(pts)), pts, atol=1e-7)

    @settings(max_examples=200, deadline=None)
    @given(st.floats(0.0, 1279.0), st.floats(-500.0, 719.0))
    def test_round_trip_or_nan_never_inf(self, u, v):
        ground = self.vt.transform_points([[u, v]])
        assert not np.isinf(ground).any()
        if np.isfinite(ground).all():
            back = self.vt.inverse_transform_points(ground)
            np.testing.assert_allclose(back[0], [u, v], atol=1e-6 * max(1.0, np.abs(ground).max()))
        else:
            assert v <= CAM.horizon_row + 1e-6


BAD_QUADS = {
    "repeated": ([[0, 0], [10, 0], [10, 0], [0, 10]], "same point"),
    "collinear": ([[0, 0], [5, 0], [10, 0], [0, 10]], "collinear"),
    "self-intersecting": ([[0, 0], [10, 10], [10, 0], [0, 10]], "self-intersecting"),
    "not convex": ([[0, 0], [10, 0], [3, 3], [0, 10]], "not convex"),
    "nan": ([[0, 0], [10, np.nan], [10, 10], [0, 10]], "NaN"),
    "three vertices": ([[0, 0], [10, 0], [10, 10]], "exactly 4"),
    "zero area": ([[1, 1], [1, 1], [1, 1], [1, 1]], "same point"),
    "overflow": ([[0, 0], [1e308, 0], [10, 10], [0, 10]], r"vertex 1 = \[1e\+308, 0\.0\] is out of range"),
    "overflow negative": ([[0, 0], [10, 0], [10, 10], [0, -1e12]], r"vertex 3 .* out of range"),
}


@pytest.mark.parametrize("name", BAD_QUADS)
def test_degenerate_quads_raise(name):
    quad, message = BAD_QUADS[name]
    with pytest.raises(ValueError, match=message):
        validate_quad(np.array(quad, dtype=float))
    with pytest.raises(ValueError, match=message):
        ViewTransformer(np.array(quad, dtype=float), GROUND)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.one_of(st.floats(-1e4, 1e4), st.sampled_from([np.nan, np.inf])), min_size=8, max_size=8))
def test_any_quad_gives_a_transformer_or_a_clear_error(coords):
    quad = np.array(coords).reshape(4, 2)
    try:
        vt = ViewTransformer(quad, GROUND)
    except ValueError as e:
        assert str(e)
        return
    out = vt.transform_points(quad)
    assert not np.isinf(out).any()
    np.testing.assert_allclose(out, GROUND, atol=1e-6 * 1e4)


class TestOrientation:
    """check_orientation against the paper camera's exact quads: metres (y up) and site-map pixels (y down)."""

    SITE_MAP = SiteMap(10.0, (400.0, 600.0))
    IMAGE = CAM.project_ground(GROUND)
    VARIANTS = {  # the corners relabelled: (order of the image's rows, of GROUND's rows, None if accepted, else the message)
        "as clicked": ([0, 1, 2, 3], [0, 1, 2, 3], None),
        "both rotated alike": ([2, 3, 0, 1], [2, 3, 0, 1], None),  # the same four pairs: the same mapping
        "mirrored left-right": ([0, 1, 2, 3], [1, 0, 3, 2], "other way from the image's"),
        "upside down": ([0, 1, 2, 3], [3, 2, 1, 0], "other way from the image's"),
        "rotated 180 degrees": ([0, 1, 2, 3], [2, 3, 0, 1], "turned against the image's"),  # the signed areas agree
        "rotated 90 degrees": ([0, 1, 2, 3], [1, 2, 3, 0], "turned against the image's"),
        "rotated 270 degrees": ([0, 1, 2, 3], [3, 0, 1, 2], "turned against the image's"),
    }

    @pytest.mark.parametrize("variant", VARIANTS)
    @pytest.mark.parametrize("units", ["metres", "site-map pixels"])
    def test_signed_areas_and_far_edge(self, variant, units):
        image_order, order, message = self.VARIANTS[variant]
        ground = GROUND[order]
        target, y_up = (ground, True) if units == "metres" else (self.SITE_MAP.to_pixels(ground), False)
        if message is None:
            check_orientation(self.IMAGE[image_order], target, target_y_up=y_up)
        else:
            with pytest.raises(ValueError, match=message):
                check_orientation(self.IMAGE[image_order], target, target_y_up=y_up)

    def test_signed_area_sign_convention(self):
        square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
        assert signed_area(square) == 1.0 and signed_area(square[::-1]) == -1.0


class TestSiteMap:
    def test_round_trip_and_axes(self):
        sm = SiteMap(10.0, (400.0, 600.0))
        np.testing.assert_allclose(sm.to_metres([[400.0, 600.0], [410.0, 500.0]]), [[0.0, 0.0], [1.0, 10.0]])
        xy = np.array([[-3.5, 8.0], [3.5, 30.0]])
        np.testing.assert_allclose(sm.to_metres(sm.to_pixels(xy)), xy)

    def test_matrix_composes_with_homography(self):
        sm = SiteMap(12.5, (300.0, 700.0))
        image = CAM.project_ground(GROUND)
        vt_px = ViewTransformer(image, sm.to_pixels(GROUND))
        vt_m = ViewTransformer(image, GROUND)
        pts = np.array([[640.0, 500.0], [100.0, 700.0]])
        H = sm.to_metres_matrix @ vt_px.m
        p = np.column_stack([pts, np.ones(2)]) @ H.T
        np.testing.assert_allclose(p[:, :2] / p[:, 2:], vt_m.transform_points(pts), atol=1e-9)

    @pytest.mark.parametrize("scale", [0.0, -1.0, np.nan])
    def test_bad_scale(self, scale):
        with pytest.raises(ValueError, match="scale_px_per_m"):
            SiteMap(scale, (0.0, 0.0))


class TestValidMask:
    def setup_method(self):
        self.vt = ViewTransformer(CAM.project_ground(GROUND), GROUND)

    def test_mask_is_false_exactly_where_the_result_is_nan(self):
        pts = np.array([[640.0, 500.0], [640.0, CAM.horizon_row - 1.0], [np.nan, 600.0], [100.0, 700.0]])
        ground, valid = self.vt.transform_points(pts, return_valid=True)
        np.testing.assert_array_equal(valid, [True, False, False, True])
        np.testing.assert_array_equal(ground, self.vt.transform_points(pts))
        np.testing.assert_allclose(ground[valid], CAM.ray_to_ground(pts[valid]), atol=1e-9)

    def test_inverse_mask_marks_points_behind_the_camera(self):
        ground = np.array([[0.0, 10.0], [0.0, -20.0]])  # the second one is behind the camera's image plane
        image, valid = self.vt.inverse_transform_points(ground, return_valid=True)
        np.testing.assert_array_equal(valid, [True, False])
        np.testing.assert_allclose(image[0], CAM.project_ground(ground[:1])[0], atol=1e-9)

    def test_supervision_style_anchors(self):
        """Detections.get_anchors_coordinates(BOTTOM_CENTER) is a plain (N, 2) float array ((x1 + x2) / 2, y2):
        it maps as it is, float32 as float64, and filtering with the mask keeps .astype(int) meaningful."""
        xyxy = np.array([[600.0, 300.0, 640.0, 420.0], [620.0, 100.0, 630.0, 150.0]], dtype=np.float32)
        anchors = np.column_stack([(xyxy[:, 0] + xyxy[:, 2]) / 2, xyxy[:, 3]])
        ground, valid = self.vt.transform_points(anchors, return_valid=True)
        np.testing.assert_allclose(ground[valid], CAM.ray_to_ground(anchors[valid].astype(np.float64)), atol=1e-9)
        assert valid.tolist() == [True, False] and (ground[valid].astype(int) > -1000).all()


MAP = SiteMap(10.0, (400.0, 600.0))  # 10 px per metre; map size 800 x 800 px: x -40..40 m, y -20..60 m
WAVES = (100 * np.sin(np.arange(1280) / 5)[None, :] + 100 * np.cos(np.arange(720) / 7)[:, None]).astype(np.float32)


class TestTransformImage:
    def setup_method(self):
        self.vt = ViewTransformer(CAM.project_ground(GROUND), GROUND)  # target in metres

    def test_lands_where_the_pinhole_camera_projects(self):
        """A frame whose pixels hold their own (u, v): every output pixel holds the image point that the
        camera projects its ground point to (bilinear interpolation of a linear image is exact, up to
        OpenCV's 1/32 px sub-pixel steps)."""
        v, u = np.mgrid[0:720, 0:1280].astype(np.float32)
        top = self.vt.transform_image(np.dstack([u, v]), (800, 800), MAP)
        py, px = np.mgrid[0:800, 0:800]
        expected = CAM.project_ground(MAP.to_metres(np.column_stack([px.ravel(), py.ravel()]))).reshape(800, 800, 2)
        inside = np.all((expected >= 1) & (expected <= [1278, 718]), axis=-1)
        assert inside.sum() > 50_000
        np.testing.assert_allclose(top[inside], expected[inside], atol=1 / 32 + 1e-3)

    def test_known_ground_points_land_on_their_map_pixels(self):
        """A frame showing 1 m ground squares where the camera sees them: on the map, each square's centroid is
        at the map pixel of its centre."""
        ground = np.array([[0.0, 5.0], [-3.0, 10.0], [4.0, 15.0], [-6.0, 20.0]])
        frame = np.zeros((720, 1280), np.float32)
        for x, y in ground:
            square = CAM.project_ground([[x - 0.5, y + 0.5], [x + 0.5, y + 0.5], [x + 0.5, y - 0.5],
                                         [x - 0.5, y - 0.5]])
            cv2.fillPoly(frame, [np.rint(square * 16).astype(np.int32)], 1.0, shift=4)
        top = self.vt.transform_image(frame, (800, 800), MAP)
        found = []
        for px, py in np.rint(MAP.to_pixels(ground)).astype(int):
            w = top[py - 10:py + 11, px - 10:px + 11]
            yy, xx = np.mgrid[py - 10:py + 11, px - 10:px + 11]
            found.append([(w * xx).sum() / w.sum(), (w * yy).sum() / w.sum()])
        np.testing.assert_allclose(MAP.to_metres(found), ground, atol=0.05)

    def test_matches_opencv_warp_and_blanks_what_is_behind_the_camera(self):
        """Against cv2.warpPerspective with OpenCV's own homography (float32); WAVES changes up to 20 a pixel,
        so 0.5 px off would differ by 7."""
        source = CAM.project_ground(GROUND).astype(np.float32)
        m = cv2.getPerspectiveTransform(source, MAP.to_pixels(GROUND).astype(np.float32))
        theirs = cv2.warpPerspective(WAVES, m, (800, 800))
        ours = self.vt.transform_image(WAVES, (800, 800), MAP)
        behind = np.zeros((800, 800), bool)
        behind[int(MAP.origin_px[1] + 10 * 4 * np.tan(np.radians(15))) + 1:] = True  # y < -h tan(tilt) = -1.07 m
        assert (ours[behind] == 0).all() and np.abs(theirs[behind]).max() > 100  # OpenCV paints the sky there
        np.testing.assert_allclose(ours[~behind], theirs[~behind], atol=0.5)

    def test_site_map_pixels_target(self):
        """A transformer built on site-map pixels gives the same image without a site_map."""
        vt_px = ViewTransformer(CAM.project_ground(GROUND), MAP.to_pixels(GROUND))
        a, b = vt_px.transform_image(WAVES, (800, 800)), self.vt.transform_image(WAVES, (800, 800), MAP)
        np.testing.assert_allclose(a, b, atol=0.5)

    def test_a_map_all_in_front_is_opencv_warp_itself(self):
        """Map rows 0..599 are y >= 0.1 m, all in front of the camera: nothing is blanked."""
        m = np.linalg.inv(MAP.to_metres_matrix) @ self.vt.m
        ours = self.vt.transform_image(WAVES, (800, 600), MAP)
        np.testing.assert_array_equal(ours, cv2.warpPerspective(WAVES, m, (800, 600)))

    @pytest.mark.parametrize("image,size,message", [
        (np.zeros((720, 1280), np.uint8), (0, 800), "size"),
        (np.zeros((720, 1280), np.uint8), (800,), "size"),
        (np.zeros((720, 1280), np.uint8), (800.5, 600), "size"),
        (np.zeros(720, np.uint8), (800, 600), "image"),
    ])
    def test_bad_input(self, image, size, message):
        with pytest.raises(ValueError, match=message):
            self.vt.transform_image(image, size, MAP)


def rasterised_box(mask: np.ndarray) -> dict[str, list[float]]:
    """The box of a mask in each convention, computed from its pixel rows and columns (as each tool does)."""
    rows, cols = np.nonzero(mask)
    x, y, w, h = cv2.boundingRect(mask)  # OpenCV: corners convention, (x + w, y + h) one past the last pixel
    return {"corners": [x, y, x + w, y + h],
            "indices": [cols.min(), rows.min(), cols.max(), rows.max()],  # supervision's mask_to_xyxy
            "homocal": [cols.min() - 0.5, rows.min() - 0.5, cols.max() + 0.5, rows.max() + 0.5]}


class TestBoxBottomPoints:
    @pytest.mark.parametrize("seed", range(5))
    def test_every_convention_gives_the_bottom_edge_centre(self, seed):
        rng = np.random.default_rng(seed)
        mask = np.zeros((120, 160), np.uint8)
        cv2.fillPoly(mask, [rng.integers(5, 115, (5, 2)).astype(np.int32)], 1)
        rows, cols = np.nonzero(mask)
        expected = [(cols.min() + cols.max()) / 2, rows.max() + 0.5]  # homocal pixels: centres at integers
        for convention, box in rasterised_box(mask).items():
            np.testing.assert_array_equal(box_bottom_points([box], convention=convention), [expected])

    def test_against_the_pinhole_camera(self):
        """A pole on the ground near 40 m, rendered by pixel-centre sampling at 200 sub-pixel positions: the
        converted corners box bottom is unbiased; the raw y2 (corners taken for homocal pixels) is 0.5 px low,
        0.33 m nearer."""
        v = CAM.project_ground([[0.0, 40.0]])[0, 1] + np.arange(-100, 100) / 100  # two pixels, evenly
        d = CAM.ray_to_ground(np.column_stack([np.full(200, 639.5), v]))[:, 1]
        bottom = CAM.project_ground(np.column_stack([np.zeros_like(d), d]))  # the pole's foot, exact
        r1 = np.floor(bottom[:, 1])  # lowest pixel row whose centre the pole covers
        c = np.round(bottom[:, 0])
        corners = np.column_stack([c - 1, r1 - 30, c + 2, r1 + 1])  # a 3 px wide pole, corners convention
        feet = box_bottom_points(corners, convention="corners")
        assert np.abs(feet[:, 1] - bottom[:, 1]).max() <= 0.5 and abs(np.mean(feet[:, 1] - bottom[:, 1])) < 0.02
        vt = ViewTransformer(CAM.project_ground(GROUND), GROUND)
        assert abs(np.mean(vt.transform_points(feet)[:, 1] - d)) < 0.02
        raw = np.column_stack([(corners[:, 0] + corners[:, 2]) / 2, corners[:, 3]])
        assert np.mean(vt.transform_points(raw)[:, 1] - d) == pytest.approx(-0.33, abs=0.02)

    @pytest.mark.parametrize("d,metres", [(10, 0.02), (20, 0.09), (40, 0.33), (50, 0.51)])
    def test_documented_half_pixel_cost(self, d, metres):
        """homocal/geometry/boxes.py's figures: a foot point 0.5 px low, straight ahead on the paper's camera."""
        low = CAM.project_ground([[0.0, d]]) + [0.0, 0.5]
        assert d - CAM.ray_to_ground(low)[0, 1] == pytest.approx(metres, abs=0.005)

    @pytest.mark.parametrize("xyxy,convention,message", [
        ([[0, 0, 10, 10]], "yolo", "convention 'yolo'"),
        ([0, 0, 10, 10], "corners", r"shape \(N, 4\)"),
        ([[0, 0, 10]], "corners", r"shape \(N, 4\)"),
        ([["a", "b", "c", "d"]], "corners", r"shape \(N, 4\)"),
    ])
    def test_bad_input(self, xyxy, convention, message):
        with pytest.raises(ValueError, match=message):
            box_bottom_points(xyxy, convention=convention)
