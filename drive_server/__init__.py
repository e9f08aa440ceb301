"""Deployment runtime: Socket.IO drive server, ONNX Runtime inference, coupled control law.

Depends only on the design card's packages (never on torch). One sub-package per job; an arrow is an import a
package may make:

- ``serving``    a model file to a steer command: the serving contract (``contract``, ``preprocess``,
                 ``smoothing``, ``settings``, ``monitor``, ``model``), the pipeline, the control law, the
                 fallback for bad frames, the monitor at run time, the bundled models  -> (nothing)
- ``observing``  latency statistics, the live view and its page, the recorder           -> serving
- ``wire``       the Socket.IO server, its limits, connections, transport, the patches of the wire's libraries,
                 per-client state, the server's settings and reports, workers           -> serving, observing

``cli`` (the ``drive_server`` command) sits on top and may import all three. ``models`` imports only the serving
contract (tests/test_layout.py), so training and serving can never drift apart. ``tests/test_layout.py`` checks
these arrows (:data:`ALLOWED_IMPORTS`). Importing ``drive_server`` loads nothing else.
"""

ALLOWED_IMPORTS: dict[str, frozenset[str]] = {
    "serving": frozenset(),
    "observing": frozenset({"serving"}),
    "wire": frozenset({"serving", "observing"}),
}
