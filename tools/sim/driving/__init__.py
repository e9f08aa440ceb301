"""A driving session: one car on one track stepped frame by frame, the scoring rules, who drives
(drive server over the wire, an ONNX model, the autopilot) and the loop that runs a scenario to its end.

Owns: :class:`~tools.sim.driving.simulation.Simulation`, :func:`~tools.sim.driving.session.run_scenario`,
the rules as data and the drivers. May import: ``tools.sim.track``, ``.vehicle``, ``.render`` (and the
Unity wire client, ``tools.wire``).
"""
