"""The FMI layer: the FMU runtime (:mod:`fmus.runtime`, bundled in every FMU), the builder,
the co-simulation master, scenarios and the command line.

Importing this package is cheap and does not import fmpy; every FMU bundles this file.
"""
