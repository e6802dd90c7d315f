"""slamio.create: the iRobot Create (1 and 2) over its Open Interface.

Modules, from the wire up:

* :mod:`slamio.create.protocol`  — pure codec: commands → bytes, bytes → sensor values,
  and a stream-frame parser that survives damaged bytes;
* :mod:`slamio.create.link`      — the serial port (pyserial ``serial_for_url``) with
  timeouts, reconnect, and an exit that always stops the wheels;
* :mod:`slamio.create.odometry`  — readings → run-log odometry records (Create 2 encoder
  counts; Create 1 distance/angle with the 1° truncation workaround);
* :mod:`slamio.create.safety`    — when to stop (bump, wheel drop, watchdog, Ctrl-C,
  serial error) and why;
* :mod:`slamio.create.sim`       — a simulated Create on a pseudo-terminal, with ground truth
  and fault injection;
* :mod:`slamio.create.record`    — the recorder behind ``fgslam record``;
  :mod:`slamio.create.controllers` (scripted paths, teleop), :mod:`slamio.create.readers`
  (stream and poll readers) and :mod:`slamio.create.record_settings` (settings, header,
  result) are its parts;
* the stop: :mod:`slamio.create.stopping` (the stop sequence and its read-back),
  :mod:`slamio.create.signals` (every terminating signal) and :mod:`slamio.create.guardian`
  (a process that stops the robot when the program dies).

Noise covariances from measured trials (``fgslam calibrate --from trials``) live with the
other noise models, in :mod:`slamio.noise.trials`.

The user's guide is ``docs/create.md``.
"""
