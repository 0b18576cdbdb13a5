"""The FMU runtime: everything an FMU carries of ``fmus``, bundled whole (docs/DEVELOPING.md).

The generic slave (:mod:`.slave`), the definition it reads (:mod:`.definition`), the block kinds
(:mod:`.kinds`), the callables they resolve (:mod:`.callables`), the FMU state format
(:mod:`.state_format`) and the names of modules inside an FMU (:mod:`.bundled`).  Nothing here
imports the host side of ``fmus`` (master, CLI, builder, campaign, ...): tests/architecture/test_runtime_isolation.py.
"""
