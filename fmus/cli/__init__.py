"""The command line ``obsfmu`` (entry point :func:`fmus.cli.main.main`; ``python -m obsfmu``).

* :mod:`~fmus.cli.main` -- the parser of every subcommand, the entry point and its error handling
* :mod:`~fmus.cli.commands` -- ``build | list | run | export | all | report``
* :mod:`~fmus.cli.runs` -- running one scenario: CSV streamed, files and record written
* :mod:`~fmus.cli.args` -- the shared arguments and value types (times with units, counts)
* :mod:`~fmus.cli.stopping` -- Ctrl-C, SIGTERM and SIGHUP
* :mod:`~fmus.cli.subcommand` -- what a subcommand is (``obsfmu sweep`` is :mod:`fmus.campaign.cli`'s)

This package's ``__init__`` imports nothing, so its modules can be used without importing the others.
"""
