"""The Zenoh bridge: the robot's twists in and odometry out for other machines.

* :mod:`~gateway.runtime.bridge.session`: the Zenoh session from the ``bridge:`` block, with
  nothing listening and no multicast unless the block asks for it;
* :mod:`~gateway.runtime.bridge.native`: wheelgate's own keys (JSON, the control socket's
  messages);
* :mod:`~gateway.runtime.bridge.ros2`: ROS 2 topics as rmw_zenoh carries them;
* :mod:`~gateway.runtime.bridge.deadman`: which commander the robot follows, and what its
  disappearance does;
* :mod:`~gateway.runtime.bridge.bridge`: :class:`~gateway.runtime.bridge.bridge.Bridge`, what
  the daemon starts: requests in through an inbox it drains between cycles, news out through a
  :class:`~gateway.runtime.mailbox.Mailbox` a worker thread publishes from.

Zenoh (PyPI ``eclipse-zenoh``, the ``zenoh`` extra) is imported only here, and this package only
when a configuration has a ``bridge:`` block.
"""
