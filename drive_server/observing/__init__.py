"""What can be seen of a drive server while it serves: per-client latency statistics, the read-only live view
(Server-Sent Events) with its page (``static/``) and what it shows, and ``--record``'s background log writer.
Imports only ``drive_server.serving`` (``drive_server.ALLOWED_IMPORTS``)."""
