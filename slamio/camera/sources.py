"""Frame sources: where camera frames come from.

Every source yields :class:`Frame` objects: a time stamp, a BGR image (OpenCV's channel
order) and, for RGB-D sources, a registered depth image in metres (NaN = no reading). A file
that cannot be decoded does **not** raise: its frame carries ``error`` (or ``depth_error``)
and no image, so a run counts it (``corrupt_image``) and goes on. Problems with the source
itself (a missing folder, a malformed ``rgb.txt`` line, a camera that cannot be opened, the
``freenect`` package missing) raise :class:`FrameSourceError` saying how to fix them.

- :func:`tum_frames` — a TUM RGB-D folder: ``rgb/`` and ``depth/`` PNGs listed with their
  stamps in ``rgb.txt`` and ``depth.txt`` (``# comment`` lines; ``stamp path`` per line);
  depth is 16-bit with 5000 units per metre (0 = missing). Each colour image is paired with
  the depth image nearest in time, within ``max_dt_s`` (0.02 s, as TUM's ``associate.py``),
  each depth image used once. Without the two lists, the stamps come from the file names
  (TUM names files by their stamp).
- :func:`folder_frames` — a folder of plain images (png, jpg, bmp, pgm, ppm, tif), in name
  order; a file name that is a number (``1305031102.175304.png``) is its stamp in seconds,
  otherwise frame k is stamped ``start_s + k/fps``. Depth images lying among the colour
  frames are not frames (:func:`depth_image_reason`: a 16-bit single-channel image, as every
  Kinect-class dataset stores depth, or a file name with the word "depth" in it); they are
  left out and :func:`split_depth_images` says which. A folder called ``depth``, or one of
  depth images only, is refused, naming the colour folder beside it (``rgb/``, ``color/``).
- :func:`video_frames` — ``cv2.VideoCapture`` on a device number or a video file/URL; a
  device's frames are stamped with the wall clock, a file's with its position.
- :func:`kinect_frames` — a live Kinect v1 through libfreenect's Python binding
  (``freenect``, an optional extra imported only here): RGB plus DEPTH_REGISTERED depth
  in millimetres.
"""

from __future__ import annotations

import os
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from slamio.camera.kinect import depth_from_mm, depth_from_scaled
from slamio.errors import FgslamError, check_regular, content_lines
from slamio.log.fields import STAMP_S

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm", ".tif", ".tiff")
TUM_DEPTH_SCALE_PER_M = 5000.0


class FrameSourceError(FgslamError):
    """A frame source that cannot be used at all (as opposed to one bad frame)."""


@dataclass(frozen=True, eq=False)
class Frame:
    stamp_s: float
    index: int
    name: str  # file name (or "video:N", "kinect:N") for messages and --show
    bgr: np.ndarray | None  # (H, W, 3) uint8; None when the image could not be read
    depth_m: np.ndarray | None = None  # (H, W) float32 metres, NaN = missing
    error: str | None = None  # why bgr is None
    depth_error: str | None = None  # why a listed depth image is missing


# --------------------------------------------------------------------------- reading files


def read_image(path: str | os.PathLike[str]) -> tuple[np.ndarray | None, str | None]:
    """(BGR image, None) or (None, why it cannot be read). Grey images become 3-channel."""
    import cv2

    path = os.fspath(path)
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError as exc:
        return None, f"{path}: cannot read ({exc.strerror})"
    if data.size == 0:
        return None, f"{path}: empty file"
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if image is None:
        return None, f"{path}: not a decodable image (corrupt or truncated?)"
    if image.dtype != np.uint8:
        image = cv2.convertScaleAbs(image, alpha=255.0 / max(1.0, float(np.iinfo(image.dtype).max)))
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    elif image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    return image, None


def read_depth_png(path: str | os.PathLike[str], scale_per_m: float = TUM_DEPTH_SCALE_PER_M
                   ) -> tuple[np.ndarray | None, str | None]:
    """(depth in metres, None) or (None, why). The PNG must be 16-bit single-channel."""
    import cv2

    path = os.fspath(path)
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError as exc:
        return None, f"{path}: cannot read ({exc.strerror})"
    raw = cv2.imdecode(data, cv2.IMREAD_ANYDEPTH) if data.size else None
    if raw is None:
        return None, f"{path}: not a decodable depth image"
    if raw.ndim != 2 or raw.dtype != np.uint16:
        return None, f"{path}: depth must be a 16-bit single-channel PNG, got {raw.dtype} with shape {raw.shape}"
    return depth_from_scaled(raw, scale_per_m), None


def _stamp_from_name(path: Path) -> float | None:
    try:
        value = float(path.stem)
    except ValueError:
        return None
    return value if abs(value) <= STAMP_S else None  # a run log's stamps are within ±1e10 s


def _image_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


#: Folder names that hold the colour half of an RGB-D recording (TUM: rgb/; Open3D: color/).
COLOUR_FOLDERS = ("rgb", "color", "colour", "image", "images")


def _name_says_depth(name: str) -> bool:
    """The word "depth" in a file or folder name, between separators: ``depth``,
    ``SUN_depth.png``, ``frame-000000.depth.png``, ``0001-depth.png`` (not ``indepth.png``)."""
    return "depth" in re.split(r"[^a-z0-9]+", name.lower())


def depth_image_reason(path: str | os.PathLike[str]) -> str | None:
    """Why the image file ``path`` is a depth image rather than a colour frame, or None.

    Either sign is enough: the file name has the word "depth" in it, or the image is 16-bit
    single-channel — how depth is stored by TUM RGB-D (5000 per metre), Open3D, SUN RGB-D and
    7-Scenes (millimetres) and by ``fgslam record --save-frames``, while a colour camera
    writes 8-bit images. Only the header is read (Pillow), never the pixels; a file Pillow
    cannot read is left to the frame reader, which reports it as a corrupt frame."""
    path = Path(path)
    if _name_says_depth(path.stem):
        return "its name says depth"
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as image:
            mode = image.mode
    except (OSError, UnidentifiedImageError, ValueError):
        return None
    if mode.startswith("I;16") or mode == "I":  # 16- or 32-bit integer grey: depth, not a camera's colour
        return f"a 16-bit single-channel image (Pillow mode {mode})"
    return None


def split_depth_images(folder: str | os.PathLike[str]) -> tuple[list[Path], dict[Path, str]]:
    """The image files of ``folder`` in name order, split into colour frames and depth
    images (each with :func:`depth_image_reason`)."""
    colour, depth = [], {}
    for path in _image_files(Path(folder)):
        reason = depth_image_reason(path)
        if reason is None:
            colour.append(path)
        else:
            depth[path] = reason
    return colour, depth


def _tum_listing(root: Path, name: str) -> list[tuple[float, str]] | None:
    """A TUM folder's ``NAME.txt`` list, else the stamp-named images of its ``NAME/`` folder,
    as (stamp, path relative to ``root``); None when it has neither."""
    if (root / f"{name}.txt").is_file():
        return read_stamp_list(root / f"{name}.txt")
    if (root / name).is_dir():
        return [(s, f"{name}/{p.name}") for p in _image_files(root / name) if (s := _stamp_from_name(p)) is not None]
    return None


def read_stamp_list(path: Path) -> list[tuple[float, str]]:
    """A TUM ``rgb.txt``/``depth.txt``: (stamp, relative path) per line; ``#`` comments."""
    out = []
    for number, text in content_lines(path):
        parts = text.split()
        try:
            stamp = float(parts[0])
            if len(parts) < 2 or not abs(stamp) <= STAMP_S:  # finite, and a run log's stamp
                raise ValueError
        except ValueError:
            raise FrameSourceError(
                f"{path}:{number}: expected 'STAMP_S PATH' (e.g. '1305031102.175304 rgb/1305031102.175304.png'), "
                f"got {text!r}"
            ) from None
        out.append((stamp, parts[1]))
    return out


def associate(first: list[float], second: list[float], max_dt_s: float = 0.02) -> dict[int, int]:
    """Pair stamps of two lists one-to-one, nearest first, within ``max_dt_s``: {i: j}."""
    a = np.asarray(first, dtype=float)
    b = np.asarray(second, dtype=float)
    if len(a) == 0 or len(b) == 0:
        return {}
    order = np.argsort(b)
    b_sorted = b[order]
    candidates = []
    for i, t in enumerate(a):  # the nearest few in the other list are enough
        k = int(np.searchsorted(b_sorted, t))
        for kk in range(max(0, k - 2), min(len(b), k + 3)):
            dt = abs(b_sorted[kk] - t)
            if dt <= max_dt_s:
                candidates.append((dt, i, int(order[kk])))
    candidates.sort()
    pairs, used_a, used_b = {}, set(), set()
    for _, i, j in candidates:
        if i not in used_a and j not in used_b:
            pairs[i] = j
            used_a.add(i)
            used_b.add(j)
    return pairs


# --------------------------------------------------------------------------- sources


def is_tum_folder(folder: str | os.PathLike[str]) -> bool:
    f = Path(folder)
    return (f / "rgb.txt").is_file() or ((f / "rgb").is_dir() and (f / "depth").is_dir())


def tum_frames(folder: str | os.PathLike[str], *, max_dt_s: float = 0.02,
               depth_scale_per_m: float = TUM_DEPTH_SCALE_PER_M) -> Iterator[Frame]:
    """Frames of a TUM RGB-D folder (see the module doc), in time order."""
    root = Path(folder)
    if not root.is_dir():
        raise FrameSourceError(f"{root}: no such folder")
    rgb = _tum_listing(root, "rgb")
    if rgb is None:
        raise FrameSourceError(f"{root}: not a TUM RGB-D folder (no rgb.txt and no rgb/ folder)")
    depth = _tum_listing(root, "depth") or []
    rgb.sort(key=lambda x: x[0])
    pairs = associate([s for s, _ in rgb], [s for s, _ in depth], max_dt_s)
    for index, (stamp, rel) in enumerate(rgb):
        bgr, error = read_image(root / rel)
        depth_m, depth_error = None, None
        if index in pairs:
            depth_m, depth_error = read_depth_png(root / depth[pairs[index]][1], depth_scale_per_m)
        yield Frame(stamp, index, rel, bgr, depth_m, error, depth_error)


def folder_frames(folder: str | os.PathLike[str], *, fps: float = 30.0, start_s: float = 0.0) -> Iterator[Frame]:
    """Frames of a folder of plain images (see the module doc)."""
    root = Path(folder)
    if not root.is_dir():
        raise FrameSourceError(f"{root}: no such folder")
    _refuse_a_depth_folder(root)
    files, depth = split_depth_images(root)
    if not files:
        _refuse_no_colour(root, depth)
    stamps = [_stamp_from_name(p) for p in files]
    if all(s is not None for s in stamps):
        order = sorted(range(len(files)), key=lambda i: stamps[i])
        files, stamps = [files[i] for i in order], [stamps[i] for i in order]
    else:
        if fps <= 0:
            raise FrameSourceError("fps must be > 0")
        stamps = [start_s + k / fps for k in range(len(files))]
    for index, (path, stamp) in enumerate(zip(files, stamps)):
        bgr, error = read_image(path)
        yield Frame(float(stamp), index, path.name, bgr, None, error)


def _colour_folder_beside(folder: Path) -> Path | None:
    return next((folder / n for n in COLOUR_FOLDERS if (folder / n).is_dir()), None)


def _give_the_colour_folder(root: Path) -> str:
    beside = _colour_folder_beside(root.resolve().parent)
    return f"give {beside}" if beside is not None else "give the folder of the colour frames"


def _refuse_a_depth_folder(root: Path) -> None:
    """A folder called ``depth`` (TUM RGB-D's, Open3D's) holds the depth half of a recording."""
    if root.resolve().name.lower() == "depth":
        raise FrameSourceError(f"{root}: a folder of depth images, not colour frames: {_give_the_colour_folder(root)} "
                               "(a TUM RGB-D folder, rgb/ and depth/ with rgb.txt and depth.txt, pairs colour with depth)")


def _refuse_no_colour(root: Path, depth: dict[Path, str]) -> None:
    """The error for a folder without colour frames, saying what it does hold."""
    if depth:
        first, why = next(iter(depth.items()))
        raise FrameSourceError(f"{root}: no colour images, only {len(depth)} depth images ({first.name}: {why}); "
                               f"{_give_the_colour_folder(root)}")
    folders = sorted(p.name + "/" for p in root.iterdir() if p.is_dir())
    hint = ""
    if folders:
        beside = _colour_folder_beside(root)
        hint = (f"; it holds the folders {', '.join(folders[:5])}: give the folder of the images"
                + (f" ({beside} for the colour frames)" if beside is not None else "")
                + ", or lay out an RGB-D recording as TUM RGB-D does (rgb/ and depth/ with rgb.txt and depth.txt)")
    raise FrameSourceError(f"{root}: no images ({', '.join(IMAGE_SUFFIXES)}) in this folder{hint}")


def open_frames(path: str | os.PathLike[str], *, fps: float = 30.0,
                depth_scale_per_m: float = TUM_DEPTH_SCALE_PER_M) -> Iterator[Frame]:
    """A TUM RGB-D folder, a plain image folder, or a video file, whichever ``path`` is."""
    p = Path(path)
    if p.is_dir():
        return tum_frames(p, depth_scale_per_m=depth_scale_per_m) if is_tum_folder(p) else folder_frames(p, fps=fps)
    if p.is_file():
        return video_frames(str(p))
    if os.path.lexists(p):  # a FIFO, a device or a loop of links: said, never opened
        check_regular(p, "frame source (a folder of images or a video file)")
    raise FrameSourceError(f"{p}: no such folder or video file")


def video_frames(source: int | str, *, max_frames: int | None = None, clock=time.time) -> Iterator[Frame]:
    """Frames from ``cv2.VideoCapture`` (a device number, a video file or a stream URL)."""
    import cv2

    capture = cv2.VideoCapture(source)
    if not capture.isOpened():
        raise FrameSourceError(
            f"cannot open video source {source!r} (a device number such as 0, a video file, or a URL)"
        )
    live = isinstance(source, int)
    name = f"video:{source}" if live else Path(str(source)).name
    try:
        index = 0
        while max_frames is None or index < max_frames:
            ok, bgr = capture.read()
            if not ok or bgr is None:
                break
            stamp = clock() if live else capture.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
            yield Frame(float(stamp), index, f"{name}#{index}", bgr)
            index += 1
    finally:
        capture.release()


FREENECT_MISSING = (
    "live Kinect frames need the optional 'freenect' package (the Python binding of libfreenect): "
    "install libfreenect and its Python wrapper (github.com/OpenKinect/libfreenect, "
    "wrappers/python; some distributions package it as python3-freenect), then run again; "
    "or record a TUM RGB-D style folder and pass that instead"
)


def kinect_frames(device: int = 0, *, max_frames: int | None = None, clock=time.time) -> Iterator[Frame]:
    """Live Kinect v1 frames: RGB and registered depth (mm → metres) through ``freenect``."""
    try:
        import freenect  # optional extra; imported only when a live Kinect is asked for
    except ImportError:
        raise FrameSourceError(FREENECT_MISSING) from None
    import cv2

    index = 0
    try:
        while max_frames is None or index < max_frames:
            video = freenect.sync_get_video(device, freenect.VIDEO_RGB)
            depth = freenect.sync_get_depth(device, freenect.DEPTH_REGISTERED)
            if video is None or depth is None:
                if index == 0:
                    raise FrameSourceError(f"no Kinect answers on device {device} (plugged in? powered?)")
                break
            stamp = clock()
            bgr = cv2.cvtColor(np.ascontiguousarray(video[0]), cv2.COLOR_RGB2BGR)
            yield Frame(float(stamp), index, f"kinect:{device}#{index}", bgr, depth_from_mm(depth[0]))
            index += 1
    finally:
        freenect.sync_stop()
