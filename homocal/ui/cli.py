"""``homocal ui``: the browser page to click the trapezoid and the reference points (served on 127.0.0.1)."""
from __future__ import annotations

import argparse
from pathlib import Path

from homocal.arguments import CAMERA_JSON_HELP, camera_json, number, xy_pair
from homocal.geometry import SiteMap
from homocal.boxes import MAX_FPS
from homocal.ui import session as sessions
from homocal.ui.server import UIServer

EPILOG = """\
With DATASET (a simgen dataset folder) the frame is video.mp4's, the site map site_map.png with the scale and
origin of site_map.json; the page can also take its hand-placed trapezoid and its calibration objects.
Otherwise give --frame, --site-map and --scale. The site map must have map up = forward (away from the
camera); a mirrored or upside-down map is refused when its corners are clicked.
With --boxes FILE (a MOTChallenge .txt, a detections.parquet or a .csv of frame,x1,y1,x2,y2, as homocal fit
--boxes reads them; a dataset's detections.parquet by default) the page also fits --method pedestrians from
those people's boxes, and draws the fitted horizon beside the clicked one; "Horizon over time" runs homocal
watch's calibrator over them at --fps and plots the horizon over time with the detected moves (a click on the
plot picks the stretch whose correction a pedestrians fit uses).
The line tool (click mode "straight lines") fits the lens from polylines along straight edges, as homocal lens
--lines, and uses it from then on; Save lens writes lines.json and lens.json into --out. Calibrate does the same
from uploaded checkerboard photographs, as homocal lens --checkerboard (Save lens also writes them).
Save writes trapezoid.json, reference_points.csv and correction.json into --out, in the formats of
homocal fit and homocal apply (for a fit from boxes also camera_intrinsics.json, the image size and K it
used, as --camera-json), and shows the homocal fit command that writes the same correction from them; it
asks before replacing a file it did not write. Load reads them back."""


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``ui``."""
    ui = subparsers.add_parser(
        "ui", help="click the trapezoid and reference points in a browser page", epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Serve a local page to click the trapezoid and reference points, see the ground grid, "
                    "fit a correction with its error bars, and save the files homocal fit and apply read.",
    )
    ui.add_argument("dataset", nargs="?", type=Path, metavar="DATASET", help="a simgen dataset folder")
    ui.add_argument("--frame", type=Path, metavar="FRAME.png|VIDEO.mp4", help="the camera frame (an image or a video)")
    ui.add_argument("--frame-index", type=number(int, 0), default=0, metavar="N", help="video frame to show, from 0 (default 0)")
    ui.add_argument("--site-map", type=Path, metavar="MAP.png", help="the site map image (top-down, map up = forward)")
    ui.add_argument("--scale", type=number(float, 0, low_open=True), metavar="PX_PER_M", help="site map pixels per metre")
    ui.add_argument("--origin", type=xy_pair, default=(0.0, 0.0), metavar="X,Y",
                    help="site map pixel of the ground origin (default 0,0: the top-left pixel)")
    ui.add_argument("--camera-origin", type=xy_pair, default=(0.0, 0.0), metavar="X,Y",
                    help="ground point under the camera, metres (default 0,0; the page can change it)")
    ui.add_argument("--boxes", type=Path, metavar="BOXES", help="people's boxes for --method pedestrians (default: "
                    "DATASET's detections.parquet)")
    ui.add_argument("--fps", type=number(float, 0, MAX_FPS, low_open=True), help="frames per second of the boxes' "
                    "video, for the horizon over time (default: what the boxes file's folder says)")
    ui.add_argument("--camera-json", type=Path, metavar="CAMERA.json", help=CAMERA_JSON_HELP + "; the page draws the "
                    "grid and horizon through it (default: DATASET's camera.json)")
    ui.add_argument("-o", "--out", type=Path, default=Path("."), metavar="DIR",
                    help="folder Save writes to (default .); made if missing, inside an existing folder")
    ui.add_argument("--port", type=number(int, 0, 65535), default=0, help="port on 127.0.0.1 (default 0: a free one)")
    ui.set_defaults(handler=handle_ui)


def handle_ui(args: argparse.Namespace) -> int:
    if args.dataset is not None:
        extra = [f for f, v in (("--frame", args.frame), ("--site-map", args.site_map), ("--scale", args.scale)) if v]
        if extra:
            raise ValueError(f"give either DATASET or --frame/--site-map/--scale, not both ({', '.join(extra)})")
        session = sessions.from_dataset(args.dataset, args.out, args.frame_index, args.boxes, args.fps)
    else:
        missing = [f for f, v in (("--frame", args.frame), ("--site-map", args.site_map), ("--scale", args.scale))
                   if v is None]
        if missing:
            raise ValueError(f"give a DATASET folder, or --frame, --site-map and --scale (missing {', '.join(missing)})")
        session = sessions.from_files(args.frame, args.site_map, SiteMap(args.scale, args.origin), args.camera_origin,
                                      args.out, args.frame_index, args.boxes, args.fps)
    camera = camera_json(args.camera_json)
    if camera is not None:
        sessions.use_lens(session, camera.lens, args.camera_json)
    server = UIServer(session, args.port)
    try:
        session.out_dir.mkdir(exist_ok=True)
        print(f"homocal ui: {session.title} on {server.url} (saves to {session.out_dir}; Ctrl-C to stop)", flush=True)
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()
    return 0

