"""Rendering: a track turned into a lit world (ground texture, props, sky) and 320x160 camera frames
of it, with the per-world image processing.

Owns: :class:`~tools.sim.render.world.World`, :class:`~tools.sim.render.renderer.Renderer`, the cameras.
May import: ``tools.sim.track``.
"""
