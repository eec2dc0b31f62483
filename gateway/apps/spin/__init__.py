"""``wheelgate spin``: turn one motor slowly, compare its motion with the command, say what to fix.

Two comparisons, because a controller's encoder cannot see a wrong ``invert`` or ``gear_ratio``:
wheelgate turns the command *and* the feedback through both, so they cancel (a motor encoder
measures exactly the command whichever sign and ratio the configuration states):

* the **encoder** against the **command** judges the controller: did it enable, does it turn,
  does it follow (direction and speed) -- its faults, wiring, limits and own units;
* what the operator **saw** the wheel do against what the encoder measured judges the
  configuration: the other way means ``invert``, N times as far means ``gear_ratio``, no
  motion at all means the motor turns something else (a coupling, or another wheel's
  ``node_id``).

* :mod:`gateway.apps.spin.plan`: the command (speed profile or steering sweep), its bounds and
  how to describe it to the operator; the bus traffic that means someone else drives;
* :mod:`gateway.apps.spin.judge`: the measurement, the operator's answer and the verdict;
* :mod:`gateway.apps.spin.runner`: the edge: one motor's driver on the bus for the duration,
  behind a deadman, and the stop (zero and disarm) sent whatever happens.
* :mod:`gateway.apps.spin.deadman`: why the spin must stop: a key on the terminal (read without
  its signal characters: Ctrl-Z stops, never suspends, a turning motor) or a signal.

The command is :mod:`gateway.cli.commands.spin`.
"""
