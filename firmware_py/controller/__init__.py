"""The controller process around the firmware ``step()``: what it receives, when it runs and
what it sends.

* ``node``: ``ControllerNode``, one controller on one bus (receive, freshness, ``step()``,
  command and status), and its ``RuntimeConfig``.
* ``inputs``: the receive record of one sensor input.
* ``timing``: cycle lateness and the phase lock to the yaw-rate frames.
* ``stats``: what the loop counts (``--stats-out``).
* ``options``: controller options shared with the other commands.
* ``main``: the ``mrsteer controller`` / ``python -m firmware_py`` command line.
"""
