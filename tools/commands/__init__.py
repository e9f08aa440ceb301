"""One module per ``rbc`` subcommand, named after it: ``add_arguments(parser)`` and ``run(args)`` only."""
