"""``ffls calibrate``: camera response from a bracket, camera intrinsics from board photos."""
from __future__ import annotations

import json
import sys

NAME = "calibrate"
#: The attribute that names the chosen subcommand (``ffls calibrate WHAT``).
SUBCOMMAND_DEST = "what"
HELP = "calibrate the camera: response curve (bracketed photos) or intrinsics (ChArUco/chessboard photos)"
DESCRIPTION = (
    "ffls calibrate response BRACKET_DIR [-o response.npy]: Debevec-Malik inverse response from a folder of "
    "bracketed 8-bit photos; exposure times from BRACKET_DIR/exposures.json ({\"file\": seconds}) or, without it, "
    "from each photo's EXIF ExposureTime. "
    "ffls calibrate camera PHOTOS... --board charuco --squares 7x5 --square-size 0.03 --marker-size 0.022 "
    "[--capture CAPTURE_DIR]: K and distortion, written into CAPTURE_DIR/capture.json or printed as JSON."
)


def add_arguments(p):
    from ffls.commands.common import integer, number, output_path, size_wxh

    sub = p.add_subparsers(dest="what", metavar="WHAT", required=True)
    r = sub.add_parser("response", help="inverse camera response from bracketed photos (Debevec-Malik 1997)")
    r.add_argument("bracket_dir", help="folder of bracketed 8-bit photos (+ exposures.json, or EXIF exposure times)")
    r.add_argument("-o", "--output", default="response.npy", type=output_path((".npy", ".csv")),
                   help="output table, .npy or .csv (default response.npy)")
    r.add_argument("--samples", type=integer(10, 100000), default=70,
                   help="pixel samples for the solver, 10 to 100000 (default 70)")
    r.add_argument("--smoothness", type=number(0.0, 1e6, lo_open=True), default=10.0,
                   help="smoothness weight lambda, > 0 (default 10)")
    c = sub.add_parser("camera", help="camera matrix and distortion from photos of a calibration board")
    c.add_argument("photos", nargs="+", help="photos of the board")
    c.add_argument("--board", choices=("charuco", "chessboard"), default="charuco")
    c.add_argument("--squares", type=size_wxh(2, 100), default=(7, 5), help="squares along x and y, e.g. 7x5")
    c.add_argument("--square-size", type=number(0.0, 1e3, lo_open=True), default=0.03, help="square side, scene units (default 0.03)")
    c.add_argument("--marker-size", type=number(0.0, 1e3, lo_open=True), default=0.022, help="ArUco marker side (default 0.022)")
    c.add_argument("--dictionary", default="DICT_5X5_100", help="ArUco dictionary (default DICT_5X5_100)")
    c.add_argument("--capture", help="capture folder whose capture.json gets camera.K and camera.dist")


def run(args) -> int:
    if args.what == "response":
        from ffls.radiance.response import calibrate_response_folder

        curve = calibrate_response_folder(args.bracket_dir, args.output, samples=args.samples,
                                          smoothness=args.smoothness)
        print(f"wrote {args.output}: inverse response (256, 3), code 128 -> {curve[128].round(4).tolist()}")
        return 0
    from ffls.camera.calibrate import calibrate_camera, write_camera_to_capture

    cal = calibrate_camera(args.photos, board=args.board, squares=args.squares, square_size=args.square_size,
                           marker_size=args.marker_size, dictionary=args.dictionary)
    if args.capture:
        path = write_camera_to_capture(args.capture, cal.K, cal.dist)
        print(f"wrote camera.K and camera.dist to {path} (rms {cal.rms:.3f} px, {len(cal.used)} views"
              f", {len(cal.skipped)} skipped)")
    else:
        json.dump(cal.to_dict(), sys.stdout, indent=2)
        print()
    return 0
