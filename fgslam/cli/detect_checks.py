"""``fgslam detect``'s checks of what the user gave and found: ``--tag-ids`` against the tag
family, ``--show`` outside the frames, and :class:`FrameProblems`, what the summary and the
errors name beyond the counts (the first unreadable files, frame sizes that do not fit the
camera file, the tag ids seen)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from slamio.errors import FgslamError

#: How many ids each AprilTag family has (the AprilTag 3 library's ``ncodes``; OpenCV's aruco
#: dictionaries of the four it knows, ``slamio.camera.apriltag.ARUCO_DICTIONARIES``, agree).
TAG_FAMILY_IDS = {
    "tag16h5": 30, "tag25h9": 35, "tag36h10": 2320, "tag36h11": 587, "tagCircle21h7": 38,
    "tagCircle49h12": 65535, "tagCustom48h12": 42211, "tagStandard41h12": 2115, "tagStandard52h13": 48714,
}
#: Unreadable files (corrupt_image, corrupt_depth) the summary names, the first ones.
NAMED_FILES = 3


class DetectError(FgslamError):
    """A user error of ``fgslam detect`` (bad option, missing file)."""


def parse_tag_ids(text: str | None, family: str) -> frozenset[int] | None:
    """The ids of ``--tag-ids`` (None: every id). Each item is a whole number inside the
    family's range (tag36h11: 0..586); an empty item, a negative or too large id is an error."""
    if text is None:
        return None
    example = "e.g. --tag-ids 0,3,7"
    items = [x.strip() for x in text.split(",")]
    if any(not x for x in items):
        raise DetectError(f"--tag-ids {text!r} has an empty item; give the tag ids separated by single commas, "
                          f"{example} (leave --tag-ids out to keep every id)")
    ids = []
    for item in items:
        try:
            ids.append(int(item))
        except ValueError:
            raise DetectError(f"--tag-ids must be whole numbers separated by commas, {example}; "
                              f"{item!r} in {text!r} is not") from None
    negative = [i for i in ids if i < 0]
    if negative:
        raise DetectError(f"--tag-ids: a tag id is 0 or more; got {', '.join(map(str, negative))} in {text!r}")
    count = TAG_FAMILY_IDS.get(family)
    too_large = [i for i in ids if count is not None and i >= count]
    if too_large:
        raise DetectError(f"--tag-ids: {family} has {count} tags, ids 0..{count - 1}; "
                          f"{', '.join(map(str, too_large))} is not one of them (check the ids, or give your tags' "
                          "family with --tag-family)")
    return frozenset(ids)


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def _why(name: str, detail: str) -> str:
    """A frame's error without the file's path in front (the summary names the frame)."""
    at = detail.find(f"{name}: ")
    return detail[at + len(name) + 2:] if at >= 0 else detail


def _ids(ids) -> str:
    ids = sorted(ids)
    shown = ", ".join(map(str, ids[:20]))
    return shown + (f" and {len(ids) - 20} more" if len(ids) > 20 else "")


class FrameProblems:
    """What the summary and the errors name beyond the counts: the first unreadable files, the
    sizes of frames that do not fit the camera file, and the tag ids seen."""

    def __init__(self, camera):
        self.camera_size = (camera.width_px, camera.height_px)
        self.unreadable: dict[str, list[tuple[str, str]]] = {"corrupt_image": [], "corrupt_depth": []}
        self.sizes: Counter = Counter()  # ("image" or "depth", width, height) -> frames
        self.first_of_size: dict[tuple, str] = {}
        self.right_size = 0  # frames whose image has the camera file's size
        self.frames = self.readable = 0  # frames in all, and those whose image could be read
        self.tag_ids: set[int] = set()  # every id decoded, allowed or not

    def add(self, frame, result) -> None:
        self.frames += 1
        self.readable += frame.bgr is not None
        wrong_size = False
        for r in result.rejections:
            if r.reason in self.unreadable and len(self.unreadable[r.reason]) < NAMED_FILES:
                self.unreadable[r.reason].append((r.what, _why(r.what, r.detail)))
            wrong_size |= r.reason == "wrong_image_size"
        if wrong_size:
            h, w = frame.bgr.shape[:2]
            if (w, h) == self.camera_size and frame.depth_m is not None:  # the depth image's size differs
                h, w = frame.depth_m.shape[:2]
                key = ("depth", w, h)
            else:
                key = ("image", w, h)
            self.sizes[key] += 1
            self.first_of_size.setdefault(key, frame.name)
        elif frame.bgr is not None:
            self.right_size += 1
        self.tag_ids.update(tag.detection.tag_id for tag in result.tags)

    def _sizes(self) -> str:
        return ", ".join(f"{'depth images' if kind == 'depth' else 'images'} {w}×{h} "
                         f"({_plural(n, 'frame')}, first {self.first_of_size[(kind, w, h)]})"
                         for (kind, w, h), n in self.sizes.most_common())

    def details(self, camera_path: str, allowed: frozenset[int] | None) -> dict[str, str]:
        """A line for the summary under each rejection whose files, sizes or ids are worth naming."""
        out = {}
        for reason, first in self.unreadable.items():
            if first:
                out[reason] = "first: " + "; ".join(f"{name} ({why})" if why else name for name, why in first)
        if self.sizes:
            w, h = self.camera_size
            out["wrong_image_size"] = f"{self._sizes()}; {camera_path} is for {w}×{h} images"
        if allowed is not None and self.tag_ids - allowed:
            out["tag_not_allowed"] = "ids seen that --tag-ids leaves out: " + _ids(self.tag_ids - allowed)
        return out

    def size_error(self, frames: str, camera_path: str) -> str | None:
        """The error when frames were read but none has the camera file's size (None otherwise)."""
        if not self.sizes or self.right_size:
            return None
        w, h = self.camera_size
        depth = any(kind == "depth" for kind, _, _ in self.sizes)
        return (f"{frames}: no frame has the camera file's image size: {self._sizes()}, but {camera_path} "
                f"is for {w}×{h} images (its image_width × image_height); use the camera file calibrated for these "
                "images (intrinsics hold for one image size only)"
                + ("; colour landmarks need depth images registered to the colour images, at their size"
                   if depth else "")
                + "; nothing was written")

    def unreadable_error(self, frames: str) -> str | None:
        """The error when frames were found but not one image could be read (None otherwise)."""
        if not self.frames or self.readable:
            return None
        first = self.unreadable["corrupt_image"]
        named = "; ".join(f"{name} ({why})" if why else name for name, why in first)
        return (f"{frames}: none of the {_plural(self.frames, 'image')} could be read"
                + (f" (first: {named})" if named else "")
                + "; check that the files are whole images (PNG, JPEG, ...) and that rgb.txt names files that "
                  "exist; nothing was written")

    def tag_ids_error(self, text: str | None, family: str, allowed: frozenset[int] | None) -> str | None:
        """The error when tags were found but --tag-ids leaves out every one (None otherwise)."""
        if allowed is None or not self.tag_ids or self.tag_ids & allowed:
            return None
        seen = sorted(self.tag_ids)
        hint = f" (--tag-ids {','.join(map(str, seen))})" if len(seen) <= 12 else ""
        return (f"--tag-ids {text}: none of the tags found is one of these ids; the frames show {family} "
                f"{'id' if len(seen) == 1 else 'ids'} {_ids(seen)}; give the ids of your landmarks{hint}, "
                "or leave --tag-ids out to keep every id; nothing was written")


def summary_with_details(stats, details: dict[str, str]) -> str:
    """The front-end's summary with the files, sizes or ids of a rejection under its line."""
    lines = []
    for line in stats.summary().splitlines():
        lines.append(line)
        if line.lstrip().startswith("rejected"):
            reason = line.split("× ", 1)[-1].split(":", 1)[0]
            if reason in details:
                lines.append(" " * 20 + details[reason])
    return "\n".join(lines)


def check_show(show: Path, frames: str) -> None:
    """--show must not be the frame folder or inside it: the annotated PNGs would sit among the
    frames, and the next detect would read them as frames."""
    source = Path(frames)
    if not source.is_dir():
        return
    folder, shown = source.resolve(), show.resolve()
    if shown == folder or folder in shown.parents:
        where = "the frame folder" if shown == folder else f"inside the frame folder {source}"
        raise DetectError(
            f"--show {show} is {where}: the annotated PNGs would be mixed with the recorded frames, and a later "
            "detect could read them as frames; give a folder outside it, "
            f"e.g. --show {source.parent / (folder.name + '_shown')}")
