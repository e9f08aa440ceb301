"""A model file to a steer command: what a model file is and carries (the serving contract, which ``models`` also
imports), the drive pipeline (decode, preprocess, infer, control), the coupled control law, the fallback for bad
frames, the misbehaviour monitor as a client runs it, and where the bundled models live. Imports no other room
of drive_server (``drive_server.ALLOWED_IMPORTS``)."""
