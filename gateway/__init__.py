"""wheelgate: a motor-control gateway over CAN for wheeled mobile robots.

The package is split into a pure core (kinematics, limits, odometry, codecs) and thin edges
(bus, loop, sockets, CLI).  See ``README.md`` for the map.
"""

from __future__ import annotations

__version__ = "0.1.0"
