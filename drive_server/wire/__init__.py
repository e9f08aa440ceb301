"""The drive server on the wire: python-socketio on eventlet, the Unity simulator's dialect, the limits against
hostile clients and where they are enforced, connections, the listening socket, the transport tuning, every patch
of the wire's libraries (``patches``), per-client state, the server's settings and reports, worker processes.
Imports ``drive_server.serving`` and ``drive_server.observing`` (``drive_server.ALLOWED_IMPORTS``)."""
