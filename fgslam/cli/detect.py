"""``fgslam detect``: camera frames → landmark observations in a run log.

``add_parser(verbs)`` adds the verb to ``fgslam``'s sub-parsers. The verb reads a
frame folder (TUM RGB-D or plain images) or a video file, runs the camera front-end
(:mod:`slamio.camera.detect`) on every frame and adds the observations to ``--out``:

- **LOG exists** (a recorded run: header and odometry): each frame's observations are put
  into the pose that is current at the frame's stamp — the pose started by the last
  odometry record at or before it — right after the records stamped at or before the frame,
  so stamps stay in order. The log format ties an observation to the latest pose, so a
  recorder writes an odometry record at each camera time (docs/log-format.md). When the
  latest pose is older than the frame by more than ``--max-pose-gap`` seconds (default
  0.05 s: a few Create sensor periods), the log has **no pose at that time**: the frame's
  observations are dropped and counted as ``no_pose_at_frame_time`` (frames older than the
  log's start as ``before_log_start``) — detect never invents motion. The file is rewritten
  atomically (a temporary file, then a rename); the header gains the front-end's settings
  under ``source.detect``.
- **Clocks**: ``--time-offset S`` adds S seconds to every frame's stamp (and its
  observations') to put the frames on the log's clock; ``--time-offset start`` puts the first
  frame at the log's start. When frames find no pose and their stamps do not even overlap the
  log's, the summary says so and prints the offset that would line them up.
- **Mode**: the rewritten log keeps its permission bits; a new one gets the umask's mode, as
  every fgslam output (``write_new_file``).
- **Once**: a log that already has observations is refused — detecting twice would add
  every observation twice. ``--replace`` removes every observation record (odometry, truth
  and all other records are kept) before the new ones go in; the header's earlier detect
  runs are kept, marked ``observations_removed``.
- **LOG does not exist**: only with ``--static`` (a camera that did not move): a new log
  with pose 0 at the first frame's stamp and no odometry, so every observation belongs to
  pose 0. ``--static`` with a log that exists is refused (it would not start a new log but
  attach to that log's odometry).

``--show DIR`` writes each frame with its detections, measurements and rejection reasons
drawn, as DIR/<frame>.png; DIR may not be the frame folder or inside it. At the end it prints
how many frames became observations and every rejection by name (corrupt image, over-exposed,
no landmark, missing depth, ...), with the first unreadable files, the sizes of frames that
differ from the camera file's, and the tag ids ``--tag-ids`` left out.

Errors after the frames were read, before anything is written (the --show frames of the run
are removed again): not one image could be read (the first files are named), no frame has the
camera file's image size (both sizes are named), or tags
were found but ``--tag-ids`` leaves out every one (the ids seen are named) — either would
only write a log without a single observation. Those checks, and what the summary names,
are in :mod:`fgslam.cli.detect_checks`.
"""

from __future__ import annotations

import argparse
import bisect
from dataclasses import replace
from functools import partial
from pathlib import Path

from fgslam.cli.common import add_verb, check_number, command_line, holds_outputs, probe_writable, write_new_file
from fgslam.cli.detect_checks import DetectError, FrameProblems, check_show, parse_tag_ids, summary_with_details
from fgslam.cli.progress import Progress
from fgslam.cli.verbs import help_of
from slamio.log import Header, Observation, Odometry, read_log, write_log
from slamio.log.mount import camera_mount_fields, pose_on_robot

DEFAULT_MAX_POSE_GAP_S = 0.05
#: Stamps closer than this are the same instant (frame files named by their stamp to the microsecond).
STAMP_RESOLUTION_S = 1e-6
# --------------------------------------------------------------------------- merging into a log


def _stamp(record) -> float | None:
    return getattr(record, "stamp_s", None)


def merge_observations(header: Header, records: list, frames: list[tuple[float, list[Observation]]],
                       max_pose_gap_s: float) -> tuple[list, dict[str, int]]:
    """Records with each frame's observations put into the pose current at its stamp.

    ``frames`` is [(stamp_s, observations)]. Returns the new record list and the count of
    frames dropped by reason (``no_pose_at_frame_time``, ``before_log_start``).
    """
    # segments: pose k = records from its odometry record (or the start) to the next one
    segments: list[list] = [[]]
    for record in records:
        if isinstance(record, Odometry):
            segments.append([])
        segments[-1].append(record)
    pose_stamps = [header.stamp_s] + [r.stamp_s for r in records if isinstance(r, Odometry)]
    dropped = {"no_pose_at_frame_time": 0, "before_log_start": 0}
    for stamp, observations in sorted(frames, key=lambda f: f[0]):
        if not observations:
            continue
        k = bisect.bisect_right(pose_stamps, stamp + STAMP_RESOLUTION_S) - 1
        if k < 0:
            dropped["before_log_start"] += 1
            continue
        if stamp < pose_stamps[k]:  # the same instant, written with fewer digits (a file name)
            stamp = pose_stamps[k]
            observations = [replace(o, stamp_s=stamp) for o in observations]
        if stamp - pose_stamps[k] > max_pose_gap_s:
            dropped["no_pose_at_frame_time"] += 1
            continue
        segment = segments[k]
        position = 0
        for i, record in enumerate(segment):
            s = _stamp(record)
            if s is not None and s <= stamp:
                position = i + 1
        segment[position:position] = observations
    merged = [r for segment in segments for r in segment]
    return merged, dropped


def static_header(first_stamp_s: float, kind: str, camera_name: str, noise: dict, command: str) -> Header:
    """Header of a new log for a camera that does not move (pose 0 only)."""
    return Header(
        stamp_s=first_stamp_s,
        start_pose=(0.0, 0.0, 0.0),
        start_sigma=(1e-3, 1e-3, 1e-3),
        robot={"name": "static camera (no odometry)"},
        sensor={"kind": "range-bearing", "landmark_kind": "apriltag" if kind == "apriltag" else "coloured-cylinder",
                "camera": camera_name},
        noise={"odometry": {"model": "none: a static camera, every observation belongs to pose 0"},
               "observation": noise},
        source={"generator": "fgslam detect --static", "command": command},
    )


def _write_log(path: Path, header: Header, records: list, *, new: bool) -> None:
    """Write the log through a temporary file and a rename (``write_new_file``): a new log gets
    the umask's mode, as every fgslam output; a rewritten one keeps its own permission bits."""
    write_new_file(path, lambda tmp: write_log(tmp, header, records), overwrite=not new)


def _time_offset(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise DetectError(f"--time-offset must be seconds (e.g. -1700000000.25) or 'start', got {text!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise DetectError(f"--time-offset must be a finite number of seconds, got {text!r}")
    return value


def _without_observations(existing, path: Path, replace_them: bool):
    """The log without its observations when ``--replace`` says so; a log that has some and no
    --replace is refused (detecting twice would add every observation twice)."""
    count = sum(isinstance(r, Observation) for r in existing.records) + len(existing.rejected)
    if not count:
        return existing, 0
    if not replace_them:
        runs = existing.header.source.get("detect")
        by = (f"{len(runs)} earlier fgslam detect run(s)" if isinstance(runs, list) and runs
              else "its recorder")
        raise DetectError(
            f"{path} already has {count} observations (from {by}); detecting again would add them twice. "
            "Pass --replace to remove every observation from it (odometry, truth and everything else is kept) "
            "and add the new ones, or give another log")
    kept = tuple(r for r in existing.records if not isinstance(r, Observation))
    return replace(existing, records=kept, rejected=()), count


def clock_hint(existing, raw_stamps: list[float], offset_s: float, dropped: dict[str, int], max_gap_s: float) -> str:
    """Why frames found no pose, and what to do: a clock offset, or odometry at each frame."""
    n = dropped.get("no_pose_at_frame_time", 0) + dropped.get("before_log_start", 0)
    if existing is not None and raw_stamps:
        stamps = [r.stamp_s for r in existing.records if _stamp(r) is not None] or [existing.header.stamp_s]
        log_lo, log_hi = min(existing.header.stamp_s, min(stamps)), max(stamps)
        lo, hi = min(raw_stamps) + offset_s, max(raw_stamps) + offset_s
        if hi < log_lo or lo > log_hi + max_gap_s:
            return (f"({n} frames found no pose: the frames' stamps {lo:.3f}..{hi:.3f} s do not overlap the log's "
                    f"{log_lo:.3f}..{log_hi:.3f} s, so the camera and the odometry are on different clocks; pass "
                    f"--time-offset SECONDS (added to each frame's stamp; {log_lo - min(raw_stamps):+.3f} puts the first "
                    "frame at the log's start) or --time-offset start)")
    return (f"({n} frames had no pose within {max_gap_s:g} s before them: record odometry at each camera frame "
            "(fgslam record --save-frames does), check the clocks (--time-offset), or raise --max-pose-gap if the "
            "robot was still)")


# --------------------------------------------------------------------------- the verb


def _check_options(args) -> None:
    """Every number option of ``detect``, before the camera file, the log or a frame is opened
    (a bad value is one line naming the option, never a crash in the detector: AprilTag with
    0 threads dies of a division by zero, a depth scale of 0 divides by zero)."""
    check = partial(check_number, error=DetectError)  # one line, as DetectError
    check("--threads", args.threads, at_least=1, what="AprilTag detector threads, e.g. 1 or 4")
    check("--tag-size", args.tag_size, above=0, what="metres: the side of the tag's black square, e.g. 0.16")
    check("--quad-decimate", args.quad_decimate, at_least=1,
          what="1 finds small tags, 2 is faster")
    check("--tag-upsample", args.tag_upsample, at_least=1,
          what="how many times AprilTag 3 enlarges the image; 1 = not enlarged")
    check("--max-pose-gap", args.max_pose_gap, above=0, what="seconds, e.g. 0.05")
    check("--min-range", args.min_range, at_least=0, what="metres")
    check("--max-range", args.max_range, above=0, what="metres")
    if args.max_range <= args.min_range:
        raise DetectError(f"--min-range and --max-range must satisfy 0 <= min < max (metres); "
                          f"got {args.min_range:g} and {args.max_range:g}")
    check("--fps", args.fps, above=0, what="frames per second of a plain image folder, e.g. 30")
    check("--depth-scale", args.depth_scale, above=0,
          what="depth PNG units per metre: TUM 5000, millimetre PNGs 1000")
    if args.max_frames is not None and args.max_frames < 1:
        raise DetectError(f"--max-frames must be >= 1 (leave it out to run until the source ends or Ctrl-C); "
                          f"got {args.max_frames}")
    if args.time_offset != "start":
        _time_offset(args.time_offset)
    parse_tag_ids(args.tag_ids, args.tag_family)


def _config_from_args(args):
    from slamio.camera.colour import ColourOptions
    from slamio.camera.detect import FrontEndConfig

    tag_ids = parse_tag_ids(args.tag_ids, args.tag_family)
    colour = ColourOptions(bearing_method=args.bearing, height_method=args.height)
    if args.landmarks:
        from slamio.camera.landmark_file import load_landmarks

        if args.kind != "colour":
            raise DetectError("--landmarks describes colour landmarks: add --kind colour")
        colour = load_landmarks(args.landmarks, base=colour)
    return FrontEndConfig(
        kind=args.kind, tag_family=args.tag_family, tag_size_m=args.tag_size, tag_ids=tag_ids,
        quad_decimate=args.quad_decimate, tag_upsample=args.tag_upsample, tag_second_pass=args.tag_second_pass,
        nthreads=args.threads, colour=colour,
        min_range_m=args.min_range, max_range_m=args.max_range,
    )


def landmark_settings(options) -> dict:
    """The colour landmarks and tolerances a detect run used, for the log's header."""
    from slamio.camera.landmark_file import options_to_dict

    return options_to_dict(options)


def _frames(args):
    from slamio.camera.sources import kinect_frames, open_frames, video_frames

    source = args.frames
    for prefix, live in (("kinect:", kinect_frames), ("camera:", video_frames)):
        if source.startswith(prefix):
            device = source[len(prefix):] or "0"
            if not device.isdigit():
                raise DetectError(f"{source!r}: the device after '{prefix}' is a number, e.g. {prefix}0")
            return live(int(device), max_frames=args.max_frames)
    _say_depth_left_out(source)
    return open_frames(source, fps=args.fps, depth_scale_per_m=args.depth_scale)


def _say_depth_left_out(source: str) -> None:
    """A plain image folder's depth images are not colour frames: say how many were left out."""
    from slamio.camera.sources import is_tum_folder, split_depth_images

    if not Path(source).is_dir() or is_tum_folder(source):
        return
    try:
        colour, depth = split_depth_images(source)
    except OSError:  # an unreadable folder is said by the frame source
        return
    if depth and colour:
        first, why = next(iter(depth.items()))
        print(f"fgslam: note: {len(depth)} depth images in {source} are not colour frames and are left out "
              f"(e.g. {first.name}: {why}); {len(colour)} colour frames")


def _remove(files: list[Path], folders: list[Path]) -> None:
    """Remove the annotated frames and the folders (deepest first) a failed run made."""
    for path in files:
        try:
            path.unlink(missing_ok=True)
        except OSError:
            pass
    for path in folders:
        try:
            path.rmdir()  # only when empty: what an earlier run left stays
        except OSError:
            pass


def _existing_log(out: Path, replace_observations: bool):
    """The recorded run log ``out`` (None for a new static log), without its earlier
    observations when they are replaced, and how many were removed."""
    existing = read_log(out) if out.exists() else None
    if existing is not None and existing.truncated:
        print(f"fgslam: warning: {existing.truncated}; the cut-off line is dropped when the log is rewritten")
    removed = 0
    if existing is not None:
        mount = pose_on_robot(existing.header.sensor)
        if mount is not None:
            raise DetectError(
                f"{out}'s header states sensor.pose_on_robot {list(mount)}: its readings are taken from there, but "
                "detect places each detection from the camera file's robot_mount (at the robot's centre). Remove "
                "the field from the header (and state the camera's mount in its camera file), or give another log")
        existing, removed = _without_observations(existing, out, replace_observations)
    return existing, removed


def _check_out(out: Path, static: bool) -> None:
    """``--out`` must be a recorded run log, or (``--static``) a new file."""
    if out.is_dir():
        raise DetectError(f"--out {out} is a folder; give the run log to add the observations to, e.g. {out / 'run.jsonl'}")
    if not out.exists() and not static:
        raise DetectError(
            f"{out} does not exist: detect adds observations to a recorded run log (header and odometry "
            "first); pass --static to start a new log for a camera that did not move"
        )
    if out.exists() and static:
        raise DetectError(
            f"--static starts a new log, but {out} already exists; leave out --static to add the observations to "
            "this recorded run (each frame joins the pose its odometry gives), or give --out a new file name "
            "(to redo a static log, remove it first)"
        )


def _make_show(show: Path, frames_source: str) -> list[Path]:
    """Check and create the ``--show`` folder; the folders it made (deepest first)."""
    made: list[Path] = []
    if show.exists() and not show.is_dir():
        raise DetectError(f"--show {show} is a file; give a folder for the annotated frames")
    check_show(show, frames_source)
    probe_writable(show, option="--show")
    folder = show
    while not folder.exists() and folder != folder.parent:
        made.append(folder)
        folder = folder.parent
    show.mkdir(parents=True, exist_ok=True)
    return made


def _annotate(show: Path, frame, result, camera, shown: list[Path]) -> None:
    """Write ``frame`` annotated with its detections into the ``--show`` folder (its path
    appended to ``shown``)."""
    import cv2

    from slamio.camera.detect import annotate

    name = Path(frame.name.replace("/", "_").replace(":", "_").replace("#", "_")).stem
    shown.append(show / f"{frame.index:06d}_{name}.png")  # before writing: a failed run removes it
    cv2.imwrite(str(shown[-1]), annotate(frame.bgr, result, camera))


def _run_settings(command: str, camera, config, front, stats, offset_s: float | None) -> dict:
    """What this detect run records in the log's ``source.detect``."""
    settings = {
        "command": command, "camera": camera.name, "kind": config.kind, "time_offset_s": offset_s,
        "frames": stats.frames, "observations": stats.observations,
        "rejected": dict(sorted(stats.reasons.items())),
        "noise": front.noise.describe(),
    }
    if config.kind == "apriltag":
        settings.update(tag_family=config.tag_family, tag_size_m=config.tag_size_m,
                        tag_upsample=config.tag_upsample, tag_second_pass=config.tag_second_pass)
    else:
        settings.update(bearing=config.colour.bearing_method, height=config.colour.height_method,
                        landmarks=landmark_settings(config.colour))
    return settings


@holds_outputs(out="--out", show="--show")
def cmd_detect(args: argparse.Namespace) -> int:
    from slamio.camera.detect import DetectionStats, FrontEnd
    from slamio.camera.model import load_camera

    _check_options(args)  # before anything is read, opened or written
    camera = load_camera(args.camera, args.camera_name)
    config = _config_from_args(args)
    front = FrontEnd(camera, config)
    out = Path(args.out)
    _check_out(out, args.static)
    probe_writable(out.parent, target=out)  # the log is rewritten at the end: check before the frames
    existing, removed = _existing_log(out, args.replace)
    show = Path(args.show) if args.show else None
    shown: list[Path] = []  # the annotated frames and the folders --show made: removed when the run fails
    made = [] if show is None else _make_show(show, args.frames)
    stats = DetectionStats()
    problems = FrameProblems(camera)
    frames: list[tuple[float, list[Observation]]] = []
    offset_s = None if args.time_offset == "start" else _time_offset(args.time_offset)
    raw_stamps: list[float] = []
    progress = Progress(unit="frames", status_at_once=False)
    try:
        try:
            for frame in _frames(args):
                result = front.process(frame)
                stats.add(result)
                problems.add(frame, result)
                progress.status(stats.frames, lambda: f"frames {stats.frames}, observations {stats.observations}")
                if offset_s is None:  # --time-offset start: the first frame is the log's start
                    offset_s = (existing.header.stamp_s if existing is not None else 0.0) - frame.stamp_s
                raw_stamps.append(frame.stamp_s)
                frames.append((frame.stamp_s + offset_s,
                               [replace(o, stamp_s=o.stamp_s + offset_s) for o in result.observations]))
                if show is not None:
                    _annotate(show, frame, result, camera, shown)
        except KeyboardInterrupt:  # a live source runs until stopped: keep what was seen
            progress.close()
            print(f"fgslam: interrupted after {stats.frames} frames; writing their observations")
        finally:
            progress.close()
        problem = (f"{args.frames}: no frames" if stats.frames == 0 else
                   problems.unreadable_error(args.frames) or problems.size_error(args.frames, args.camera)
                   or problems.tag_ids_error(args.tag_ids, config.tag_family, config.tag_ids))
        if problem:  # before anything is written: a log without any of the frames' landmarks helps no one
            raise DetectError(problem)
    except BaseException:
        _remove(shown, made)  # nothing of a failed run stays behind
        raise
    command = command_line(args, "detect")
    if existing is None:
        header = static_header(min(s for s, _ in frames), config.kind, camera.name, front.noise.describe(), command)
        records = [o for _, observations in sorted(frames, key=lambda f: f[0]) for o in observations]
        dropped: dict[str, int] = {}
    else:
        header = existing.header
        records, dropped = merge_observations(existing.header, list(existing.records), frames, args.max_pose_gap)
        for reason, count in dropped.items():
            if count:
                stats.reject(reason, count)
    settings = _run_settings(command, camera, config, front, stats, offset_s)
    earlier = header.source.get("detect")
    runs = list(earlier) if isinstance(earlier, list) else []
    if removed:
        runs = [{**run, "observations_removed": True} if isinstance(run, dict) else run for run in runs]
        settings["replaced_observations"] = removed
    sensor = {**(header.sensor if isinstance(header.sensor, dict) else {}), **camera_mount_fields(camera.T_robot_camera)}
    header = replace(header, sensor=sensor, source={**header.source, "detect": runs + [settings]})
    _write_log(out, header, records, new=existing is None)
    kept = sum(isinstance(r, Observation) for r in records) - (
        0 if existing is None else sum(isinstance(r, Observation) for r in existing.records))
    print(f"wrote {out}: {kept} observations added" + (f" ({removed} earlier ones removed)" if removed else ""))
    print(summary_with_details(stats, problems.details(args.camera, config.tag_ids)))
    if dropped.get("no_pose_at_frame_time") or dropped.get("before_log_start"):
        print("  " + clock_hint(existing, raw_stamps, offset_s, dropped, args.max_pose_gap))
    if show is not None:
        print(f"annotated frames in {show}/")
    return 0


def add_parser(verbs) -> argparse.ArgumentParser:
    """Add the ``detect`` verb to ``fgslam``'s sub-parsers; returns its parser."""
    from slamio.camera.sources import TUM_DEPTH_SCALE_PER_M

    detect = add_verb(
        verbs, "detect",
        help=help_of("detect"),
        description=(
            "Detect landmarks in camera frames and add them to a run log as observations in the robot\n"
            "frame (range, bearing, and tag yaw or cylinder height). FRAMES is a TUM RGB-D folder\n"
            "(rgb/, depth/, rgb.txt, depth.txt), a folder of images (stamps from numeric file names,\n"
            "else --fps), a video file, camera:N (a live cv2.VideoCapture device) or kinect:N (a live\n"
            "Kinect through the optional freenect package). CAM.yaml is a ROS camera_info file with an\n"
            "optional robot_mount (fgslam calibrate-camera writes one) or a Kalibr cameras.yaml.\n\n"
            "Observations go into the pose current at each frame's stamp (the last odometry record at or\n"
            "before it); a frame with no pose within --max-pose-gap is dropped and counted. Frames that\n"
            "cannot be used (corrupt, over-exposed, no landmark, no depth) are counted by reason, never\n"
            "fatal. See docs/camera.md."
        ),
        epilog=(
            "examples:\n"
            "  fgslam detect run/frames --camera kinect.yaml --kind colour --out run.jsonl --show run/shown\n"
            "  fgslam detect tags/ --camera webcam.yaml --tag-size 0.16 --out still.jsonl --static"
        ),
    )
    detect.add_argument("frames", metavar="FRAMES", help="frame folder, video file, camera:N or kinect:N")
    detect.add_argument("--camera", required=True, metavar="CAM.yaml", help="camera file: a ROS camera_info YAML (intrinsics, mount) "
                        "or a Kalibr cameras.yaml")
    detect.add_argument("--camera-name", default=None, metavar="NAME",
                        help="the camera of a Kalibr file holding several (cam0, cam1, ...)")
    detect.add_argument("--out", required=True, metavar="LOG", help="run log to add the observations to")
    detect.add_argument("--show", default=None, metavar="DIR", help="write annotated frames (PNG) to DIR (a folder outside FRAMES)")
    detect.add_argument("--kind", choices=("apriltag", "colour"), default="apriltag",
                        help="landmarks to look for (default apriltag)")
    detect.add_argument("--static", action="store_true",
                        help="LOG does not exist yet: start one for a camera that did not move (pose 0 only)")
    detect.add_argument("--replace", action="store_true",
                        help="LOG already has observations: remove them (odometry and truth are kept) and add the new "
                        "ones; without it such a log is refused, as detecting twice would add everything twice")
    detect.add_argument("--time-offset", default="0", metavar="S",
                        help="seconds added to every frame's stamp to put it on the log's clock (default 0); 'start': "
                        "the first frame is at the log's start (only if the camera and the robot started together)")
    detect.add_argument("--max-pose-gap", type=float, default=DEFAULT_MAX_POSE_GAP_S, metavar="S",
                        help=f"largest gap between a frame and the pose it joins (default {DEFAULT_MAX_POSE_GAP_S} s)")
    detect.add_argument("--tag-family", default="tag36h11", help="AprilTag family (default tag36h11)")
    detect.add_argument("--tag-size", type=float, default=0.16, metavar="M",
                        help="side of the tag's black square, metres (default 0.16)")
    detect.add_argument("--tag-ids", default=None, metavar="LIST",
                        help="only these ids (comma-separated, e.g. 0,3,7; within the family: tag36h11 0..586)")
    detect.add_argument("--quad-decimate", type=float, default=1.0,
                        help="AprilTag quad_decimate (default 1.0: finds small tags; 2.0 is faster)")
    detect.add_argument("--tag-upsample", type=float, default=1.75, metavar="F",
                        help="AprilTag 3 sees the image enlarged F times (default 1.75: finds 11-17 px and oblique "
                        "tags; 1 is a little faster and finds fewer, 2 finds a few more)")
    detect.add_argument("--tag-second-pass", choices=("aruco", "none"), default="aruco",
                        help="aruco (default): cv2.aruco adds tags AprilTag 3 missed; none: AprilTag 3 only")
    detect.add_argument("--threads", type=int, default=1, help="AprilTag detector threads (default 1)")
    detect.add_argument("--landmarks", default=None, metavar="FILE",
                        help="colour: the landmark file (YAML/JSON: colours, ids, shapes, sizes, check tolerances; "
                        "default seed 000's red/green/blue cylinders; fgslam tune-colours writes one)")
    detect.add_argument("--bearing", choices=("exact", "linear"), default="exact",
                        help="colour: bearing through the intrinsics (default) or seed 000's linear map")
    detect.add_argument("--height", choices=("pinhole", "gheight"), default="pinhole",
                        help="colour: exact pinhole height (default) or seed 002's gHeight")
    detect.add_argument("--min-range", type=float, default=0.1, metavar="M", help="drop nearer landmarks (default 0.1)")
    detect.add_argument("--max-range", type=float, default=8.0, metavar="M", help="drop farther landmarks (default 8)")
    detect.add_argument("--fps", type=float, default=30.0,
                        help="stamps of a plain image folder whose file names are not numbers (default 30)")
    detect.add_argument("--depth-scale", type=float, default=TUM_DEPTH_SCALE_PER_M, metavar="UNITS_PER_M",
                        help="depth PNG units per metre (TUM 5000, the default; millimetre PNGs 1000)")
    detect.add_argument("--max-frames", type=int, default=None, help="live sources: stop after N frames")
    detect.set_defaults(func=cmd_detect)
    return detect

