"""Headless driving simulator, one sub-package per job; an arrow is an import a package may make.

- ``track``    the road as data, its looks and the track file formats   -> (nothing)
- ``vehicle``  the car: kinematic and dynamic bicycle models            -> (nothing)
- ``render``   lit worlds and camera frames                             -> track
- ``driving``  a session: simulation, rules, drivers, the scenario loop -> track, vehicle, render
- ``pictures`` maps, strips and video of runs and recordings            -> track, vehicle, driving
- ``worldgen`` procedural worlds (generated, checked by driving them)   -> track, render, driving, pictures
- ``collect``  recording training sets with the autopilot               -> track, driving, worldgen

``tests/test_layout.py`` checks these arrows (:data:`ALLOWED_IMPORTS`). Importing ``tools.sim`` loads
nothing else; import the module you need (``tools.sim.track.files``, ``tools.sim.render.renderer``, ...).
"""

ALLOWED_IMPORTS: dict[str, frozenset[str]] = {
    "track": frozenset(),
    "vehicle": frozenset(),
    "render": frozenset({"track"}),
    "driving": frozenset({"track", "vehicle", "render"}),
    "pictures": frozenset({"track", "vehicle", "driving"}),
    "worldgen": frozenset({"track", "render", "driving", "pictures"}),
    "collect": frozenset({"track", "driving", "worldgen"}),
}
