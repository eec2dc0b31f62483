"""``wheelgate calibrate``: the odometry's calibration factors fitted to runs measured on the
floor (:mod:`gateway.apps.calibrate.runs`, :mod:`gateway.apps.calibrate.fit`)."""
