"""``python -m drive_server``: same as the ``drive_server`` console script."""

from drive_server.cli import main

raise SystemExit(main())
