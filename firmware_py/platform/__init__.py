"""What every bus process needs, whatever it is (controller, plant, logger, bridge).

* ``bus_open``: the bus a process opens (explicit, python-can config, SocketCAN vcan0, or the
  fallback bus), announced in one line.
* ``fallback_bus``, ``fallback_broker``, ``fallback_wire``: the loopback stand-in for SocketCAN
  on machines without vcan: the python-can interface ``mrsteer``, its broker, its wire format.
* ``cli``: command-line conventions (one-line errors, exit status 2, the SecOC key options).
* ``files``: outputs written whole or not at all.
* ``lifecycle``: signals, ready line, bus failure and outputs of a running bus process.
* ``realtime``: SCHED_FIFO, CPU pinning, memory figures.
* ``rx_queue``: deep kernel receive queues for processes that must not lose frames.
"""
