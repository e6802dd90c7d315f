"""Tags that any detector finds in a photo: a listing to score a detector's recall against.

A listing made by one detector cannot show what that detector misses. The union of what
several detector set-ups find in the same photos can: ``scripts/apriltag_union.py`` builds it
for the NASA photos of ``tests/data/apriltag-photos`` and writes ``nasa_union.txt`` there,
one tag per line::

    image, id, centre x, centre y, side px, found by (space-separated set-up names)

Centres are in OpenCV's pixel convention (the top-left pixel's centre at 0, 0). Detections
are the same tag when their ids agree and their centres are within
``max(3 px, 0.3 × side)`` of each other — corners are not compared, since detectors order
them differently and disagree on them by pixels on blurred or oblique tags.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np


#: "found by" names that are not detector set-ups: the photos' own listing, and tags seen by eye.
NOT_SETUPS = ("reference", "seen-by-eye")


@dataclass
class ListedTag:
    """One tag in a union listing."""

    image: str
    tag_id: int
    centre_px: np.ndarray  # (2,), OpenCV pixel convention
    side_px: float
    found_by: list[str] = field(default_factory=list)


def found_by_a_setup(tag: ListedTag) -> bool:
    """True for the tags recall is counted over: found by at least one detector set-up."""
    return any(name not in NOT_SETUPS for name in tag.found_by)


def same_tag(tag: ListedTag, tag_id: int, centre_px: np.ndarray) -> bool:
    """True when a detection (id, centre) is ``tag``: same id, centres within max(3 px, 0.3 × side)."""
    distance = float(np.linalg.norm(np.asarray(centre_px, dtype=float) - tag.centre_px))
    return tag_id == tag.tag_id and distance <= max(3.0, 0.3 * tag.side_px)


def add_detections(union: list[ListedTag], image: str, detections, found_by: str) -> None:
    """Merge one set-up's detections of ``image`` — (id, centre, side) triples — into ``union``."""
    for tag_id, centre, side in detections:
        centre = np.asarray(centre, dtype=float)
        for tag in union:
            if tag.image == image and same_tag(tag, tag_id, centre):
                if found_by not in tag.found_by:
                    tag.found_by.append(found_by)
                break
        else:
            union.append(ListedTag(image, int(tag_id), centre, float(side), [found_by]))


def write_union(path: str | os.PathLike[str], union: list[ListedTag], header: str) -> None:
    """Write a listing; ``header`` lines become ``#`` comments."""
    with open(path, "w", encoding="utf-8") as f:
        for line in header.strip().splitlines():
            f.write(f"# {line}".rstrip() + "\n")
        f.write("# image, id, centre x, centre y, side px, found by\n")
        for t in sorted(union, key=lambda t: (t.image, t.centre_px[0], t.centre_px[1])):
            f.write(f"{t.image}, {t.tag_id}, {t.centre_px[0]:.2f}, {t.centre_px[1]:.2f}, {t.side_px:.1f}, "
                    f"{' '.join(t.found_by)}\n")


def listing_lines(path: str | os.PathLike[str]):
    """(line number, stripped text) of every line of a listing that is neither blank nor a ``#`` comment."""
    with open(path, encoding="utf-8") as f:
        for number, line in enumerate(f, start=1):
            text = line.strip()
            if text and not text.startswith("#"):
                yield number, text


def read_union(path: str | os.PathLike[str]) -> list[ListedTag]:
    """Read a listing written by :func:`write_union`; a malformed line is a ValueError naming it."""
    out = []
    for number, text in listing_lines(path):
        parts = [p.strip() for p in text.split(",")]
        try:
            if len(parts) != 6:
                raise ValueError
            image, tag_id, x, y, side, found_by = parts
            out.append(ListedTag(image, int(tag_id), np.array([float(x), float(y)]), float(side), found_by.split()))
        except ValueError:
            raise ValueError(f"{path}:{number}: expected 'image, id, x, y, side, found by', got {text!r}") from None
    return out


@dataclass
class UnionScore:
    """A detector scored against a union listing (recall counted over the ``counted`` tags only)."""

    counted: int = 0  # listed tags that count for recall
    found: int = 0  # of those, found
    found_other: int = 0  # listed tags outside the counted ones, found
    not_listed: list = field(default_factory=list)  # (image, id, centre): matches no listed tag
    duplicates: list = field(default_factory=list)  # (image, id, centre): a second detection of one tag
    missed: list = field(default_factory=list)  # (image, id, centre) of counted tags not found


def score_against_union(detections: dict[str, list], union: list[ListedTag], counted=lambda tag: True) -> UnionScore:
    """Score detections — per image, (id, centre) pairs — against ``union``.

    ``counted(tag)`` says which listed tags recall is counted over (the others may be found
    without counting as false detections). A detection matching no listed tag of its image
    is ``not_listed``: a false detection, or a real tag no set-up of the listing found — look.
    """
    score = UnionScore(counted=sum(1 for t in union if counted(t) and t.image in detections))
    for image, found in detections.items():
        tags = [t for t in union if t.image == image]
        hit: set[int] = set()
        for tag_id, centre in found:
            centre = np.asarray(centre, dtype=float)
            k = next((k for k, t in enumerate(tags) if same_tag(t, tag_id, centre)), None)
            if k is None:
                score.not_listed.append((image, tag_id, centre))
            elif k in hit:
                score.duplicates.append((image, tag_id, centre))
            else:
                hit.add(k)
        for k, t in enumerate(tags):
            if k in hit:
                score.found += counted(t)
                score.found_other += not counted(t)
            elif counted(t):
                score.missed.append((image, t.tag_id, t.centre_px))
    return score
