"""Pictures and video of runs and recordings: trajectory maps, frame strips, H.264 writers, text.

Owns: :mod:`~tools.sim.pictures.viz`, :mod:`~tools.sim.pictures.video`. May import: ``tools.sim.track``,
``.vehicle``, ``.driving`` (what a run returned).
"""
