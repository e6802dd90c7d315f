"""``fgslam tune-colours``: fit the landmark colours to the user's own frames, and show what they find.

Reads RGB-D frames (a TUM RGB-D folder, e.g. one ``fgslam record --save-frames`` wrote) in
which the landmarks are seen, tunes the HSV ranges of the landmark file
(:mod:`slamio.camera.tune`: loosen, find the landmarks with every check, fit the ranges to
their pixels) and writes the tuned file. ``--show DIR`` writes, per frame, the colour
masks of the tuned ranges (``*_mask.png``: each landmark colour painted in its own colour,
the rest black) and the detections with the tuned file (``*_detections.png``: every
candidate blob, measurements and rejection reasons), to check by eye before
``fgslam detect --landmarks``.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from fgslam.cli.common import (
    add_overwrite_option,
    add_verb,
    check_new_file,
    check_number,
    holds_outputs,
    probe_writable,
    write_new_file,
)
from fgslam.cli.verbs import help_of
from slamio.errors import FgslamError

DESCRIPTION = """\
Tune the landmark colours of a landmark file (YAML/JSON, docs/camera.md) on your own frames.

The ranges are loosened, the landmarks found in every frame with the same checks as
fgslam detect (shape, depth, width at depth, height: clutter does not count), and the ranges
fitted to the found landmarks' pixels. Shapes, sizes, ids and tolerances are kept: set them
in the file first (width and height are what the checks trust). A colour found in no frame
keeps its ranges; the summary says so.
"""


def add_parser(verbs) -> argparse.ArgumentParser:
    from slamio.camera.sources import TUM_DEPTH_SCALE_PER_M

    p = add_verb(
        verbs, "tune-colours",
        help=help_of("tune-colours"),
        description=DESCRIPTION,
        epilog="example:\n  fgslam tune-colours run/frames --camera kinect.yaml --out landmarks.yaml --show run/tuning",
    )
    p.add_argument("frames", metavar="FRAMES", help="RGB-D frames: a TUM RGB-D folder (rgb/, depth/)")
    p.add_argument("--camera", required=True, metavar="CAM.yaml", help="camera file: a ROS camera_info YAML (intrinsics, mount) "
                   "or a Kalibr cameras.yaml")
    p.add_argument("--camera-name", default=None, metavar="NAME",
                   help="the camera of a Kalibr file holding several (cam0, cam1, ...)")
    p.add_argument("--out", required=True, metavar="FILE", help="the tuned landmark file (.yaml, or .json)")
    p.add_argument("--landmarks", default=None, metavar="FILE",
                   help="the landmark file to start from (default seed 000's red/green/blue cylinders)")
    p.add_argument("--show", default=None, metavar="DIR", help="write the masks and detections (PNG) here")
    p.add_argument("--hue-widen", type=int, default=12, metavar="H",
                   help="hue search this far beyond the starting ranges, OpenCV units 0-179 (default 12)")
    p.add_argument("--depth-scale", type=float, default=TUM_DEPTH_SCALE_PER_M, metavar="UNITS_PER_M",
                   help="depth PNG units per metre (TUM 5000, the default; millimetre PNGs 1000)")
    add_overwrite_option(p, "an existing --out FILE")
    p.set_defaults(func=cmd_tune_colours)
    return p


def _frames(args):
    from slamio.camera.sources import open_frames

    return open_frames(args.frames, depth_scale_per_m=args.depth_scale)


def _mask_picture(bgr, options):
    """Each landmark colour's cleaned mask painted in that colour's mean BGR; the rest black."""
    import cv2
    import numpy as np

    from slamio.camera.colour import clean_mask, colour_mask

    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    out = np.zeros_like(bgr)
    for colour in options.colours:
        mask = clean_mask(colour_mask(hsv, colour), options.open_px, options.close_px) > 0
        if mask.any():
            out[mask] = np.mean(bgr[mask], axis=0).astype(np.uint8)
    return out


@holds_outputs(out="--out", show="--show")
def cmd_tune_colours(args: argparse.Namespace) -> int:
    import cv2

    from slamio.camera.colour import ColourOptions
    from slamio.camera.detect import DetectionStats, FrontEnd, FrontEndConfig, annotate
    from slamio.camera.landmark_file import load_landmarks, save_landmarks
    from slamio.camera.model import load_camera
    from slamio.camera.tune import loosened, sample_frame, tuned_options

    if not 0 <= args.hue_widen <= 60:
        raise FgslamError(f"--hue-widen must be 0..60 (OpenCV hue units), got {args.hue_widen}")
    check_number("--depth-scale", args.depth_scale, above=0,  # 0 would divide every depth by zero
                 what="depth PNG units per metre: TUM 5000, millimetre PNGs 1000")
    out = check_new_file(args.out, overwrite=args.overwrite, example="landmarks.yaml")
    camera = load_camera(args.camera, args.camera_name)
    start = load_landmarks(args.landmarks) if args.landmarks else ColourOptions()
    show = Path(args.show) if args.show else None
    if show is not None:
        probe_writable(show, option="--show")
    loose = replace(start, colours=tuple(loosened(c, args.hue_widen) for c in start.colours))
    samples: dict = {}
    frames = with_depth = 0
    for frame in _frames(args):
        frames += 1
        if frame.bgr is None or frame.depth_m is None:
            continue
        with_depth += 1
        sample_frame(frame.bgr, frame.depth_m, camera, loose, samples)
    if with_depth == 0:
        raise FgslamError(f"{args.frames}: {frames} frames, none with a depth image; tuning needs RGB-D frames "
                          "(a TUM RGB-D folder: rgb/, depth/)")
    tuned = tuned_options(start, samples)
    lines = []
    for before, after in zip(start.colours, tuned.colours):
        seen = samples.get(before.name)
        if seen is None or after is before:
            lines.append(f"  {before.name}: not found in any frame; ranges kept (check its width_m/height_m, or "
                         f"widen --hue-widen)")
        else:
            lines.append(f"  {before.name}: found in {seen.frames_found} of {with_depth} frames, "
                         f"{len(seen.stacked())} pixels; hsv {_ranges(before.hsv_ranges)} -> {_ranges(after.hsv_ranges)}")
    comment = f"tuned by fgslam tune-colours on {args.frames} ({with_depth} RGB-D frames)"
    write_new_file(out, lambda tmp: save_landmarks(tmp, tuned, comment, as_json=out.suffix.lower() == ".json"),
                   overwrite=args.overwrite)
    stats = DetectionStats()
    front = FrontEnd(camera, FrontEndConfig(kind="colour", colour=tuned))
    if show is not None:
        show.mkdir(parents=True, exist_ok=True)
    for frame in _frames(args):  # what the tuned file finds, frame by frame
        result = front.process(frame)
        stats.add(result)
        if show is not None and frame.bgr is not None:
            stem = f"{frame.index:06d}_{Path(frame.name).stem}"
            cv2.imwrite(str(show / f"{stem}_mask.png"), _mask_picture(frame.bgr, tuned))
            cv2.imwrite(str(show / f"{stem}_detections.png"), annotate(frame.bgr, result, camera))
    print(f"wrote {out}: {len(tuned.colours)} landmark colours tuned on {with_depth} RGB-D frames")
    print("\n".join(lines))
    print("with the tuned file: " + stats.summary())
    if show is not None:
        print(f"masks and detections in {show}/")
    return 0


def _ranges(ranges) -> str:
    return " + ".join(f"H {lo[0]}-{hi[0]} S>={lo[1]} V>={lo[2]}" for lo, hi in ranges)
