"""The track and its file formats: a closed road as data, its looks and themes, cones on it, and the
JSON track file (versions 1 and 2) with the built-in tracks in ``builtin/``.

Owns: :class:`~tools.sim.track.road.Track`, :func:`~tools.sim.track.files.load_track`, the themes and
looks the renderer draws. May import: nothing else of the simulator (it is the bottom of the stack).
"""
