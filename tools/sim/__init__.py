"""Headless driving simulator: tracks as data, a fast NumPy/OpenCV renderer, vehicle and sessions.

Importing ``tools.sim`` loads nothing; import the module you need (``tools.sim.track``, ``.world``,
``.render``, ``.session``).
"""
