"""The FMI layer: FMU definitions, the generic slave adapter, the builder,
the co-simulation master, scenarios and the command line.

Importing this package is cheap and does not import fmpy; the bundled copy
inside every FMU only needs ``fmus.definition``, ``fmus.kinds``, ``fmus.bundle``
and ``fmus.slave``.
"""
