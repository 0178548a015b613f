"""homocal.geometry against independent computations: pinhole projection, OpenCV, hand-made quads."""
import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from homocal.geometry import PinholeCamera, SiteMap, ViewTransformer, check_orientation, signed_area, validate_quad

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
