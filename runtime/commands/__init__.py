"""One module per ``omnijax`` subcommand: ``add_parser(subparsers)`` registers it, ``run(args)`` runs it."""
