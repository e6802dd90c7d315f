"""Camera frames saved while ``fgslam record`` drives: one frame per odometry record, on the odometry's clock.

``fgslam detect`` puts a frame's observations into the pose current at the frame's stamp and
drops frames that have no pose close enough before them. A camera on its own clock, or
odometry recorded at another rate, loses frames that way. :class:`FrameSaver` rides on the
recorder (its ``hooks``, :class:`slamio.create.record.RecordHooks`): each time the recorder
writes an odometry record it takes the newest camera frame and saves it **stamped with that
record's stamp**, so every saved frame has a pose at exactly its time, and
``fgslam detect FOLDER --out LOG`` attaches every one of them.

The folder is a TUM RGB-D folder (:func:`slamio.camera.sources.tum_frames` reads it):
``rgb/<stamp>.png``, ``depth/<stamp>.png`` (16-bit, 5000 per metre, 0 = missing) when the
camera gives depth, and ``rgb.txt`` / ``depth.txt`` listing them, written as the run goes
(each line flushed). Encoding PNGs takes longer than the control loop may wait, so frames go
to a writer thread through a short queue; when the writer falls behind a frame is skipped
(counted), never the control loop held up.
"""

from __future__ import annotations

import queue
import threading
from pathlib import Path
from typing import Callable

import numpy as np

from slamio.errors import FgslamError

TUM_DEPTH_SCALE_PER_M = 5000.0


class FrameSaver:
    """Record hooks that write an odometry record every ``record_period_s`` and save a frame
    for each (see the module doc). ``grab_for(index, odometry)`` is called in the control loop
    and must be quick (snapshot the newest frame or the true pose); the function it returns is
    called in the writer thread and returns a :class:`slamio.camera.sources.Frame`."""

    def __init__(self, folder: str | Path, grab_for: Callable, record_period_s: float = 0.1, queue_size: int = 8):
        self.folder = Path(folder)
        self.grab_for = grab_for
        self.record_period_s = record_period_s
        (self.folder / "rgb").mkdir(parents=True, exist_ok=True)
        (self.folder / "depth").mkdir(exist_ok=True)
        self._rgb_list = open(self.folder / "rgb.txt", "w", encoding="utf-8")
        self._depth_list = open(self.folder / "depth.txt", "w", encoding="utf-8")
        for f in (self._rgb_list, self._depth_list):
            f.write("# timestamp filename (seconds on the run log's clock: fgslam record --save-frames)\n")
            f.flush()
        self._queue: queue.Queue = queue.Queue(maxsize=queue_size)
        self._last_record_s = 0.0
        self._index = 0
        self.saved = self.skipped = self.missing = 0
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="fgslam-frame-saver", daemon=True)
        self._thread.start()

    # -- the recorder's hooks (control loop thread)

    def due(self, now_s: float) -> bool:
        if self.error is not None:
            raise FgslamError(f"saving camera frames: {type(self.error).__name__}: {self.error}") from self.error
        return now_s - self._last_record_s >= self.record_period_s

    def after_record(self, record, log) -> None:
        self._last_record_s = record.stamp_s
        self._index += 1
        try:
            self._queue.put_nowait((record.stamp_s, self.grab_for(self._index, record)))
        except queue.Full:
            self.skipped += 1

    # -- the writer thread

    def _run(self) -> None:
        import cv2

        while True:
            item = self._queue.get()
            if item is None:
                return
            stamp, grab = item
            try:
                frame = grab()
                if frame.bgr is None:
                    self.missing += 1
                    continue
                name = f"{stamp:.6f}.png"
                if not cv2.imwrite(str(self.folder / "rgb" / name), frame.bgr):
                    raise OSError(f"cannot write {self.folder / 'rgb' / name}")
                self._rgb_list.write(f"{stamp:.6f} rgb/{name}\n")
                self._rgb_list.flush()
                if frame.depth_m is not None:
                    depth = np.nan_to_num(np.asarray(frame.depth_m) * TUM_DEPTH_SCALE_PER_M, nan=0.0)
                    cv2.imwrite(str(self.folder / "depth" / name), np.clip(np.round(depth), 0, 65535).astype(np.uint16))
                    self._depth_list.write(f"{stamp:.6f} depth/{name}\n")
                    self._depth_list.flush()
                self.saved += 1
            except BaseException as exc:  # raised in the control loop by due()
                self.error = exc
                return

    def close(self) -> None:
        """After the recorder returned: save what is queued, then close the lists."""
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        self._rgb_list.close()
        self._depth_list.close()
