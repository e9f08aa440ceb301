"""Data collection: the autopilot driving a track or many generated worlds, recorded in the Udacity
simulator's log format, in this process, a process pool or on Ray.

Owns: :func:`~tools.sim.collect.dataset.collect`, :func:`~tools.sim.collect.worlds.collect_worlds`.
May import: ``tools.sim.track``, ``.driving``, ``.worldgen`` (and ``tools.ray_support``).
"""
