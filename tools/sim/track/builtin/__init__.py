"""Built-in track files (JSON, format version 1); see :mod:`tools.sim.track.road`."""
