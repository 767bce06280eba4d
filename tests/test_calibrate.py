"""Camera calibration (ffls.camera.calibrate) on synthetic ChArUco views with a known K.

A ChArUco board image from OpenCV is warped into seven views through known poses and a known K
(the homography K [r1 r2 t] composed with the board-image-from-plane homography), so the
ground truth matches cv2.projectPoints exactly. Tolerances: focal length within 0.5 %,
principal point within 3 px, RMS reprojection error below 0.5 px.
"""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from ffls.errors import InputError
from ffls.camera import calibrate as cal

K_TRUE = np.array([[820.0, 0, 331.0], [0, 820.0, 236.0], [0, 0, 1]])
SQUARES, SQ, MK = (7, 5), 0.03, 0.022
W, H = 640, 480


def _views():
    board = cal.make_board(SQUARES, SQ, MK)
    px_per_m = 4000.0  # 120 px squares
    margin = 40
    size = (int(SQUARES[0] * SQ * px_per_m) + 2 * margin, int(SQUARES[1] * SQ * px_per_m) + 2 * margin)
    flat = board.generateImage(size, marginSize=margin, borderBits=1)
    # board-image pixels from board-plane metres, measured on the flat image itself
    obj, img = cal.detect_board(flat, "charuco", SQUARES, SQ, MK)
    Hb, _ = cv2.findHomography(obj[:, :2], img, 0)
    views = []
    # (rotation about x, y, z in degrees; board centre offset in metres) -- tilted views spread
    # over the frame so that distortion and principal point are separable
    poses = [(0, 0, 0, 0, 0), (30, 0, 0, 0.05, 0.03), (-30, 5, 0, -0.05, -0.03), (0, 30, 10, -0.06, 0.04),
             (5, -30, -10, 0.06, -0.04), (20, 20, 30, 0.0, 0.05), (-20, -20, -20, 0.0, -0.05)]
    for k, (ax, ay, az, ox, oy) in enumerate(poses):
        rvec = np.deg2rad([ax, ay, az]).astype(np.float64)
        R, _ = cv2.Rodrigues(rvec)
        centre = np.array([SQUARES[0] * SQ / 2, SQUARES[1] * SQ / 2, 0])
        t = np.array([ox, oy, 0.42]) - R @ centre
        Hv = K_TRUE @ np.column_stack([R[:, 0], R[:, 1], t])
        M = Hv @ np.linalg.inv(Hb)
        v = cv2.warpPerspective(flat, M, (W, H), flags=cv2.INTER_AREA, borderValue=200)
        views.append(cv2.GaussianBlur(v, (0, 0), 0.6))
    return views


@pytest.fixture(scope="module")
def views():
    return _views()


def test_charuco_recovers_K(views):
    res = cal.calibrate_camera([f"v{i}.png" for i in range(len(views))], board="charuco", squares=SQUARES,
                               square_size=SQ, marker_size=MK, images=views)
    assert res.rms < 0.5
    assert abs(res.K[0, 0] / K_TRUE[0, 0] - 1) < 0.005
    assert abs(res.K[1, 1] / K_TRUE[1, 1] - 1) < 0.005
    assert np.hypot(res.K[0, 2] - K_TRUE[0, 2], res.K[1, 2] - K_TRUE[1, 2]) < 3.0
    # the true lens has no distortion: the fitted model moves points by < 0.5 px within 200 px
    # of the centre (the coefficients themselves trade off against each other)
    t = np.linspace(0, 2 * np.pi, 24)
    pts = np.stack([200 * np.cos(t) + 331, 200 * np.sin(t) + 236], 1)
    rays = np.column_stack([(pts - K_TRUE[:2, 2]) / 820.0, np.ones(len(t))])
    moved, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), res.K, res.dist)
    ideal, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), res.K, None)
    assert np.max(np.linalg.norm(moved - ideal, axis=-1)) < 0.5
    assert len(res.used) == len(views)


def test_cli_writes_capture_json(tmp_path, views):
    from ffls.cli import main
    paths = []
    for i, v in enumerate(views):
        p = tmp_path / f"v{i}.png"
        cv2.imwrite(str(p), v)
        paths.append(str(p))
    cap = tmp_path / "cap"
    cap.mkdir()
    (cap / "capture.json").write_text(json.dumps({"format": "x", "sphere_radius": 0.05, "camera": {"world_from_camera": np.eye(4).tolist()}}))
    assert main(["calibrate", "camera", *paths, "--squares", "7x5", "--square-size", "0.03", "--marker-size", "0.022",
                 "--capture", str(cap)]) == 0
    doc = json.loads((cap / "capture.json").read_text())
    assert doc["format"] == "x" and doc["sphere_radius"] == 0.05
    assert doc["camera"]["world_from_camera"] == np.eye(4).tolist()
    assert abs(doc["camera"]["K"][0][0] / 820 - 1) < 0.005 and len(doc["camera"]["dist"]) == 5


def test_too_few_boards_names_folder(tmp_path):
    blank = np.full((120, 160), 128, np.uint8)
    with pytest.raises(InputError, match="found in 0 of 3 photos"):
        cal.calibrate_camera([tmp_path / f"b{i}.png" for i in range(3)], images=[blank] * 3)
    with pytest.raises(InputError, match="image file not found") as e:
        cal.calibrate_camera([tmp_path / "missing.png"])
    assert "missing.png" in str(e.value)


def test_write_camera_needs_capture(tmp_path):
    with pytest.raises(InputError, match="capture.json not found"):
        cal.write_camera_to_capture(tmp_path, np.eye(3), np.zeros(5))


def test_same_view_twice_is_refused(views):
    with pytest.raises(InputError, match="the same image as v0.png") as e:
        cal.calibrate_camera(["v0.png", "v1.png", "v2.png", "v0b.png"], images=[views[0], views[1], views[2], views[0]])
    assert "v0b.png" in str(e.value)


def test_two_photos_of_one_view_are_refused(views):
    # one view, three files that differ in one pixel: calibrateCamera returned fx ~5e7 px (~1e10 px
    # for a chessboard): the corners of each are within SAME_VIEW_PX of the first's
    alike = []
    for k in range(3):
        v = views[0].copy()
        v[0, k] ^= 1
        alike.append(v)
    with pytest.raises(InputError, match=r"b.png: shows the board where a.png does"):
        cal.calibrate_camera(["a.png", "b.png", "c.png"], images=alike)


def test_camera_matrix_bounds_are_capture_json_ones():
    assert cal.camera_matrix_problem([[820.0, 0, 331], [0, 820.0, 236], [0, 0, 1]]) is None
    assert "beyond 1e+08 px" in cal.camera_matrix_problem([[1.26e10, 0, 240], [0, 8.2e9, 200], [0, 0, 1]])
    assert "far from square" in cal.camera_matrix_problem([[5000.0, 0, 240], [0, 500.0, 200], [0, 0, 1]])
    assert "not positive" in cal.camera_matrix_problem([[-5.0, 0, 240], [0, 500.0, 200], [0, 0, 1]])


def test_capture_of_another_size_is_refused(tmp_path):
    doc = {"format": "ffls-capture", "image_size": [96, 96], "camera": {}}
    (tmp_path / "capture.json").write_text(json.dumps(doc))
    K = [[500.0, 0, 240], [0, 500.0, 200], [0, 0, 1]]
    with pytest.raises(InputError, match="image_size 96x96 differs from the 480x400 board photos"):
        cal.write_camera_to_capture(tmp_path, K, np.zeros(5), image_size=(480, 400))
    assert json.loads((tmp_path / "capture.json").read_text()) == doc
    cal.write_camera_to_capture(tmp_path, K, np.zeros(5), image_size=(96, 96))
    assert json.loads((tmp_path / "capture.json").read_text())["camera"]["K"] == K


def test_camera_help_gives_every_board_default(capsys):
    """``ffls calibrate camera --help`` showed no default for --board and --squares: a first user could not
    tell that a board photographed as 5x7 is taken as 7x5 unless said."""
    from ffls.cli import main

    with pytest.raises(SystemExit) as done:
        main(["calibrate", "camera", "--help"])
    assert done.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "(default charuco)" in text and "(default 7x5)" in text and "(default 0.03)" in text


def test_a_board_given_with_its_squares_swapped_says_which_it_is(tmp_path, views):
    """A 7x5 ChArUco board given as ``--squares 5x7`` (board printers name columns and rows in either
    order) was "found in 0 of 7 photos"; the line now says it is found as 7x5. Nothing is said where the
    swapped board is not found either."""
    names = [tmp_path / f"v{i}.png" for i in range(len(views))]
    with pytest.raises(InputError) as e:
        cal.calibrate_camera(names, squares=(5, 7), square_size=SQ, marker_size=MK, images=views)
    assert "found in 0 of 7 photos" in str(e.value)
    assert "found as 7x5 squares in 3 of the first 3 photos without it: give --squares 7x5" in str(e.value)
    blank = np.full((120, 160), 128, np.uint8)
    with pytest.raises(InputError) as e:
        cal.calibrate_camera(names[:3], squares=(5, 7), images=[blank] * 3)
    assert "found as" not in str(e.value)
