"""What the 2-D filters answer alike: :class:`FilterOutputs`, a mixin.

A filter's estimate is final as soon as a step is consumed, so ``finish()`` has nothing to
do and the trajectory is the pose right after each step (online = final). The filter keeps
those poses in ``self._trajectory`` and, for :meth:`FilterOutputs.current_pose`, the robot
pose first in ``self._mean`` (a filter that keeps it elsewhere defines its own).
"""

from __future__ import annotations

import numpy as np

from ekf.models import ROBOT_DIM


class FilterOutputs:
    """``current_pose``, ``finish`` and ``trajectory`` of a 2-D filter (see the module docstring)."""

    def current_pose(self) -> tuple[float, float, float]:
        """The current robot pose estimate ``(x_m, y_m, theta_rad)``."""
        x, y, th = self._mean[:ROBOT_DIM]
        return float(x), float(y), float(th)

    def finish(self) -> None:
        """Nothing to do: a filter's estimate is final as soon as a step is consumed."""

    def trajectory(self) -> np.ndarray:
        """(n, 3) array: the pose estimate right after each step (for a filter, online = final)."""
        return np.array(self._trajectory, dtype=float).reshape(-1, ROBOT_DIM)
