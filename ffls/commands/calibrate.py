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


#: ChArUco defaults of ``calibrate camera`` (None in the parsed flags when not given, so that a
#: chessboard refuses them).
MARKER_SIZE = 0.022
DICTIONARY = "DICT_5X5_100"


def _dictionary_name(text: str) -> str:
    """argparse type: an OpenCV ArUco dictionary name."""
    import argparse

    from ffls.camera.calibrate import aruco_dictionary

    try:
        aruco_dictionary(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
    return text


def board_flags(args) -> dict:
    """The board keywords of :func:`ffls.camera.calibrate.calibrate_camera` from the parsed flags.

    Raises InputError (one line naming the flag) for a ChArUco flag with ``--board chessboard``
    (it would do nothing) and for a ChArUco board OpenCV cannot build.
    """
    from ffls.camera.calibrate import charuco_problem
    from ffls.errors import InputError

    if args.board == "chessboard":
        for flag, v in (("--marker-size", args.marker_size), ("--dictionary", args.dictionary)):
            if v is not None:
                raise InputError(f"{flag} is for --board charuco: a chessboard has no markers")
        return dict(board="chessboard", squares=args.squares, square_size=args.square_size)
    marker = MARKER_SIZE if args.marker_size is None else args.marker_size
    dictionary = DICTIONARY if args.dictionary is None else args.dictionary
    if not marker < args.square_size:
        raise InputError(f"--marker-size {marker:g} must be smaller than --square-size {args.square_size:g}"
                         " (a marker sits inside a square)")
    why = charuco_problem(args.squares, args.square_size, marker, dictionary)
    if why:
        raise InputError(f"--squares {args.squares[0]}x{args.squares[1]} with --dictionary {dictionary}: {why}")
    return dict(board="charuco", squares=args.squares, square_size=args.square_size, marker_size=marker,
                dictionary=dictionary)


#: The most pixel samples ``calibrate response --samples`` takes: OpenCV's Debevec solve is an SVD
#: whose time grows with the cube of the samples (docs/reliability.md).
MAX_RESPONSE_SAMPLES = 1000


def add_arguments(p):
    from ffls.commands.common import input_path, integer, number, output_path, size_wxh

    sub = p.add_subparsers(dest="what", metavar="WHAT", required=True)
    r = sub.add_parser("response", help="inverse camera response from bracketed photos (Debevec-Malik 1997)")
    r.add_argument("bracket_dir", type=input_path,
                   help="folder of bracketed 8-bit photos (+ exposures.json, or EXIF exposure times)")
    r.add_argument("-o", "--output", default="response.npy", type=output_path((".npy", ".csv")),
                   help="output table, .npy or .csv (default response.npy)")
    # OpenCV's solve grows with the cube of the samples (3 photos: 1000 in 8 s, 1600 in 23 s), and
    # Debevec-Malik need only samples x (photos - 1) > 255 (docs/reliability.md)
    r.add_argument("--samples", type=integer(10, MAX_RESPONSE_SAMPLES, why=(
        "OpenCV's solve time grows with the cube of the samples: 1600 took 23 s on 3 photos")), default=70,
                   help=f"pixel samples for the solver, 10 to {MAX_RESPONSE_SAMPLES} (default 70; the solve's time "
                        "grows with the cube of the samples)")
    r.add_argument("--smoothness", type=number(0.0, 1e6, lo_open=True), default=10.0,
                   help="smoothness weight lambda, > 0 (default 10)")
    c = sub.add_parser("camera", help="camera matrix and distortion from photos of a calibration board")
    c.add_argument("photos", nargs="+", type=input_path, help="photos of the board")
    c.add_argument("--board", choices=("charuco", "chessboard"), default="charuco",
                   help="the board's kind (default charuco)")
    c.add_argument("--squares", type=size_wxh(2, 100), default=(7, 5),
                   help="squares along x and y, e.g. 7x5 (default 7x5)")
    c.add_argument("--square-size", type=number(0.0, 1e3, lo_open=True), default=0.03, help="square side, scene units (default 0.03)")
    c.add_argument("--marker-size", type=number(0.0, 1e3, lo_open=True), default=None,
                   help=f"ArUco marker side, smaller than --square-size (charuco only; default {MARKER_SIZE})")
    c.add_argument("--dictionary", type=_dictionary_name, default=None,
                   help=f"ArUco dictionary, OpenCV's name (charuco only; default {DICTIONARY})")
    c.add_argument("--capture", type=input_path,
                   help="capture folder whose capture.json gets camera.K and camera.dist")


def run(args) -> int:
    if args.what == "response":
        from ffls.radiance.response import calibrate_response_folder

        curve = calibrate_response_folder(args.bracket_dir, args.output, samples=args.samples,
                                          smoothness=args.smoothness)
        print(f"wrote {args.output}: inverse response (256, 3), code 128 -> {curve[128].round(4).tolist()}")
        return 0
    from ffls.camera.calibrate import calibrate_camera, check_camera_capture, write_camera_to_capture

    if args.capture:  # before the calibration: a missing or read-only capture was reported after it
        check_camera_capture(args.capture)
    cal = calibrate_camera(args.photos, **board_flags(args))
    if args.capture:
        path = write_camera_to_capture(args.capture, cal.K, cal.dist, cal.image_size)
        legacy = ("; the board's ChArUco layout is OpenCV's legacy one, of boards made before OpenCV 4.6"
                  if cal.legacy_pattern else "")
        print(f"wrote camera.K and camera.dist to {path} (rms {cal.rms:.3f} px, {len(cal.used)} views"
              f", {len(cal.skipped)} skipped{legacy})")
    else:
        json.dump(cal.to_dict(), sys.stdout, indent=2)
        print()
    return 0
