"""The navigators of issue 44: policies that steer the robot from its scans, so it finds its
own way (``fgslam live --navigate NAME``), and a kinematic harness to test them.

* ``vfh-s000`` — seed 000's widest-gap follower, as written (:mod:`.vfh_s000`);
* ``vfh`` — Borenstein and Koren's Vector Field Histogram with VFH+ refinements (:mod:`.vfh`);
* ``explore-s001`` — seed 001's scan / approach-nearest / turn-45° loop, as written
  (:mod:`.explore_s001`);
* ``explore`` — frontier exploration on an occupancy grid that also revisits the mapped
  landmarks for loop closures, steering with ``vfh`` (:mod:`.explore`).

Every navigator has ``name`` and ``step(Situation) -> Command`` (:mod:`.common`);
:func:`make_navigator` builds one by name.
"""

from __future__ import annotations

from fgslam.navigate.common import Command, Navigator, Situation
from fgslam.navigate.explore import Explore
from fgslam.navigate.explore_s001 import ExploreS001
from fgslam.navigate.vfh import Vfh
from fgslam.navigate.vfh_s000 import VfhS000
from slamio.errors import FgslamError

__all__ = ["NAVIGATORS", "make_navigator", "Situation", "Command", "Navigator"]

NAVIGATORS = {"vfh-s000": VfhS000, "vfh": Vfh, "explore-s001": ExploreS001, "explore": Explore}


def make_navigator(name: str, *, seed: int = 0, **options) -> Navigator:
    """A new navigator called ``name`` (a key of :data:`NAVIGATORS`), its randomness seeded
    from ``seed``; ``options`` go to its constructor (e.g. ``goal_xy`` for ``vfh``)."""
    if name not in NAVIGATORS:
        raise FgslamError(f"--navigate: no navigator called {name!r}; choose one of {', '.join(NAVIGATORS)}")
    try:
        return NAVIGATORS[name](seed=seed, **options)
    except TypeError as error:
        raise FgslamError(f"--navigate {name}: {error}") from None
