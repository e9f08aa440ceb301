"""The car: its parameters, the kinematic bicycle and the dynamic single-track model with tyre slip.

Owns: :class:`~tools.sim.vehicle.kinematic.VehicleParams`, the vehicles and unit conversions.
May import: nothing else of the simulator (a surface is known to it by its kind's name only).
"""
